"""The ImGui Test Engine scripts of the viewer's tests and screenshots: a slider, a key,
the camera and the timeline (``slider``), the export buttons (``export``), and states
worth a screenshot (``shot-*``). Each one acts as a person would with the mouse (widgets
by their IDs) and writes what it saw into ``report``."""

from __future__ import annotations

import time

import numpy as np
from imgui_bundle import imgui

from texvocab_viewer.testing.steps import LEFT_ARM_MOVE, snapshot, wait_export, wait_neural


def script_slider(ctx, viewer, report: dict) -> None:
    """Move a left-arm slider; record the vocabulary panel before and after."""
    ctx.yield_(6)
    report["before"] = snapshot(viewer)
    report["version_before"] = viewer.state.version
    ctx.set_ref("Pose")
    ctx.item_input_value(*LEFT_ARM_MOVE)
    ctx.yield_(4)
    report["after"] = snapshot(viewer)
    report["version_after"] = viewer.state.version
    report["left_shoulder_deg"] = viewer.state.joint_deg(16).tolist()
    shown = {}
    ctx.set_ref("Vocabulary")
    for key_id, _, _ in viewer.drawn_keys.get("left_arm", []):
        shown[str(key_id)] = bool(ctx.item_exists(f"left_arm/keys/key{key_id}"))
    report["left_arm_buttons_found"] = shown
    far_key = report["after"]["keys"]["left_arm"][-1][0]  # the farthest selected key
    ctx.item_click(f"left_arm/keys/key{far_key}")
    ctx.yield_(3)
    report["clicked_key"] = far_key
    report["after_click"] = snapshot(viewer)
    _camera_steps(ctx, viewer, report)
    if viewer.sequence_path:
        _sequence_steps(ctx, viewer, report)
    wait_neural(ctx, viewer, report)


def _camera(viewer) -> dict:
    c = viewer.camera
    return {"yaw": c.yaw, "pitch": c.pitch, "distance": c.distance, "target": c.target.tolist()}


def _camera_steps(ctx, viewer, report: dict) -> None:
    """Orbit (left drag), zoom (wheel) and pan (right drag) in the 3D view."""
    ctx.set_ref("3D view")
    report["camera_start"] = _camera(viewer)
    ctx.mouse_move("**/##viewport")
    ctx.mouse_drag_with_delta(imgui.ImVec2(60, 0))
    report["camera_orbited"] = _camera(viewer)
    ctx.mouse_move("**/##viewport")
    ctx.mouse_wheel_y(2)
    ctx.yield_(2)
    report["camera_zoomed"] = _camera(viewer)
    ctx.mouse_move("**/##viewport")
    ctx.mouse_drag_with_delta(imgui.ImVec2(0, 40), imgui.MouseButton_.right)
    report["camera_panned"] = _camera(viewer)
    ctx.item_click("**/Reset camera")
    ctx.yield_(2)
    report["camera_reset"] = _camera(viewer)


def _sequence_steps(ctx, viewer, report: dict) -> None:
    """Load the pose file given by --poses and scrub its timeline to frame 2."""
    ctx.set_ref("Pose")
    ctx.item_open("**/Sequence")
    ctx.item_click("**/Sequence/Load")
    ctx.yield_(2)
    report["sequence_error"] = viewer.sequence_error
    if viewer.sequence is None:
        return
    report["sequence_frames"] = len(viewer.sequence.poses)
    ctx.item_input_value("**/Sequence/##frame", 2)
    ctx.yield_(2)
    report["sequence_frame"] = viewer.sequence.frame
    report["pose_at_frame"] = viewer.state.pose.tolist()
    report["trans_at_frame"] = viewer.state.trans.tolist()
    ctx.item_click("**/Sequence/Play")
    seq = viewer.sequence
    t0 = time.perf_counter()
    while seq.frame == 2 and time.perf_counter() - t0 < 10:
        ctx.yield_()
    report["played_to"] = seq.frame
    report["played_pose_matches"] = bool(np.allclose(viewer.state.pose, seq.poses[seq.frame]))
    ctx.item_click("**/Sequence/Pause")
    paused_at = seq.frame
    ctx.yield_(5)
    report["paused"] = not seq.playing and seq.frame == paused_at


def script_shot_default(ctx, viewer, report: dict) -> None:
    ctx.yield_(6)
    wait_neural(ctx, viewer, report)


def script_shot_left_arm(ctx, viewer, report: dict) -> None:
    ctx.yield_(4)
    ctx.set_ref("Pose")
    ctx.item_input_value(*LEFT_ARM_MOVE)
    ctx.item_input_value("**/left_elbow/##y", -60.0)
    ctx.yield_(4)
    report["after"] = snapshot(viewer)
    wait_neural(ctx, viewer, report)


def script_shot_novelty(ctx, viewer, report: dict) -> None:
    ctx.yield_(4)
    ctx.set_ref("Pose")
    ctx.item_input_value("**/left_shoulder/##z", 60.0)  # raise the left arm
    ctx.item_input_value("**/right_hip/##x", -90.0)
    ctx.set_ref("3D view")
    ctx.item_click("**/Novelty")
    ctx.item_click("**/Skeleton")
    ctx.item_click("**/Reset camera")  # frame the new pose
    ctx.yield_(4)
    report["novelty_on"] = bool(viewer.options.novelty)
    report["skeleton_on"] = bool(viewer.options.skeleton)
    report["after"] = snapshot(viewer)
    wait_neural(ctx, viewer, report)


def script_export(ctx, viewer, report: dict) -> None:
    """Load the --poses sequence, turn Follow on, click "Export video", then "Screenshot";
    wait for each."""
    ctx.yield_(4)
    ctx.set_ref("Pose")
    ctx.item_open("**/Sequence")
    ctx.item_click("**/Sequence/Load")
    ctx.yield_(2)
    report["sequence_frames"] = None if viewer.sequence is None else len(viewer.sequence.poses)
    report["fps"] = None if viewer.sequence is None else viewer.sequence.fps
    ctx.set_ref("3D view")
    ctx.item_click("**/Follow")  # the video's cameras then move with the root
    report["follow"] = viewer.follow
    ctx.set_ref("Pose")
    ctx.item_click("**/Sequence/Export video")
    report["video"] = wait_export(ctx, viewer)
    ctx.set_ref("3D view")
    ctx.item_click("**/Screenshot")
    report["screenshot"] = wait_export(ctx, viewer)


ENGINE_SCRIPTS = {
    "slider": script_slider,
    "shot-default": script_shot_default,
    "export": script_export,
    "shot-left-arm": script_shot_left_arm,
    "shot-novelty": script_shot_novelty,
}
