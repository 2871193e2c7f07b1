"""Pose panel: presets, root orientation and translation, the five body parts with three
sliders (degrees, within joint limits) per joint, resets, and a pose-sequence timeline.

Widget IDs (for the ImGui Test Engine): window "Pose", a joint's sliders under
``<joint name>/x``, ``/y``, ``/z`` (e.g. ``**/left_shoulder/z``), buttons
``**/<part>/Reset part``, ``**/<joint>/reset``, ``**/Reset all``, the timeline
``**/Sequence/##frame``, ``**/Sequence/Play`` (``Pause``), ``**/Sequence/Open...``, the
root combo ``Sequence/root``.

A joint value outside its limits (a pose from a file or a key) is shown in red with its
exact value, and stays as it is until its own slider moves.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from imgui_bundle import imgui

from texvocab.errors import TexvocabError
from texvocab.pipeline import (
    BODY_PARTS,
    JOINT_LIMITS_DEG,
    JOINT_NAMES,
    ROOT_HELP,
    ROOTS,
    place_motion,
    read_pose_sequence,
)
from texvocab.pipeline import POSE_PRESETS as PRESETS
from texvocab_viewer.dialogs import POSE_FILTERS

AXES = ("x", "y", "z")
DEFAULT_FPS = 30.0  # playback rate of a file that states none
EXPORT_FPS = 30.0  # "Export video" keeps every n-th frame of faster sequences
EDITED_SINCE = "pose edited since frame %d"  # under the timeline once the pose leaves it
OUT_OF_LIMIT = (0.75, 0.18, 0.15, 1.0)
#: where a pose file's motion stands in a capture's world: ``texvocab render --root``'s
#: choices (texvocab.pipeline.place_motion)
ROOT_TOOLTIP = "where the motion stands (as texvocab render --root):\n" + ROOT_HELP.replace("; ", "\n")


class PoseSequence:
    """A loaded pose file: poses (T, 24, 3), trans (T, 3), every frame of the file; the
    current frame and playback at ``fps`` (the file's own rate, ``file_fps``, when it
    states one). ``shown_version``: the viewer state's version when it last showed a frame
    of the sequence (an edit after that leaves the timeline, and it says so)."""

    def __init__(self, path: str, poses: np.ndarray, trans: np.ndarray, fps: float | None = None):
        self.path, self.poses, self.trans = path, poses, trans
        self.file_fps = fps
        self.frame, self.playing, self.fps = 0, False, float(fps or DEFAULT_FPS)
        self.shown_version = -1
        self._clock = 0.0

    @classmethod
    def load(cls, path: str, capture=None, root: str = "floor") -> PoseSequence:
        """The pose file at ``path``; with a ``capture``, its motion put into that world as
        ``texvocab render --root ROOT`` puts it (:func:`texvocab.pipeline.place_motion`:
        turned upright when the capture is not Y up, then stood by ``root``)."""
        pelvis = None if capture is None else capture.body.rest_joints[0].double().numpy()
        seq = read_pose_sequence(path, fps=None, pelvis=pelvis)  # every frame, at its rate
        if len(seq.poses) == 0:
            raise TexvocabError(f"{path}: 'poses' holds no frames")
        poses, trans = seq.poses, seq.trans
        if capture is not None:
            poses, trans = place_motion(poses, trans, pelvis, capture, capture.cameras[0], root)
        return cls(path, poses, trans, seq.source_fps)

    def advance(self, now: float) -> bool:
        """While playing, step frames by wall time at ``fps``; True if the frame changed."""
        if not self.playing:
            self._clock = now
            return False
        steps = int((now - self._clock) * self.fps)
        if steps <= 0:
            return False
        self._clock += steps / self.fps
        self.frame = (self.frame + steps) % len(self.poses)
        return True


def _joint_sliders(viewer, j: int) -> None:
    state = viewer.state
    imgui.push_id(JOINT_NAMES[j])
    deg = state.joint_deg(j)
    outside = state.out_of_limits(j)
    width = (
        imgui.get_content_region_avail().x
        - imgui.get_style().item_spacing.x * 3
        - imgui.calc_text_size("reset").x
        - 2 * imgui.get_style().frame_padding.x
    ) / 3
    new = deg.copy()
    for a, axis in enumerate(AXES):
        if a:
            imgui.same_line()
        imgui.set_next_item_width(max(width, 30.0))
        lo, hi = (float(v) for v in JOINT_LIMITS_DEG[j, a])
        if outside[a]:
            imgui.push_style_color(imgui.Col_.frame_bg, imgui.ImVec4(*OUT_OF_LIMIT))
        fmt = f"{axis} {deg[a]:.1f}°!" if outside[a] else f"{axis} %.0f°"
        changed, value = imgui.slider_float(f"##{axis}", float(deg[a]), lo, hi, fmt)
        if outside[a]:
            imgui.pop_style_color()
        if imgui.is_item_hovered():
            note = f"\n{deg[a]:.2f}° lies outside the limits" if outside[a] else ""
            imgui.set_tooltip(f"{JOINT_NAMES[j]} {axis}: {lo:.0f}° .. {hi:.0f}°{note}")
        if changed:
            new[a] = value
    if not np.array_equal(new, deg):
        state.set_joint(j, new)
    imgui.same_line()
    if imgui.small_button("reset"):
        state.reset_joint(j)
    imgui.pop_id()


def _presets(viewer) -> None:
    state = viewer.state
    imgui.set_next_item_width(imgui.get_content_region_avail().x * 0.5)
    if imgui.begin_combo("##preset", viewer.preset or "preset..."):
        for name in sorted(PRESETS):
            if imgui.selectable(name, name == viewer.preset)[0]:
                state.apply_preset(name)
                viewer.preset = name
        imgui.end_combo()
    imgui.same_line()
    if imgui.button("Reset all"):
        state.reset_all()
        viewer.preset = ""
        if viewer.sequence is not None:
            viewer.sequence.playing = False  # the timeline then says the pose left it


def _root(viewer) -> None:
    state = viewer.state
    imgui.text("orientation")
    _joint_sliders(viewer, 0)
    imgui.text("translation (m)")
    imgui.push_id("trans")
    t = state.trans.astype(np.float32)
    imgui.set_next_item_width(-1)
    changed, value = imgui.drag_float3("##trans", t.tolist(), 0.005, -5.0, 5.0, "%.2f")
    if changed:
        state.set_trans(np.asarray(value, np.float64))
    imgui.pop_id()


def check_pose_file(path: str) -> None:
    """Read and check the pose file ``--poses`` names before anything else loads, so that a
    bad one is refused at once (TexvocabError naming ``--poses``). Where it goes in a
    capture's world is decided later (:meth:`PoseSequence.load`)."""
    try:
        seq = read_pose_sequence(path.strip(), fps=None)
    except (TexvocabError, OSError, ValueError) as exc:
        raise TexvocabError(f"--poses {path}: {exc}") from None
    if len(seq.poses) == 0:
        raise TexvocabError(f"--poses {path}: 'poses' holds no frames")


