"""The pose feature f(Θ, x) of Sec. 3.4:

    f(Θ_t, x) = Σ_p Ω(x, p) · h(x_uv, F_{p,t}),   F_{p,t} = Σ_k ŵ_{p,k} F̂_k   (Eqs. 5, 7–9)

x is projected onto the posed body (observation space, as the paper does, not x_c) to
get its UV x_uv and interpolated skinning weights ω, which give the attention Ω. Since
bilinear sampling h is linear in the feature map, h(x_uv, Σ_k ŵ F̂_k) = Σ_k ŵ h(x_uv, F̂_k):
we never blend whole maps. Per pose, the vocabulary query turns into one coefficient per
(part, training frame); per point, Ω mixes those into one coefficient per frame, and each
referenced frame's features are sampled only at the points whose coefficient is non-zero
— parts with zero attention cost nothing. The per-pose work (posed mesh, surface index,
query, feature maps) lives in a :class:`PoseContext` reused by every ray of a frame.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch
from torch import nn

from texvocab.body.parts import part_membership
from texvocab.body.pose_condition import condition_pose
from texvocab.geometry.surface import SurfaceIndex
from texvocab.method.feature_maps import FeatureMaps, sample_maps
from texvocab.torch_threads import one_torch_thread

__all__ = ["FeatureMaps", "FeatureOutput", "PoseContext", "PoseFeature", "naive_pose_feature", "sample_maps"]


@dataclass
class PoseContext:
    """Everything about one pose that every ray of a frame shares.

    ``pose`` is the full pose the body is posed with (root orientation included);
    :attr:`condition` is the pose the field's Θ reads, under ``pose_condition`` (the
    vocabulary's, :mod:`texvocab.body.pose_condition`)."""

    pose: torch.Tensor  # (24, 3)
    vertices: torch.Tensor  # (V, 3) posed
    transforms: torch.Tensor  # (J, 4, 4) rest -> posed per joint (inverse LBS uses them)
    index: SurfaceIndex
    frames: torch.Tensor  # (U,) training frames the pose's keys point to
    part_coef: torch.Tensor  # (P, U) Σ_k ŵ_{p,k} over keys of part p pointing to frame u
    features: FeatureMaps | None  # the U frames' encoder maps (a frozen encoder's are
    # rows of its cache's table, shared by every pose: never copied per pose)
    pose_condition: str = "global"
    stats: dict = field(default_factory=dict)
    # training with pose refinement: the frame's point warp x -> x' (PointWarp), else None
    warp: object | None = None

    @property
    def condition(self) -> torch.Tensor:
        """(24, 3) the pose as the field's Θ sees it (computed from ``pose`` on each read,
        so gradients reach ``pose``)."""
        return condition_pose(self.pose, self.pose_condition)


@dataclass
class FeatureOutput:
    features: torch.Tensor  # (N, C) f(Θ, x); zero for invalid points
    uv: torch.Tensor  # (N, 2)
    skin_weights: torch.Tensor  # (N, J) of the closest surface point
    distance: torch.Tensor  # (N,) signed distance to the posed body (negative inside)
    closest: torch.Tensor  # (N, 3) closest point on the posed body
    valid: torch.Tensor  # (N,) bool: within max_distance of the body


