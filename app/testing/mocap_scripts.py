"""Scripted runs of the viewer window on mocap (ImGui Test Engine, as :mod:`.scripts`): the
``--poses`` sequence seen from a capture camera at its first, middle and last frames
(``mocap-frames``), and the novelty overlay of a frame facing camera 0 against the same
frame facing away (``mocap-novelty``). Each writes the 3D view's pixels, read back from
its framebuffer, as PNGs into the folder ``TEXVOCAB_TEST_OUT`` names (default: the
working folder)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from texvocab.pipeline import save_png
from texvocab_viewer.panels.pose import ROOTS

HEAD, LEFT_FOOT, RIGHT_FOOT = 15, 10, 11  # SMPL joints
LEFT_HIP, RIGHT_HIP = 1, 2


def _out() -> Path:
    out = Path(os.environ.get("TEXVOCAB_TEST_OUT", "."))
    out.mkdir(parents=True, exist_ok=True)
    return out


def _view(ctx, viewer, name: str) -> dict:
    """The 3D view's last image (its framebuffer, as the window shows it) written as
    ``name``, with its silhouette (the depth buffer's body pixels) and the camera's
    projection of the head and the feet. Read on the window's thread, where GL is."""
    got: dict = {}

    def read() -> None:
        scene = viewer.scene
        got["image"], got["depth"], got["size"] = scene.read(), scene.read_depth(), scene.size

    viewer.window_thread_calls.append(read)
    while "size" not in got:
        ctx.yield_()
    path = save_png(_out() / name, got["image"])
    np.save(_out() / (Path(name).stem + "_silhouette.npy"), got["depth"] < 1.0)
    w, h = got["size"]
    cam = viewer.camera.to_texvocab_camera(w, h)
    _, joints = viewer.state.posed()
    uv, z = cam.project(joints[[HEAD, LEFT_FOOT, RIGHT_FOOT]].astype(np.float64))
    return {
        "png": str(path),
        "size": [w, h],
        "head_uv": uv[0].tolist(),
        "feet_uv": uv[1:].tolist(),
        "depths": z.tolist(),
    }


def _show_frame(ctx, viewer, frame: int) -> None:
    ctx.set_ref("Pose")
    ctx.item_input_value("**/Sequence/##frame", frame)
    ctx.yield_(4)  # the 3D view redraws the new pose


def script_mocap_frames(ctx, viewer, report: dict) -> None:
    """Capture view 1 from the camera combo, the root choice ``TEXVOCAB_TEST_ROOT`` names
    (if any) from the Sequence's "root" combo, Follow if ``TEXVOCAB_TEST_FOLLOW``; the
    --poses sequence's first, middle and last frames, each read back from the 3D view
    (``view1_frameN.png``)."""
    ctx.yield_(4)
    ctx.set_ref("3D view")
    ctx.combo_click("##camera/capture view 1")  # a "**" wildcard misses "##" labels
    ctx.yield_(2)
    report["camera_index"] = getattr(viewer.camera, "index", None)
    seq = viewer.sequence
    report["frames_in_file"] = None if seq is None else len(seq.poses)
    if seq is None:
        return
    ctx.set_ref("Pose")
    ctx.item_open("**/Sequence")
    root = os.environ.get("TEXVOCAB_TEST_ROOT")
    if root:  # the Sequence's "root" combo, as a user picks it
        ctx.item_click("Sequence/root")
        ctx.yield_(2)
        index = ROOTS.index(root)  # imgui.combo pushes each entry's index
        ctx.item_click(f"//##Combo_00/$${index}/{root}")
        ctx.yield_(2)
    report["root_choice"] = viewer.sequence_root
    seq = viewer.sequence
    last = len(seq.poses) - 1
    if os.environ.get("TEXVOCAB_TEST_FOLLOW"):  # the camera moves with the root from frame 0
        _show_frame(ctx, viewer, 0)
        ctx.set_ref("3D view")
        ctx.item_click("**/Follow")
        ctx.yield_(2)
    report["follow"] = viewer.follow
    shots = []
    for frame in (0, last // 2, last):
        _show_frame(ctx, viewer, frame)
        shot = _view(ctx, viewer, f"view1_frame{frame}.png")
        shot["frame"], shot["shown"] = frame, seq.frame
        shot["root"] = viewer.root_position().tolist()
        shot["background"] = list(viewer.options.background)
        shots.append(shot)
    report["shots"] = shots


def _facing(viewer) -> float:
    """The cosine between where the body faces and the way to camera 0, both horizontal
    (1: towards the camera, -1: away)."""
    _, joints = viewer.state.posed()
    j = joints.astype(np.float64)
    up = j[9] - j[0]  # pelvis to spine3
    up /= np.linalg.norm(up)
    forward = np.cross(j[LEFT_HIP] - j[RIGHT_HIP], up)
    to_cam = np.asarray(viewer.data.capture.cameras[0].center, np.float64) - j[0]
    to_cam -= np.dot(to_cam, up) * up
    return float(np.dot(forward, to_cam) / (np.linalg.norm(forward) * np.linalg.norm(to_cam)))


def _novelty(ctx, viewer, name: str) -> dict:
    vocab = viewer.data.vocab
    colours = viewer.scene.novelty_colors(viewer.state, viewer.options.novelty_scale)
    return {
        "novelty": dict(zip(vocab.part_names, viewer.state.novelty().tolist(), strict=True)),
        "facing_camera0": _facing(viewer),
        "colours": np.asarray(colours, np.float64),
        "view": _view(ctx, viewer, name),
    }


def script_mocap_novelty(ctx, viewer, report: dict) -> None:
    """The Novelty overlay, the orbit camera reset (it faces the body from camera 0's
    side, framing it); the --poses file's first frame, then the
    file ``TEXVOCAB_TEST_AWAY_POSES`` names (the same motion turned to face away), typed
    into the Sequence path field: each one's per-part novelty and overlay colours, and the
    3D view (``novelty_facing.png``, ``novelty_away.png``)."""
    ctx.yield_(4)
    report["pose_condition"] = viewer.data.vocab.pose_condition
    ctx.set_ref("3D view")
    ctx.item_click("**/Novelty")
    ctx.item_click("**/Reset camera")  # the orbit's front: towards camera 0, the body framed
    ctx.yield_(4)
    runs = {"facing": _novelty(ctx, viewer, "novelty_facing.png")}
    ctx.set_ref("Pose")
    ctx.item_open("**/Sequence")
    ctx.item_input_value("**/Sequence/##path", os.environ["TEXVOCAB_TEST_AWAY_POSES"])
    ctx.item_click("**/Sequence/Load")
    ctx.yield_(4)
    report["away_loaded"] = viewer.sequence is not None and viewer.sequence.path.endswith("away.npz")
    ctx.set_ref("3D view")
    ctx.item_click("**/Reset camera")
    ctx.yield_(4)
    runs["away"] = _novelty(ctx, viewer, "novelty_away.png")
    a, b = runs["facing"].pop("colours"), runs["away"].pop("colours")
    report["overlay_colour_diff"] = float(np.abs(a - b).max())
    report.update(runs)
