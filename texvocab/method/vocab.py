"""TexVocab's body-part-wise vocabulary (Sec. 3.3) and its query (Sec. 3.4).

Per body part p, M key part-poses are chosen from the training frames by farthest point
sampling under the part distance of Eq. 4,

    d(ρ1, ρ2) = Σ_{k=1..J_p} (1 − |q(θ1^k) · q(θ2^k)|),

and each key keeps the frame whose texture map it points to. A query pose takes, per
part, its K nearest keys and weights w = J_p − d (Eq. 6), normalised to sum to one
(Eq. 5). Strategies: ``part`` (Table 1's five parts), ``joint`` (one part per joint),
``global`` (one part of all joints) — the paper's ablation.

Keys and queries read the pose under the vocabulary's ``pose_condition``
(:mod:`texvocab.body.pose_condition`): ``root-relative`` for new vocabularies (joint 0's
rotation, which says which way the body faces, removed), ``global`` for those recorded
before the condition existed (joint 0 as the reader folded the root orientation into it).
Root-relative, J_p in Eq. 6 stays the part's joint count (Table 1), the main body's
distances reach at most J_p − 1, and the ``joint`` strategy's pelvis part sees one pose:
its keys tie (the first M frames) and every query blends its first K keys uniformly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from texvocab.body.parts import STRATEGIES, body_parts
from texvocab.body.pose_condition import check_pose_condition, condition_pose, ignored_joints
from texvocab.geometry.rotations import rotvec_to_quat


def part_distance(query: torch.Tensor, keys: torch.Tensor) -> torch.Tensor:
    """Eq. 4 between part-poses.

    Args:
        query: (..., J_p, 4) unit quaternions; keys: (M, J_p, 4).

    Returns:
        (..., M) distances in [0, J_p].
    """
    dots = torch.einsum("...jc,mjc->...mj", query, keys).abs().clamp(max=1.0)
    return (1.0 - dots).sum(-1)


def farthest_point_sampling(
    quats: torch.Tensor, num: int, start: int = 0, min_distance: float = 0.0
) -> torch.Tensor:
    """Indices of up to ``num`` part-poses chosen by farthest point sampling under Eq. 4.

    Args:
        quats: (T, J_p, 4) part-poses of the training frames.
        num: M; capped at T.
        start: the first key (frame 0 by default: deterministic).
        min_distance: adaptive M: stop early once every part-pose is within this distance
            of a key (the farthest remaining one is no farther), so a part that barely
            moves gets few keys. 0: always ``num`` keys.

    Ties pick the lowest frame index; once every distinct pose is chosen, further keys
    repeat poses (distance 0), which the query handles.
    """
    t = quats.shape[0]
    num = min(num, t)
    chosen = [start]
    dist = part_distance(quats, quats[start : start + 1])[:, 0]
    dist[start] = -1.0
    for _ in range(num - 1):
        if float(dist.max()) <= min_distance and min_distance > 0:
            break
        nxt = int(torch.argmax(dist))  # argmax returns the first maximum: lowest index
        chosen.append(nxt)
        dist = torch.minimum(dist, part_distance(quats, quats[nxt : nxt + 1])[:, 0])
        dist[chosen] = -1.0
    return torch.tensor(chosen, dtype=torch.long)


WEIGHTINGS = ("paper", "inverse")


def knn_weights(
    dist: torch.Tensor, k: int, num_joints: int, weighting: str = "paper"
) -> tuple[torch.Tensor, torch.Tensor]:
    """K nearest keys and their normalised weights (Eqs. 5–6).

    Args:
        dist: (..., M) distances to every key; k: K (capped at M); num_joints: J_p.
        weighting: ``paper``: w = J_p − d (Eq. 6). With d ≪ J_p these weights are close to
            uniform over the K keys. ``inverse``: w = 1 / d, with a query equal to a key
            getting that key alone (weight exactly 1) — offered for comparison.

    Returns:
        idx (..., K) key indices, nearest first (ties: lower key index first);
        weights (..., K) summing to 1; when every w is 0 (all K keys at the maximum
        distance J_p) the weights are uniform instead of NaN.
    """
    if weighting not in WEIGHTINGS:
        raise ValueError(f"unknown weighting {weighting!r}; expected one of {WEIGHTINGS}")
    k = min(k, dist.shape[-1])
    # stable sort gives deterministic tie-breaking by key index
    d_sorted, idx = torch.sort(dist, dim=-1, stable=True)
    d_sorted, idx = d_sorted[..., :k], idx[..., :k]
    if weighting == "paper":
        w = (num_joints - d_sorted).clamp(min=0.0)
    else:
        exact = d_sorted <= 0.0
        safe = torch.where(exact, torch.ones_like(d_sorted), d_sorted)
        w = torch.where(exact.any(-1, keepdim=True), exact.to(d_sorted), 1.0 / safe)
    total = w.sum(-1, keepdim=True)
    uniform = torch.full_like(w, 1.0 / k)
    weights = torch.where(total > 0, w / torch.where(total > 0, total, torch.ones_like(total)), uniform)
    return idx, weights


@dataclass
class PartQuery:
    """The vocabulary's answer for one part of one pose."""

    part: str
    key_ids: np.ndarray  # (K,) indices into the part's keys
    frames: np.ndarray  # (K,) training frames whose texture maps the keys point to
    weights: np.ndarray  # (K,) sum to 1
    distances: np.ndarray  # (K,)

    @property
    def novelty(self) -> float:
        """Distance to the nearest key: how far this part's pose is from anything seen."""
        return float(self.distances[0])