class PoseFeature(nn.Module):
    """f(Θ, x) for a body, a vocabulary, the training texture maps and an encoder.

    Args:
        body: :class:`~texvocab.body.BodyModel` with UVs.
        vocab: :class:`~texvocab.method.vocab.Vocabulary` built from the same training frames.
        textures: (T, 3, S, S) texture maps U_t in [0, 1], indexed like the vocabulary's
            key frames.
        encoder: a :class:`~texvocab.method.encoder.TextureEncoder`; a frozen one's feature maps
            are computed once per frame and cached, a trainable one's on every context.
        betas: (1, S) the subject's shape (``Capture.shape()``), or None: every pose is
            posed with it, as the texture maps were.
    """

    def __init__(
        self, body, vocab, textures: torch.Tensor, encoder: nn.Module, betas: torch.Tensor | None = None
    ):
        super().__init__()
        self.body = body
        self.betas = None if betas is None else torch.as_tensor(betas).reshape(1, -1)
        self.vocab = vocab
        self.encoder = encoder
        # not in the state dict: a checkpoint's maps are rebuilt from the capture's cache
        # (432 maps of 256² are 340 MB of float32); older checkpoints that stored them
        # load them back (texvocab.pipeline.avatar.load_stored_textures)
        self.register_buffer("textures", torch.as_tensor(textures, dtype=torch.float32), persistent=False)
        self.register_buffer("membership", part_membership(vocab.part_joints, body.num_joints))
        self._frozen_table: FeatureMaps | None = None  # frozen encoder: all frames' maps
        self._frozen_filled: set[int] = set()

    @property
    def feature_dim(self) -> int:
        return int(self.encoder.feature_dim)

    def feature_maps(self, frames: torch.Tensor) -> FeatureMaps:
        """Encoder feature maps of the given training frames (U,). A frozen encoder's are
        computed once per frame into one table for all training frames, shared by every
        context; a trainable one's are recomputed (with gradients)."""
        if getattr(self.encoder, "trainable", True):
            return FeatureMaps.from_stack(self.encoder(self.textures[frames]))
        missing = [int(f) for f in frames if int(f) not in self._frozen_filled]
        if missing:
            with torch.no_grad():
                new = FeatureMaps.from_stack(self.encoder(self.textures[missing]))
            if self._frozen_table is None:
                h, w = new.height, new.width
                self._frozen_table = FeatureMaps(
                    new.table.new_zeros(len(self.textures) * h * w, new.channels),
                    torch.zeros(0, dtype=torch.long),
                    h,
                    w,
                )
            cache, size = self._frozen_table, new.height * new.width
            for i, f in enumerate(missing):
                cache.table[f * size : (f + 1) * size] = new.table[i * size : (i + 1) * size]
            self._frozen_filled.update(missing)
        cache = self._frozen_table
        return FeatureMaps(
            cache.table,
            torch.as_tensor(frames, dtype=torch.long) * (cache.height * cache.width),
            cache.height,
            cache.width,
        )

    def warm_feature_maps(self, batch: int = 8) -> int:
        """Encode every key frame's texture map into a frozen encoder's cache now (in
        batches of ``batch``), so no later pose pays for the keys it selects first: a
        viewer's first render of a pose whose keys were not seen before took 15-17 ms of
        pose context instead of 8. Returns how many frames were encoded (0 with a
        trainable encoder, whose maps are recomputed on every context anyway)."""
        if getattr(self.encoder, "trainable", True):
            return 0
        frames = sorted({int(f) for keys in self.vocab.key_frames for f in keys} - self._frozen_filled)
        for i in range(0, len(frames), batch):
            self.feature_maps(torch.as_tensor(frames[i : i + batch], dtype=torch.long))
        return len(frames)

    def context(self, pose, trans=None, like=None) -> PoseContext:
        """Per-pose work: posed body, its surface index, the vocabulary query, features.
        ``like``: a surface index of another pose whose slot layout the new index borrows
        (:class:`~texvocab.geometry.surface.SurfaceIndex`; same answers, a cheaper build).
        With autograd off its small operations run on one torch thread
        (:mod:`texvocab.torch_threads`)."""
        with one_torch_thread(not torch.is_grad_enabled()):
            return self._context(pose, trans, like)

    def _context(self, pose, trans, like) -> PoseContext:
        pose = torch.as_tensor(np.asarray(pose), dtype=torch.float32).reshape(24, 3)
        trans = torch.zeros(3) if trans is None else torch.as_tensor(np.asarray(trans), dtype=torch.float32)
        posed = self.body.forward(pose[None], trans.reshape(1, 3), self.betas)
        verts = posed.vertices[0]
        index = SurfaceIndex(verts.detach().double().numpy(), self.body.faces.numpy(), like=like)
        part_frames, part_weights, _ = self.vocab.query_tensors(pose.double())
        condition = self.vocab.pose_condition
        if not part_frames:  # strategy "none": no vocabulary, no texture feature (zeros)
            return PoseContext(
                pose,
                verts,
                posed.transforms[0],
                index,
                torch.zeros(0, dtype=torch.long),
                torch.zeros(0, 0),
                None,
                condition,
            )
        all_frames = torch.cat([f[0] for f in part_frames])
        frames, inverse = torch.unique(all_frames, return_inverse=True)
        coef = torch.zeros(self.vocab.num_parts, len(frames), dtype=torch.float64)
        start = 0
        for p, w in enumerate(part_weights):
            k = w.shape[-1]
            coef[p].index_add_(0, inverse[start : start + k], w[0])
            start += k
        return PoseContext(
            pose,
            verts,
            posed.transforms[0],
            index,
            frames,
            coef.float(),
            self.feature_maps(frames),
            condition,
        )

    def _projection_tables(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The body's vt (T, 2) float64, ft (F, 3) int64 and skinning weights (V, J)
        float64 as the projection reads them, converted once (the weights' float64 copy
        cost 0.2 ms a call) and again only if a table changes."""
        tables = (self.body.vt, self.body.ft, self.body.weights)
        key = tuple((id(t), t._version) for t in tables)
        cached = getattr(self, "_tables", None)
        if cached is None or cached[0] != key:
            arrays = tuple(
                np.ascontiguousarray(t.detach().cpu().numpy(), dtype=dt)
                for t, dt in zip(tables, (np.float64, np.int64, np.float64))
            )
            self._tables = cached = (key, arrays)
        return cached[1]

    def forward(
        self,
        ctx: PoseContext,
        points: torch.Tensor,
        max_distance: float | None = None,
        known: torch.Tensor | None = None,
    ) -> FeatureOutput:
        """f(Θ, x) at points (N, 3) in the observation space of ``ctx``'s pose. ``known``
        (N,) long: each point's closest face of the posed body where the caller knows it
        (-1 elsewhere; :meth:`SurfaceIndex.project`'s ``known``: no search for those)."""
        proj = ctx.index.project(
            points.detach().double().cpu().numpy(),
            *self._projection_tables(),
            max_distance=max_distance,
            known=None if known is None else known.numpy(),
        )
        valid = torch.from_numpy(proj.face >= 0)
        n = points.shape[0]
        # converted whole, the invalid rows (NaN) then zeroed: copying the valid rows out
        # and back by a boolean mask took as long as the projection itself
        invalid = ~valid[:, None]
        uv, skin, closest = (
            torch.from_numpy(a).to(points.dtype).masked_fill_(invalid, 0.0)
            for a in (proj.uv, proj.weights, proj.closest)
        )
        dist = torch.as_tensor(proj.distance, dtype=points.dtype)
        total = skin.sum(-1, keepdim=True)
        omega = (skin @ self.membership.to(skin)) / torch.where(total > 0, total, torch.ones_like(total))
        coef = omega @ ctx.part_coef.to(omega)  # (N, U): Ω-weighted key weight per frame
        if ctx.features is None:
            feats = torch.zeros(n, self.feature_dim, dtype=points.dtype)
        else:
            feats = ctx.features.sample(uv, coef)
        sampled = int((coef > 0).sum())
        ctx.stats = {"frames": int(coef.shape[1]), "samples": sampled, "points": n}
        return FeatureOutput(feats.to(points.dtype), uv, skin, dist, closest, valid)


def naive_pose_feature(model: PoseFeature, ctx: PoseContext, points: torch.Tensor) -> torch.Tensor:
    """Reference: blend whole maps per part (Eq. 5), sample each at the projection's UV
    (Eq. 7), Ω-weighted sum (Eqs. 8–9)."""
    out = model(ctx, points)
    omega = out.skin_weights @ model.membership.to(out.skin_weights)
    omega = omega / out.skin_weights.sum(-1, keepdim=True).clamp(min=1e-12)
    total = torch.zeros_like(out.features)
    stack = ctx.features.stack()
    for p in range(ctx.part_coef.shape[0]):
        blended = torch.einsum("u,uchw->chw", ctx.part_coef[p].to(stack), stack)
        total = total + omega[:, p : p + 1] * sample_maps(blended, out.uv)
    return total * out.valid[:, None]
