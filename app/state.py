"""What the viewer shows: the loaded data (:class:`ViewerData`) and the pose being edited
(:class:`ViewerState`, versioned so renderers and workers can tell when it changed).
No GL and no GUI here."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from texvocab.errors import TexvocabError
from texvocab.pipeline import (
    BODY_PARTS,
    JOINT_LIMITS_DEG,
    JOINT_NAMES,
    DataSettings,
    Settings,
    VocabTexture,
    build_vocabulary,
    load_avatar,
    load_body,
    load_textures,
    needs_placing,
    open_capture,
    part_distance,
    place_in_capture,
    quat_to_rotvec,
    rotvec_to_quat,
)
from texvocab.pipeline import POSE_PRESETS as PRESETS
from texvocab.pipeline import pose_preset as preset
from texvocab_viewer.posing import BodyPoser


@dataclass
class ViewerData:
    """Everything loaded once.

    Attributes:
        body: :class:`~texvocab.body.BodyModel`.
        vocab: :class:`~texvocab.method.vocab.Vocabulary` or None (no capture given).
        textures: (T, S, S, 3) float32 texture maps of the training frames, or None.
        model: the trained :class:`~texvocab.method.field.AvatarField` or None (no checkpoint).
        capture: :class:`~texvocab.capture.Capture` or None.
        settings: :class:`~texvocab.pipeline.settings.Settings` (the checkpoint's, else defaults).
        source: what was loaded, for the window title and messages.
    """

    body: object
    vocab: object | None = None
    textures: np.ndarray | None = None
    model: object | None = None
    capture: object | None = None
    settings: Settings | None = None
    source: str = "default body"


def _capture_data(path: Path, smpl: str | None) -> ViewerData:
    cap = open_capture(path, body=load_body(smpl))
    if cap.num_train < 1:
        raise TexvocabError(f"{path}: the capture has no training frames to build a vocabulary")
    # the viewer of a bare capture holds out the default evaluation views it has (a
    # capture with fewer views simply has fewer held out); training refuses instead
    held_out = tuple(v for v in Settings().data.eval_views if v < cap.num_views)
    s = Settings(data=DataSettings(eval_views=held_out))
    vocab = build_vocabulary(cap, s)
    textures = load_textures(cap, s, progress=True).permute(0, 2, 3, 1).numpy()
    return ViewerData(
        cap.body, vocab, textures, None, cap, s, f"capture {path} ({cap.num_train} training frames)"
    )


def _checkpoint_data(
    path: Path, smpl: str | None, capture: str | None = None, other_capture: bool = False
) -> ViewerData:
    cap = None if capture is None else open_capture(Path(capture).expanduser(), body=load_body(smpl))
    avatar = load_avatar(path, cap, smpl=smpl, other_capture=other_capture)
    model = avatar.model
    textures = model.pose_feature.textures.permute(0, 2, 3, 1).numpy()
    return ViewerData(
        avatar.capture.body,
        model.pose_feature.vocab,
        textures,
        model,
        avatar.capture,
        avatar.settings,
        f"checkpoint {path} (step {avatar.step}, capture {avatar.capture.root})",
    )


def load_viewer_data(
    source: str | None, smpl: str | None = None, capture: str | None = None, other_capture: bool = False
) -> ViewerData:
    """Load what ``texvocab view [SOURCE]`` shows.

    Args:
        source: None (the body only), a capture folder (vocabulary from its training
            poses with default Settings, cached texture maps prepared if missing) or a
            checkpoint file written by ``texvocab train`` (its model, vocabulary and
            capture).
        smpl: the user's SMPL model file/folder; default the embedded default body.
        capture: for a checkpoint, its capture folder when not where it records it.
        other_capture: for a checkpoint, accept a capture it was not trained on (one
            warning line) instead of refusing it.
    """
    if capture is not None and (source is None or Path(source).expanduser().is_dir()):
        raise TexvocabError("--capture applies to a checkpoint SOURCE only")
    if source is None:
        body = load_body(smpl)
        return ViewerData(body, settings=Settings(), source=body.name)
    path = Path(source).expanduser()
    if path.is_dir():
        return _capture_data(path, smpl)
    if path.is_file():
        return _checkpoint_data(path, smpl, capture, other_capture)
    raise TexvocabError(
        f"{source}: no such file or folder; expected a checkpoint .pt written "
        "by 'texvocab train' or a capture folder"
    )


PART_NAMES: tuple[str, ...] = tuple(BODY_PARTS)


class ViewerState:
    """The pose being edited and everything derived from it, cached per :attr:`version`.

    Attributes:
        pose: (24, 3) float64 axis-angle, radians (SMPL order; joint 0 is the root).
        trans: (3,) float64 root translation, metres.
        version: incremented on every change of pose or trans.
        change: the last change in words ("left shoulder z -40°", "preset walk"), for
            labels such as the neural render's stale banner.
    """

    def __init__(self, data: ViewerData, pose=None, trans=None):
        self.data = data
        self.rest_trans = np.zeros(3)
        self.rest_root = np.zeros(3)  # the rest pose's root orientation (axis-angle)
        cap = data.capture
        if cap is not None and len(cap.trans):
            self.rest_trans = np.asarray(cap.trans[0], dtype=np.float64).copy()
            if needs_placing(cap, "auto"):  # a world not Y up: stand up, face camera 0
                pelvis = cap.body.rest_joints[0].double().numpy()
                zero = (np.zeros((1, 24, 3)), np.zeros((1, 3)))
                root, stand = place_in_capture(*zero, pelvis, cap, cap.cameras[0])
                self.rest_root, self.rest_trans = root[0, 0].copy(), stand[0].copy()
        if pose is None:
            self.pose = np.zeros((24, 3))
            self.pose[0] = self.rest_root
        else:
            self.pose = np.array(pose, np.float64).reshape(24, 3)
        self.trans = self.rest_trans.copy() if trans is None else np.array(trans, np.float64)
        self.version = 0
        self.change = "rest pose"
        self.moved: tuple[int, ...] = ()  # the joints the last change turned
        self._cache: dict[str, tuple[int, object]] = {}
        self._vocab_texture = None
        self._poser = None

    # -- editing ------------------------------------------------------------------------
    def _changed(self, pose: np.ndarray, trans: np.ndarray | None = None, change: str = "pose set") -> bool:
        trans = self.trans if trans is None else np.asarray(trans, np.float64).reshape(3)
        if np.array_equal(pose, self.pose) and np.array_equal(trans, self.trans):
            return False
        if not (np.isfinite(pose).all() and np.isfinite(trans).all()):
            raise TexvocabError("pose and translation must be finite")
        self.moved = tuple(int(j) for j in np.flatnonzero(np.any(pose != self.pose, axis=1)))
        self.pose, self.trans = pose, trans.copy()
        self.version += 1
        self.change = change
        return True

    def set_pose(self, pose, trans=None, change: str = "pose set") -> bool:
        """Replace the whole pose (24, 3) (and trans (3,)); no clamping. True if changed."""
        return self._changed(np.array(pose, np.float64).reshape(24, 3), trans, change)

    def joint_deg(self, j: int) -> np.ndarray:
        """(3,) axis-angle components of joint ``j`` in degrees (the sliders' values)."""
        return np.degrees(self.pose[j])

    def set_joint(self, j: int, xyz_deg) -> bool:
        """Set joint ``j``'s axis-angle components (degrees). The components that change
        are clamped to the joint's limits; the others keep their value even when it lies
        outside them (a pose loaded from a file), so moving one slider never snaps another."""
        lim = JOINT_LIMITS_DEG[j].astype(np.float64)
        old = np.degrees(self.pose[j])
        new = np.asarray(xyz_deg, np.float64).reshape(3)
        moved = ~np.isclose(new, old, rtol=0.0, atol=1e-9)
        deg = np.where(moved, np.clip(new, lim[:, 0], lim[:, 1]), old)
        pose = self.pose.copy()
        pose[j] = np.where(moved, np.radians(deg), self.pose[j])
        what = ", ".join(f"{'xyz'[a]} {deg[a]:.0f}°" for a in np.flatnonzero(moved))
        return self._changed(pose, change=f"{JOINT_NAMES[j].replace('_', ' ')} {what}")

    def out_of_limits(self, j: int) -> np.ndarray:
        """(3,) bool: which of joint ``j``'s components lie outside its limits (by more than
        a hundredth of a degree)."""
        lim = JOINT_LIMITS_DEG[j].astype(np.float64)
        deg = self.joint_deg(j)
        return (deg < lim[:, 0] - 1e-2) | (deg > lim[:, 1] + 1e-2)

    def set_trans(self, xyz) -> bool:
        return self._changed(self.pose.copy(), np.asarray(xyz, np.float64), "root moved")

    def reset_joint(self, j: int) -> bool:
        pose = self.pose.copy()
        pose[j] = 0.0
        return self._changed(pose, change=f"{JOINT_NAMES[j].replace('_', ' ')} reset")

    def reset_part(self, name: str) -> bool:
        """Rest pose for the joints of one of the five body parts (``BODY_PARTS``)."""
        if name not in BODY_PARTS:
            raise TexvocabError(f"unknown body part {name!r}; expected one of {PART_NAMES}")
        pose = self.pose.copy()
        pose[list(BODY_PARTS[name])] = 0.0
        return self._changed(pose, change=f"{name.replace('_', ' ')} reset")

    def reset_all(self) -> bool:
        """Rest pose (T-pose; the root upright: zero orientation in a Y-up world) at the rest
        translation."""
        pose = np.zeros((24, 3))
        pose[0] = self.rest_root
        return self._changed(pose, self.rest_trans, "rest pose")

    def apply_preset(self, name: str) -> bool:
        """A named preset (texvocab.body.poses), the whole pose: its joints, the rest pose's
        root orientation (upright, facing as the rest pose faces) and the rest translation
        plus the preset's offset; what ``texvocab shot --pose NAME`` shows, whatever the
        pose before."""
        if name not in PRESETS:
            raise TexvocabError(f"unknown pose preset {name!r}; expected one of {sorted(PRESETS)}")
        p, t = preset(name)
        pose = np.asarray(p, np.float64).copy()
        pose[0] = self.rest_root  # the presets' own roots are all zero
        return self._changed(pose, self.rest_trans + np.asarray(t, np.float64), f"preset {name}")

    def key_pose(self, part: str | int, key_index: int) -> tuple[tuple[int, ...], np.ndarray]:
        """(joints of the vocabulary part, their (J_p, 3) axis-angle in key ``key_index``)."""
        vocab = self._require_vocab()
        p = vocab.part_names.index(part) if isinstance(part, str) else int(part)
        if not 0 <= p < vocab.num_parts:
            raise TexvocabError(f"part {part!r}: the vocabulary has parts {vocab.part_names}")
        keys = vocab.key_quats[p]
        if not 0 <= key_index < len(keys):
            raise TexvocabError(f"key {key_index}: part {vocab.part_names[p]} has keys 0..{len(keys) - 1}")
        return vocab.part_joints[p], quat_to_rotvec(keys[key_index]).double().numpy()

    def set_part_to_key(self, part: str | int, key_index: int) -> bool:
        """Move the part's joints to the pose of one of its keys (not clamped: keys are
        training poses), making that key the part's nearest (distance ~0). Joints the
        vocabulary does not see (the root under a root-relative condition: its keys hold
        no facing) keep their rotation, so the body keeps facing where it faced."""
        joints, rotvecs = self.key_pose(part, key_index)
        ignored = self.data.vocab.ignored_joints
        seen = [i for i, j in enumerate(joints) if j not in ignored]
        pose = self.pose.copy()
        pose[[joints[i] for i in seen]] = rotvecs[seen]
        name = self.data.vocab.part_names[part] if isinstance(part, int) else part
        return self._changed(pose, change=f"{name.replace('_', ' ')} to key {key_index}")

    # -- derived, cached per version -----------------------------------------------------
    def _cached(self, key: str, make):
        hit = self._cache.get(key)
        if hit is not None and hit[0] == self.version:
            return hit[1]
        value = make()
        self._cache[key] = (self.version, value)
        return value

    def _require_vocab(self):
        if self.data.vocab is None:
            raise TexvocabError("no vocabulary: open a capture folder or a checkpoint")
        return self.data.vocab

    def query(self) -> list:
        """Per vocabulary part a :class:`~texvocab.method.vocab.PartQuery` (``key_ids``,
        ``frames``, ``weights`` (K,) each, ``distances`` (K,), ``novelty`` = distance to
        the nearest key); [] without a vocabulary."""
        if self.data.vocab is None:
            return []
        return self._cached("query", lambda: self.data.vocab.query(self.pose))

    def moved_parts(self) -> list[str]:
        """The vocabulary parts whose joints the last change turned (joints the vocabulary
        does not see, such as the root under a root-relative condition, do not count)."""
        vocab = self.data.vocab
        if vocab is None:
            return []
        seen = set(self.moved) - set(vocab.ignored_joints)
        return [
            n for n, joints in zip(vocab.part_names, vocab.part_joints, strict=True) if seen & set(joints)
        ]

    def key_distances(self) -> list[np.ndarray]:
        """Per vocabulary part, (M_p,) the distance (Eq. 4) of the pose to each of the
        part's keys, selected or not: the range a selected key's distance lies in."""
        vocab = self._require_vocab()

        def make():
            import torch

            quats = rotvec_to_quat(vocab.condition(torch.as_tensor(self.pose, dtype=torch.float64)))
            return [
                part_distance(quats[list(joints)], keys.double()).numpy()
                for joints, keys in zip(vocab.part_joints, vocab.key_quats, strict=True)
            ]

        return self._cached("key_distances", make)

    def novelty(self) -> np.ndarray:
        """(P,) distance of each vocabulary part to its nearest key (Eq. 4); (0,) without
        a vocabulary."""
        return np.array([q.novelty for q in self.query()], dtype=np.float64)

    def blended_texture(self) -> np.ndarray | None:
        """(S, S, 3) float32 texture of the current pose (texvocab.method.vocab_texture), or None
        without a vocabulary and texture maps."""
        if self.data.vocab is None or self.data.textures is None:
            return None
        if self._vocab_texture is None:
            self._vocab_texture = VocabTexture(self.data.body, self.data.vocab, self.data.textures)
        return self._cached("texture", lambda: self._vocab_texture.blend(self.pose, self.query()))

    def posed(self) -> tuple[np.ndarray, np.ndarray]:
        """(vertices (V, 3), joints (24, 3)) float32 of the current pose, world space."""

        def make():
            if self._poser is None:
                self._poser = BodyPoser(self.data.body)
            verts, joints = self._poser(self.pose, self.trans)
            return verts.astype(np.float32), joints.astype(np.float32)

        return self._cached("posed", make)