@dataclass
class Vocabulary:
    """Keys per part. ``key_frames[p][m]`` is the training frame (index into the frames the
    vocabulary was built from) whose texture map key m of part p points to.
    ``pose_condition``: the pose its keys were taken from and its queries read
    (:func:`~texvocab.body.pose_condition.condition_pose`); a vocabulary given its keys
    directly, or read from a checkpoint that records none, is ``global``."""

    strategy: str
    part_names: list[str]
    part_joints: list[tuple[int, ...]]
    key_quats: list[torch.Tensor]  # per part (M_p, J_p, 4)
    key_frames: list[torch.Tensor]  # per part (M_p,)
    k: int
    weighting: str = "paper"
    pose_condition: str = "global"

    @classmethod
    def build(
        cls,
        poses,
        strategy: str = "part",
        num_keys: int = 20,
        k: int = 3,
        weighting: str = "paper",
        min_distance: float = 0.0,
        pose_condition: str = "root-relative",
    ) -> Vocabulary:
        """Farthest-point-sample ``num_keys`` keys per part from training poses (T, 24, 3)
        (fewer for a part whose poses all lie within ``min_distance`` of its keys; 0: every
        training frame is a key), read under ``pose_condition``."""
        poses = torch.as_tensor(np.asarray(poses), dtype=torch.float64)
        if poses.ndim != 3 or poses.shape[1:] != (24, 3) or len(poses) == 0:
            raise ValueError(f"poses must be (T, 24, 3) with T >= 1, got {tuple(poses.shape)}")
        if num_keys < 0 or k < 1:
            raise ValueError(f"num_keys must be >= 0 and k >= 1, got M={num_keys}, K={k}")
        num_keys = num_keys or len(poses)  # 0: a key per training frame
        if weighting not in WEIGHTINGS:
            raise ValueError(f"unknown weighting {weighting!r}; expected one of {WEIGHTINGS}")
        quats = rotvec_to_quat(condition_pose(poses, pose_condition))
        parts = body_parts(strategy)
        key_quats, key_frames = [], []
        for joints in parts.values():
            q = quats[:, list(joints)]
            idx = farthest_point_sampling(q, num_keys, min_distance=min_distance)
            key_quats.append(q[idx])
            key_frames.append(idx)
        return cls(
            strategy, list(parts), list(parts.values()), key_quats, key_frames, k, weighting, pose_condition
        )

    @property
    def num_parts(self) -> int:
        return len(self.part_names)

    def condition(self, pose) -> torch.Tensor:
        """The pose (..., 24, 3) as this vocabulary (and the field built on it) reads it."""
        return condition_pose(pose, self.pose_condition)

    @property
    def ignored_joints(self) -> tuple[int, ...]:
        """Joints whose rotation the queries do not see (their keys hold the identity)."""
        return ignored_joints(self.pose_condition)

    def query_tensors(self, pose) -> tuple[list[torch.Tensor], list[torch.Tensor], list[torch.Tensor]]:
        """Batched query: per part, frames (B, K), weights (B, K), distances (B, K).

        Args:
            pose: (B, 24, 3) or (24, 3) axis-angle, the full pose (read here under the
                vocabulary's ``pose_condition``).
        """
        pose = torch.as_tensor(np.asarray(pose), dtype=torch.float64)
        if pose.ndim == 2:
            pose = pose[None]
        quats = rotvec_to_quat(self.condition(pose))
        frames, weights, dists = [], [], []
        for joints, keys, kf in zip(self.part_joints, self.key_quats, self.key_frames, strict=True):
            d = part_distance(quats[:, list(joints)], keys)
            idx, w = knn_weights(d, self.k, len(joints), self.weighting)
            frames.append(kf[idx])
            weights.append(w)
            dists.append(torch.gather(d, -1, idx))
        return frames, weights, dists

    def query(self, pose) -> list[PartQuery]:
        """Per part: selected keys, their source frames, weights and distances (one pose)."""
        pose = torch.as_tensor(np.asarray(pose), dtype=torch.float64).reshape(24, 3)
        quats = rotvec_to_quat(self.condition(pose))
        out = []
        for name, joints, keys, kf in zip(
            self.part_names, self.part_joints, self.key_quats, self.key_frames, strict=True
        ):
            d = part_distance(quats[list(joints)], keys)
            idx, w = knn_weights(d, self.k, len(joints), self.weighting)
            out.append(PartQuery(name, idx.numpy(), kf[idx].numpy(), w.numpy(), d[idx].numpy()))
        return out

    def format_query(self, pose) -> str:
        """A table of :meth:`query` for people (``texvocab vocab``)."""
        sizes = sorted({len(f) for f in self.key_frames})
        keys = "-".join(str(m) for m in sizes[:: max(1, len(sizes) - 1)]) if sizes else "0"
        lines = [
            f"vocabulary: strategy={self.strategy}, M={keys} keys/part, "
            f"K={self.k}, weighting={self.weighting}, pose={self.pose_condition}",
            f"{'part':<16}{'novelty':>9}  keys (id:frame weight)",
        ]
        for q in self.query(pose):
            keys = "  ".join(
                f"{i}:{f} {w:.3f}" for i, f, w in zip(q.key_ids, q.frames, q.weights, strict=True)
            )
            lines.append(f"{q.part:<16}{q.novelty:>9.4f}  {keys}")
        return "\n".join(lines)

    def to_dict(self) -> dict:
        """Plain containers and tensors (checkpoint-safe)."""
        return {
            "strategy": self.strategy,
            "part_names": list(self.part_names),
            "part_joints": [list(j) for j in self.part_joints],
            "key_quats": list(self.key_quats),
            "key_frames": list(self.key_frames),
            "k": self.k,
            "weighting": self.weighting,
            "pose_condition": self.pose_condition,
        }

    def check(self, num_frames: int) -> None:
        """ValueError unless the parts, keys and key frames are consistent: every part's
        keys are (M_p, J_p, 4) finite quaternions pointing to frames in [0, num_frames)."""
        if self.strategy not in STRATEGIES or self.weighting not in WEIGHTINGS or self.k < 1:
            raise ValueError(f"strategy {self.strategy!r}, weighting {self.weighting!r}, k {self.k!r}")
        check_pose_condition(self.pose_condition)
        if not len(self.part_names) == len(self.part_joints) == len(self.key_quats) == len(self.key_frames):
            raise ValueError("parts, joints, keys and key frames differ in number")
        for name, joints, q, f in zip(
            self.part_names, self.part_joints, self.key_quats, self.key_frames, strict=True
        ):
            if not all(0 <= j < 24 for j in joints):
                raise ValueError(f"part {name}: joints {joints} outside 0..23")
            if not (isinstance(q, torch.Tensor) and isinstance(f, torch.Tensor)):
                raise ValueError(f"part {name}: keys are not tensors")
            if q.ndim != 3 or q.shape[1:] != (len(joints), 4) or len(f) != len(q) or not len(q):
                raise ValueError(
                    f"part {name}: keys {tuple(q.shape)} and frames {tuple(f.shape)} for {len(joints)} joints"
                )
            if not torch.isfinite(q).all() or f.min() < 0 or f.max() >= num_frames:
                raise ValueError(f"part {name}: non-finite keys or frames outside 0..{num_frames - 1}")

    @classmethod
    def from_dict(cls, d: dict) -> Vocabulary:
        """The vocabulary :meth:`to_dict` wrote; one without ``pose_condition`` (written
        before it existed) is ``global``, so its keys keep their meaning."""
        return cls(
            d["strategy"],
            list(d["part_names"]),
            [tuple(j) for j in d["part_joints"]],
            list(d["key_quats"]),
            list(d["key_frames"]),
            int(d["k"]),
            d["weighting"],
            d.get("pose_condition", "global"),
        )