def load_sequence(viewer, path: str) -> None:
    """Load a pose file into the timeline and show its first frame. When it cannot be
    read, the timeline keeps the sequence loaded before (if any) and the error shows in
    the status line and under the path field, until a later load succeeds. The Sequence
    header opens either way."""
    viewer.sequence_path = path
    viewer.open_sequence = True
    try:
        sequence = PoseSequence.load(path.strip(), viewer.data.capture, viewer.sequence_root)
    except (TexvocabError, OSError, ValueError) as exc:
        viewer.sequence_error = str(exc)
        kept = "" if viewer.sequence is None else f" (kept {Path(viewer.sequence.path).name})"
        viewer.status.fail(f"pose file not loaded{kept}: {exc}")
        return
    viewer.sequence, viewer.sequence_error = sequence, ""
    viewer.status.done(f"loaded {Path(path.strip()).name}: {len(sequence.poses)} frames")
    _show_frame(viewer)


def _sequence(viewer) -> None:
    imgui.push_id("Sequence")
    dialogs = viewer.dialogs
    buttons = (
        imgui.calc_text_size("LoadOpen...").x
        + 4 * imgui.get_style().frame_padding.x
        + 2 * imgui.get_style().item_spacing.x
    )
    imgui.set_next_item_width(imgui.get_content_region_avail().x - buttons)
    _, viewer.sequence_path = imgui.input_text_with_hint("##path", "poses.npz", viewer.sequence_path)
    imgui.same_line()
    if imgui.button("Load"):
        load_sequence(viewer, viewer.sequence_path)
    imgui.same_line()
    missing = dialogs.missing()
    imgui.begin_disabled(bool(missing) or dialogs.open)
    if imgui.button("Open..."):
        dialogs.ask("poses", "Open a pose file", POSE_FILTERS, viewer.sequence_path)
    imgui.end_disabled()
    if missing and imgui.is_item_hovered(imgui.HoveredFlags_.allow_when_disabled):
        imgui.set_tooltip(missing)
    _placement(viewer)
    if viewer.sequence_error:
        imgui.push_text_wrap_pos(0.0)
        imgui.text_colored(imgui.ImVec4(1.0, 0.45, 0.4, 1.0), viewer.sequence_error)
        imgui.pop_text_wrap_pos()
    seq = viewer.sequence
    if seq is not None:
        label = "Pause" if seq.playing else "Play"
        if imgui.button(label, imgui.ImVec2(60, 0)):
            seq.playing = not seq.playing
            seq.advance(time.perf_counter())
            if seq.playing:
                _show_frame(viewer)
        imgui.same_line()
        imgui.set_next_item_width(-1)
        edited = seq.shown_version != viewer.state.version
        text = f"frame %d / {len(seq.poses) - 1}"
        changed, frame = imgui.slider_int("##frame", seq.frame, 0, len(seq.poses) - 1, text)
        if changed or (imgui.is_item_activated() and edited):
            seq.frame = frame
            _show_frame(viewer)
        viewer.drawn_timeline_note = EDITED_SINCE % seq.frame if edited else ""
        if edited:  # a line of its own, wrapped: never cut off by a narrow panel
            imgui.push_text_wrap_pos(0.0)
            imgui.text_disabled(viewer.drawn_timeline_note)
            imgui.pop_text_wrap_pos()
        imgui.set_next_item_width(100)
        _, seq.fps = imgui.slider_float("fps", seq.fps, 1.0, 120.0, "%.0f fps")
        imgui.same_line()
        rate = f"file: {seq.file_fps:g} fps" if seq.file_fps else f"file states no rate: {DEFAULT_FPS:g}"
        imgui.text_disabled(f"{Path(seq.path).name}, {len(seq.poses)} frames, {rate}")
    _export_buttons(viewer)
    imgui.pop_id()


