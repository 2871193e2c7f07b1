"""Pose panel: presets, root orientation and translation, the five body parts with three
sliders (degrees, within joint limits) per joint, resets, and a pose-sequence timeline.

Widget IDs (for the ImGui Test Engine): window "Pose", a joint's sliders under
``<joint name>/x``, ``/y``, ``/z`` (e.g. ``**/left_shoulder/z``), buttons
``**/<part>/Reset part``, ``**/<joint>/reset``, ``**/Reset all``, the timeline
``**/Sequence/frame``.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from imgui_bundle import imgui

from texvocab.errors import TexvocabError
from texvocab.pipeline import BODY_PARTS, JOINT_LIMITS_DEG, JOINT_NAMES, load_pose_file
from texvocab.pipeline import POSE_PRESETS as PRESETS

AXES = ("x", "y", "z")


class PoseSequence:
    """A loaded pose file: poses (T, 24, 3), trans (T, 3), the current frame and playback."""

    def __init__(self, path: str, poses: np.ndarray, trans: np.ndarray, fps: float = 30.0):
        self.path, self.poses, self.trans = path, poses, trans
        self.frame, self.playing, self.fps = 0, False, fps
        self._clock = 0.0

    @classmethod
    def load(cls, path: str) -> PoseSequence:
        poses, trans = load_pose_file(path)
        if len(poses) == 0:
            raise TexvocabError(f"{path}: 'poses' holds no frames")
        return cls(path, poses, trans)

    def advance(self, now: float) -> bool:
        """While playing, step frames by wall time; True if the frame changed."""
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
    width = (imgui.get_content_region_avail().x - imgui.get_style().item_spacing.x * 3
             - imgui.calc_text_size("reset").x - 2 * imgui.get_style().frame_padding.x) / 3
    new = deg.copy()
    for a, axis in enumerate(AXES):
        if a:
            imgui.same_line()
        imgui.set_next_item_width(max(width, 30.0))
        lo, hi = (float(v) for v in JOINT_LIMITS_DEG[j, a])
        changed, value = imgui.slider_float(f"##{axis}", float(deg[a]), lo, hi, f"{axis} %.0f°")
        if imgui.is_item_hovered():
            imgui.set_tooltip(f"{JOINT_NAMES[j]} {axis}: {lo:.0f}° .. {hi:.0f}°")
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


def _sequence(viewer) -> None:
    imgui.push_id("Sequence")
    imgui.set_next_item_width(imgui.get_content_region_avail().x - 60)
    _, viewer.sequence_path = imgui.input_text_with_hint("##path", "poses.npz", viewer.sequence_path)
    imgui.same_line()
    if imgui.button("Load"):
        try:
            viewer.sequence = PoseSequence.load(viewer.sequence_path.strip())
            viewer.sequence_error = ""
            _show_frame(viewer)
        except (TexvocabError, OSError, ValueError) as exc:
            viewer.sequence, viewer.sequence_error = None, str(exc)
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
        imgui.same_line()
        imgui.set_next_item_width(-1)
        changed, frame = imgui.slider_int("frame", seq.frame, 0, len(seq.poses) - 1,
                                          f"frame %d / {len(seq.poses) - 1}")
        if changed:
            seq.frame = frame
            _show_frame(viewer)
        imgui.set_next_item_width(100)
        _, seq.fps = imgui.slider_float("fps", seq.fps, 1.0, 60.0, "%.0f fps")
        imgui.same_line()
        imgui.text_disabled(Path(seq.path).name)
    _export_buttons(viewer)
    imgui.pop_id()


def _export_buttons(viewer) -> None:
    """"Export video" (the loaded sequence) and "Screenshot" (the current pose: 3D view
    and neural render), rendered in the background from the 3D view's camera at the
    neural panel's resolution (app.export); the result's path or error underneath."""
    if viewer.neural is None:
        return
    job = viewer.export
    if job is not None and job.running:
        imgui.text(f"exporting {job.done}/{job.total} ...")
        return
    seq = viewer.sequence
    if seq is not None and imgui.button("Export video"):
        viewer.start_export(seq.poses, seq.trans, Path(seq.path).stem, seq.fps)
    if seq is not None:
        imgui.same_line()
    if imgui.button("Screenshot"):
        viewer.start_export(viewer.state.pose[None], viewer.state.trans[None], "shot", 1.0,
                            view3d=True)
    if job is not None:
        if job.error:
            imgui.text_colored(imgui.ImVec4(1.0, 0.45, 0.4, 1.0), job.error)
        elif job.path is not None:
            imgui.text_disabled(f"wrote {job.path}")


def _show_frame(viewer) -> None:
    seq = viewer.sequence
    viewer.state.set_pose(seq.poses[seq.frame], seq.trans[seq.frame])


def tick_sequence(viewer) -> None:
    """Advance a playing sequence (call once per frame)."""
    seq = viewer.sequence
    if seq is not None and seq.advance(time.perf_counter()):
        _show_frame(viewer)


def draw_pose_panel(viewer) -> None:
    """The "Pose" window's contents."""
    _presets(viewer)
    if imgui.collapsing_header("Sequence"):
        _sequence(viewer)
    if imgui.collapsing_header("Root", imgui.TreeNodeFlags_.default_open):
        _root(viewer)
    for part, joints in BODY_PARTS.items():
        imgui.push_id(part)
        open_ = imgui.collapsing_header(f"{part.replace('_', ' ')}###header",
                                        imgui.TreeNodeFlags_.default_open)
        if open_:
            if imgui.small_button("Reset part"):
                viewer.state.reset_part(part)
            for j in joints:
                if j == 0:
                    continue  # the root has its own section
                imgui.text_disabled(JOINT_NAMES[j].replace("_", " "))
                _joint_sliders(viewer, j)
        imgui.pop_id()
