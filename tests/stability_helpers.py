"""Builders and checks shared by tests/pipeline/test_stability.py: a small real avatar (default
body, a vocabulary of a few random training poses, 32² texture maps, a small encoder and
field), cameras around a posed body, and finiteness checks for values and gradients."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import torch
from torch import nn

from texvocab.capture.camera import Camera
from texvocab.geometry.rotations import rotvec_to_quat
from texvocab.method.encoder import build_encoder
from texvocab.method.feature import PoseContext, PoseFeature
from texvocab.method.field import AvatarField, FieldSettings
from texvocab.method.vocab import Vocabulary, knn_weights, part_distance
from texvocab.render import MarchSettings, ShellGeometry, render_rays

NUM_FRAMES = 6
TEXTURE_SIZE = 32
FIELD = FieldSettings(
    hidden=32,
    sdf_layers=2,
    color_layers=1,
    pos_freqs=4,
    dir_freqs=2,
    feature_proj=16,
    position_encoding="frequencies",
    triplane_resolution=16,
)
#: the trainer's march (all coarse samples in one call), small enough for tests
MARCH = MarchSettings.from_flat(coarse_samples=8, fine_samples=4, segment=512, scout_threshold=None)


class PassThrough(nn.Module):
    """Frozen 'encoder' returning the texture itself, so features can be checked exactly."""

    feature_dim = 3
    trainable = False

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x


def training_poses(seed: int = 0) -> np.ndarray:
    """(NUM_FRAMES, 24, 3) poses: frame 0 is the rest pose, the others random (σ 0.3 rad)."""
    poses = np.random.default_rng(seed).normal(0, 0.3, (NUM_FRAMES, 24, 3))
    poses[0] = 0.0
    return poses


def make_field(
    body,
    vocab: Vocabulary,
    textures: torch.Tensor | None = None,
    encoder: nn.Module | str = "small",
    seed: int = 0,
    position_encoding: str = "frequencies",
) -> AvatarField:
    """An AvatarField over ``vocab`` with random (seeded) 32² textures unless given.

    The SDF net's last layer, zero at initialisation, is randomised like a trained one's,
    so the SDF residual and the pose conditioning take part in every value and gradient;
    so are the tri-plane features with ``position_encoding="triplane"`` (16² planes).
    """
    gen = torch.Generator().manual_seed(seed)
    if textures is None:
        textures = torch.rand(NUM_FRAMES, 3, TEXTURE_SIZE, TEXTURE_SIZE, generator=gen)
    with torch.random.fork_rng():
        torch.manual_seed(seed)
        enc = build_encoder(encoder) if isinstance(encoder, str) else encoder
        field = AvatarField(PoseFeature(body, vocab, textures, enc), FIELD)
        with torch.no_grad():
            field.sdf_net[-1].weight.normal_(0.0, 0.05, generator=gen)
            field.sdf_net[-1].bias.normal_(0.0, 0.01, generator=gen)
    if position_encoding == "frequencies":
        return field
    return with_triplane(field, position_encoding, gen)


def with_triplane(plain: AvatarField, position_encoding: str, gen: torch.Generator) -> AvatarField:
    """``plain`` with tri-plane features added: the same weights (the SDF network's first
    layer gains the planes' input columns), the planes random (σ 0.01), so the field is the
    plain one's geometry plus features that take part in every value and gradient."""
    settings = replace(FIELD, position_encoding=position_encoding)
    field = AvatarField(plain.pose_feature, settings)
    d = plain.position_dim
    with torch.no_grad():
        source = dict(plain.named_parameters())
        for name, p in field.named_parameters():
            if name.startswith("triplane"):
                p.normal_(0.0, 0.01, generator=gen)
            elif name == "sdf_net.0.weight":  # the planes' columns keep their initial values
                p[:, :d] = source[name][:, :d]
                p[:, field.position_dim :] = source[name][:, d:]
            else:
                p.copy_(source[name])
    return field


def look_at(center, eye, size: int = 12, focal: float | None = None) -> Camera:
    """A ``size``² pinhole camera at ``eye`` (3,) looking at ``center`` (3,), y up."""
    center, eye = np.asarray(center, float), np.asarray(eye, float)
    fwd = (center - eye) / np.linalg.norm(center - eye)
    up = np.array([0.0, 1.0, 0.0]) if abs(fwd[1]) < 0.9 else np.array([0.0, 0.0, 1.0])
    right = np.cross(fwd, up)
    right /= np.linalg.norm(right)
    down = np.cross(fwd, right)
    R = np.stack([right, down, fwd])  # rows: camera x (right), y (down), z (forward)
    f = focal if focal is not None else 1.2 * size
    K = np.array([[f, 0, (size - 1) / 2], [0, f, (size - 1) / 2], [0, 0, 1]])
    return Camera(K, R, -R @ eye, size, size)


def front_camera(vertices: torch.Tensor, size: int = 12, distance: float = 3.0) -> Camera:
    """A camera ``distance`` m in front (+z) of the posed body's bounding-box centre."""
    v = vertices.detach().double().numpy()
    c = (v.min(0) + v.max(0)) / 2
    return look_at(c, c + np.array([0.0, 0.0, distance]), size)


def shell_points(ctx: PoseContext, n: int = 300, sigma: float = 0.01, seed: int = 0) -> torch.Tensor:
    """(n, 3) float32 points near the posed surface (vertices plus N(0, σ²) noise)."""
    rng = np.random.default_rng(seed)
    v = ctx.vertices.detach()
    idx = torch.as_tensor(rng.integers(0, len(v), n))
    return v[idx] + torch.as_tensor(rng.normal(0, sigma, (n, 3)), dtype=v.dtype)


def assert_finite(**tensors: torch.Tensor) -> None:
    """Every named tensor is finite (no NaN, no ±inf)."""
    for name, t in tensors.items():
        assert t is not None, f"{name} is None"
        bad = ~torch.isfinite(t)
        assert not bad.any(), f"{name}: {int(bad.sum())} non-finite of {t.numel()}"


def assert_param_grads(module: nn.Module, require_some: bool = True) -> None:
    """Gradients of ``module``'s parameters are finite; some are nonzero if asked."""
    grads = {n: p.grad for n, p in module.named_parameters() if p.grad is not None}
    assert grads, "no parameter received a gradient"
    assert_finite(**grads)
    if require_some:
        assert sum(float(g.abs().sum()) for g in grads.values()) > 0


@dataclass
class Rendered:
    """Values of one differentiable render_rays call and its ray count."""

    rgb: torch.Tensor
    opacity: torch.Tensor
    depth: torch.Tensor
    rays: int


def render_and_backprop(
    field: AvatarField,
    ctx: PoseContext,
    origins: torch.Tensor,
    dirs: torch.Tensor,
    shell: ShellGeometry | None = None,
    seed: int = 0,
) -> Rendered:
    """The training path: render_rays with the trainer's march and random samples, a
    colour + mask + depth loss, backward to the model parameters (zeroed first).

    Args: origins, dirs (R, 3); rays that miss the shell are kept (they must cost nothing).
    """
    shell = shell or ShellGeometry.build(
        ctx.vertices.detach(), field.body.faces, FIELD.shell_width, index=ctx.index
    )
    hit, near, far = shell.ray_bounds(origins, dirs)
    field.zero_grad(set_to_none=True)
    out = render_rays(
        field.for_pose(ctx),
        origins,
        dirs,
        near,
        far,
        MARCH,
        torch.Generator().manual_seed(seed),
        shell,
        background=(0.2, 0.4, 0.6),
    )
    assert_finite(rgb=out.rgb, opacity=out.opacity, depth=out.depth)
    if out.rgb.requires_grad:
        loss = (out.rgb - 0.5).square().mean() + (out.opacity - 1).abs().mean() + 0.01 * out.depth.mean()
        loss.backward()
    return Rendered(out.rgb.detach(), out.opacity.detach(), out.depth.detach(), int(hit.sum()))


def vocab_pose_gradient(vocab: Vocabulary, pose: torch.Tensor) -> tuple[torch.Tensor, list]:
    """d(loss)/d(pose) through the pose condition → quaternions → Eq. 4 distances →
    Eqs. 5–6 weights, float64.

    Args: pose (24, 3). Returns the gradient (24, 3) and per part (weights (K,), d (K,)).
    """
    pose = pose.detach().double().requires_grad_(True)
    quats = rotvec_to_quat(vocab.condition(pose))
    loss = pose.new_zeros(())
    parts = []
    for joints, keys in zip(vocab.part_joints, vocab.key_quats, strict=True):
        d = part_distance(quats[list(joints)], keys.double())
        idx, w = knn_weights(d, vocab.k, len(joints), vocab.weighting)
        ramp = torch.arange(1, w.shape[-1] + 1, dtype=w.dtype)
        loss = loss + (w * ramp).sum() + d.sum()
        parts.append((w.detach(), d[idx].detach()))
    (grad,) = torch.autograd.grad(loss, pose)
    return grad, parts