def _placement(viewer) -> None:
    """The "root" combo (a capture only): where the motion stands in the capture's world;
    a change loads the sequence again, placed anew, at the same frame."""
    if viewer.data.capture is None:
        return
    imgui.set_next_item_width(110)
    changed, index = imgui.combo("root", ROOTS.index(viewer.sequence_root), list(ROOTS))
    if imgui.is_item_hovered():
        imgui.set_tooltip(ROOT_TOOLTIP)
    if changed and ROOTS[index] != viewer.sequence_root:
        viewer.sequence_root = ROOTS[index]
        seq = viewer.sequence
        if seq is not None:
            frame = seq.frame
            load_sequence(viewer, seq.path)
            if viewer.sequence is not seq:
                viewer.sequence.frame = min(frame, len(viewer.sequence.poses) - 1)
                _show_frame(viewer)


def _export_buttons(viewer) -> None:
    """ "Export video": the loaded sequence rendered in the background from the 3D view's
    camera at the neural panel's resolution (texvocab_viewer.export.job); progress, or the result's
    path or error, underneath (the 3D view's Screenshot job shows here too)."""
    if viewer.neural is None or viewer.sequence is None:
        return
    job = viewer.export
    if job is not None and job.running:
        imgui.text(f"exporting {job.done}/{job.total} ...")
        return
    if imgui.button("Export video"):
        seq = viewer.sequence
        step = max(1, round(seq.fps / EXPORT_FPS))  # every step-th frame: at most ~30 fps
        viewer.start_export(seq.poses[::step], seq.trans[::step], Path(seq.path).stem, seq.fps / step)
    if imgui.is_item_hovered():
        imgui.set_tooltip(
            f"the sequence at its playback speed, at most {EXPORT_FPS:g} frames "
            "per second of video (a 120 fps file: every 4th frame)"
        )
    if job is not None:
        if job.error:
            imgui.text_colored(imgui.ImVec4(1.0, 0.45, 0.4, 1.0), job.error)
        elif job.path is not None:
            imgui.text_disabled(f"wrote {job.path}")


def _show_frame(viewer) -> None:
    seq = viewer.sequence
    viewer.state.set_pose(seq.poses[seq.frame], seq.trans[seq.frame], f"frame {seq.frame}")
    seq.shown_version = viewer.state.version


def tick_sequence(viewer) -> None:
    """Advance a playing sequence (call once per frame)."""
    seq = viewer.sequence
    if seq is not None and seq.advance(time.perf_counter()):
        _show_frame(viewer)


def draw_pose_panel(viewer) -> None:
    """The "Pose" window's contents."""
    _presets(viewer)
    if viewer.open_sequence:  # a pose file was loaded (or failed to): show its section
        imgui.set_next_item_open(True)
        viewer.open_sequence = False
    if imgui.collapsing_header("Sequence"):
        _sequence(viewer)
    if imgui.collapsing_header("Root", imgui.TreeNodeFlags_.default_open):
        _root(viewer)
    for part, joints in BODY_PARTS.items():
        imgui.push_id(part)
        open_ = imgui.collapsing_header(
            f"{part.replace('_', ' ')}###header", imgui.TreeNodeFlags_.default_open
        )
        if open_:
            if imgui.small_button("Reset part"):
                viewer.state.reset_part(part)
            for j in joints:
                if j == 0:
                    continue  # the root has its own section
                imgui.text_disabled(JOINT_NAMES[j].replace("_", " "))
                _joint_sliders(viewer, j)
        imgui.pop_id()
