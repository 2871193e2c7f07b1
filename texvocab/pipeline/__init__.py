"""Runs of the method (settings, training, evaluation, loading an avatar) and the public
API that the viewer (``app/``), the benchmarks and users' scripts import.

``from texvocab.pipeline import NAME`` resolves NAME lazily (PEP 562): importing this
package loads neither torch nor GL until a name is used. The import contract in
pyproject.toml (``[tool.importlinter]``) holds ``app`` to this module and
:mod:`texvocab.errors`.
"""

from __future__ import annotations

import importlib

#: public name -> (module, attribute there)
_API: dict[str, tuple[str, str]] = {
    # body model (data flow step 1)
    "load_body": ("texvocab.body", "load_body"),
    "BODY_PARTS": ("texvocab.body.parts", "BODY_PARTS"),
    "JOINT_NAMES": ("texvocab.body.parts", "JOINT_NAMES"),
    "part_attention": ("texvocab.body.parts", "part_attention"),
    "JOINT_LIMITS_DEG": ("texvocab.body.limits", "JOINT_LIMITS_DEG"),
    "POSE_PRESETS": ("texvocab.body.poses", "PRESETS"),
    "pose_preset": ("texvocab.body.poses", "preset"),
    "forward_kinematics": ("texvocab.body.lbs", "forward_kinematics"),
    "corrective_pose_feature": ("texvocab.body.lbs", "pose_feature"),
    "rotvec_to_rotmat": ("texvocab.geometry.rotations", "rotvec_to_rotmat"),
    "quat_to_rotvec": ("texvocab.geometry.rotations", "quat_to_rotvec"),
    "rotvec_to_quat": ("texvocab.geometry.rotations", "rotvec_to_quat"),
    "part_distance": ("texvocab.method.vocab", "part_distance"),
    "outward_orientation": ("texvocab.geometry.surface", "outward_orientation"),
    # captures (step 2)
    "Camera": ("texvocab.capture", "Camera"),
    "look_at": ("texvocab.capture.camera", "look_at"),
    "open_capture": ("texvocab.capture", "open"),
    "load_pose_file": ("texvocab.capture.synth", "load_pose_file"),
    "read_pose_sequence": ("texvocab.body.pose_files", "read_pose_sequence"),
    # the method (steps 3-6)
    "Vocabulary": ("texvocab.method.vocab", "Vocabulary"),
    "VocabTexture": ("texvocab.method.vocab_texture", "VocabTexture"),
    # rendering (step 7)
    "ShellGeometry": ("texvocab.render", "ShellGeometry"),
    "prepare_shell": ("texvocab.render", "prepare_shell"),
    "render_image": ("texvocab.render", "render_image"),
    "progressive_render": ("texvocab.render", "progressive_render"),
    "progressive_shard": ("texvocab.render", "progressive_shard"),
    # runs
    "Settings": ("texvocab.pipeline.settings", "Settings"),
    "DataSettings": ("texvocab.pipeline.settings", "DataSettings"),
    "VocabSettings": ("texvocab.pipeline.settings", "VocabSettings"),
    "FieldSettings": ("texvocab.method.field", "FieldSettings"),
    "RenderSettings": ("texvocab.pipeline.settings", "RenderSettings"),
    "TrainSettings": ("texvocab.pipeline.settings", "TrainSettings"),
    "RENDER_PRESETS": ("texvocab.pipeline.settings", "PRESETS"),
    "march_settings": ("texvocab.pipeline.settings", "march_settings"),
    "render_overrides": ("texvocab.pipeline.settings", "render_overrides"),
    "load_textures": ("texvocab.pipeline.model", "load_textures"),
    "build_vocabulary": ("texvocab.pipeline.model", "build_vocabulary"),
    "Avatar": ("texvocab.pipeline.avatar", "Avatar"),
    "load_avatar": ("texvocab.pipeline.avatar", "load_avatar"),
    # clips (texvocab render, the viewer's export)
    "FrameWorker": ("texvocab.pipeline.clip_worker", "FrameWorker"),
    "write_mp4": ("texvocab.pipeline.clip", "write_mp4"),
    "follow_camera": ("texvocab.pipeline.clip", "follow_camera"),
    "needs_placing": ("texvocab.pipeline.clip_placement", "needs_placing"),
    "capture_up": ("texvocab.pipeline.clip_placement", "capture_up"),
    "stand_point": ("texvocab.pipeline.clip_placement", "stand_point"),
    "toward": ("texvocab.pipeline.clip_placement", "toward"),
    "place_in_capture": ("texvocab.pipeline.clip_placement", "place_in_capture"),
    "place_motion": ("texvocab.pipeline.clip_placement", "place_motion"),
    "ROOTS": ("texvocab.pipeline.root_choice", "ROOTS"),
    "ROOT_HELP": ("texvocab.pipeline.root_choice", "ROOT_HELP"),
    # threads
    "budget_blas_threads": ("texvocab.blas", "budget_blas_threads"),
    "blas_threads": ("texvocab.blas", "blas_threads"),
    # files
    "save_png": ("texvocab.io.images", "save_png"),
    "to_uint8": ("texvocab.io.images", "to_uint8"),
    "contact_sheet": ("texvocab.io.images", "contact_sheet"),
    "atomic_write_bytes": ("texvocab.io.images", "atomic_write_bytes"),
    "temp_prefix": ("texvocab.io.temp_files", "temp_prefix"),
    "sweep_stale": ("texvocab.io.temp_files", "sweep_stale"),
}

__all__ = sorted(_API)


def __getattr__(name: str):
    if name not in _API:
        raise AttributeError(f"module 'texvocab.pipeline' has no attribute {name!r}")
    module, attr = _API[name]
    value = getattr(importlib.import_module(module), attr)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_API))
