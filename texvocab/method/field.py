"""The avatar field g(γ(x_c), γ(d), f(Θ, x), Θ) → (SDF, RGB) (Eq. 1, Sec. 3.5) and VolSDF's
density (Yariv et al. 2021).

* x is canonicalised by inverse LBS with the skinning weights of its closest point on
  the posed body: x_c = (Σ_j ω_j A_j)^-1 x.
* SDF = d_body(x) - g(x) + MLP(γ(x_c), f, Θ): the signed distance to the posed body, less
  the body's girth g (zero unless fitted to the masks, :mod:`texvocab.body.girth`), plus a
  learned residual whose last layer starts at zero — the geometric initialisation is the
  body surface itself (for a clothed person the residual is small), which is what makes
  short CPU training converge.
* Θ is the pose's condition (:attr:`~texvocab.method.feature.PoseContext.condition`), the
  vocabulary's: root-relative in new models, so x_c, f and Θ, and with them the SDF, do
  not change when the whole body turns; γ(d) reads the viewing direction in the world.
* density σ = α Ψ_β(−SDF), α = 1/β, Ψ_β the Laplace CDF, evaluated with exponentials of
  non-positive arguments only, so σ stays finite as β → 0 (β is clamped at ``beta_min``).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import ClassVar

import torch
import torch.nn.functional as F
from torch import nn

from texvocab.geometry.rotations import rotvec_to_quat
from texvocab.knobs import Check, at_least, check_group, count_in, knob, within
from texvocab.method.feature import PoseContext, PoseFeature
from texvocab.method.field_precision import PRECISIONS, resolve_precision  # noqa: F401 (PRECISIONS: re-exported)
from texvocab.method.frozen_mlps import FrozenMLPs
from texvocab.method.triplane import CanonicalTriplane, canonical_box
from texvocab.torch_threads import one_torch_thread

VIEW_FRAMES = ("world", "body")
SHELL_SHAPES = ("uniform", "joints")
POSITION_ENCODINGS = ("frequencies", "triplane")
#: the tri-plane's box: the canonical body's vertices widened by this on every side (m),
#: more than the widest shell (12 cm) with room for a fitted body's rest shape
TRIPLANE_MARGIN = 0.15


@dataclass
class FieldSettings:
    """The field's network sizes and VolSDF's β (settings group ``field``); each size trades
    speed for capacity."""

    GROUP: ClassVar[str] = "field"

    pos_freqs: int = knob(6, count_in(0, 16), doc="γ_x frequencies")
    dir_freqs: int = knob(4, count_in(0, 16), doc="γ_d frequencies")
    feature_proj: int = knob(32, at_least(1), doc="f(Θ, x) is linearly projected to this many channels")
    hidden: int = knob(128, at_least(1), doc="width of the SDF network (the colour network's is half)")
    sdf_layers: int = knob(3, at_least(1), doc="hidden layers of the SDF network")
    color_layers: int = knob(2, at_least(0), doc="hidden layers of the colour network")
    beta_init: float = knob(
        0.005,
        Check(lambda v, g: v >= g.beta_min, ">= field.beta_min"),
        doc="VolSDF β at the start of training (m)",
    )
    # float32 VolSDF density and its gradients break down for beta below ~1e-17
    beta_min: float = knob(1e-4, at_least(1e-8), doc="β is clamped at this (m)")
    shell_width: float = knob(
        0.04,
        within(0, 1, open_low=True, unit=" m"),
        doc="points farther from the body count as empty space (m); with shell_coverage "
        "the narrowest shell, widened at the start of training to reach the masks",
    )
    shell_coverage: float | None = knob(
        0.97,
        within(0, 1, open_low=True),
        doc="a new run widens shell_width (in 1 cm steps, up to 12 cm) until this share of "
        "the training masks' pixels see the posed body within it, so clothing and hair off "
        "the body (or a fit centimetres off) stay inside the field; none: shell_width as "
        "given (texvocab.pipeline.shell_fit)",
    )
    shell_shape: str = knob(
        "uniform",
        Check(lambda v, g: v in SHELL_SHAPES, "one of " + ", ".join(SHELL_SHAPES)),
        doc="with shell_coverage, one width for the whole body, or one per body part (a "
        "joint and its mirror twin): each part's narrowest width that reaches the share of "
        "the mask pixels whose rays come closest to it; shell_width is then the widest",
    )
    view_frame: str = knob(
        "world",
        Check(lambda v, g: v in VIEW_FRAMES, "one of " + ", ".join(VIEW_FRAMES)),
        doc="γ(d) reads the viewing direction in the world, or in the body's frame at the point "
        "(d_c = R⁻¹d, R the blended bone rotation): how the body faces the camera and lights",
    )

    position_encoding: str = knob(
        "triplane",
        Check(lambda v, g: v in POSITION_ENCODINGS, "one of " + ", ".join(POSITION_ENCODINGS)),
        doc="how x_c enters the SDF network: γ(x_c) alone, or γ(x_c) and learned feature "
        "planes over the canonical body (texvocab.method.triplane)",
    )
    triplane_resolution: int = knob(256, at_least(2), doc="texels on each side of a tri-plane")
    triplane_channels: int = knob(8, at_least(1), doc="features of each of the three planes")

    def __post_init__(self) -> None:
        check_group(self)

    def to_dict(self) -> dict:
        return asdict(self)


def positional_encoding(x: torch.Tensor, freqs: int) -> torch.Tensor:
    """γ(x) = [x, sin(2^k π x), cos(2^k π x)]_{k<freqs}: (N, D) → (N, D (1 + 2 freqs))."""
    scales = (2.0 ** torch.arange(freqs, dtype=x.dtype, device=x.device)) * torch.pi
    xs = x[..., None] * scales
    return torch.cat([x, xs.sin().flatten(-2), xs.cos().flatten(-2)], -1)


def laplace_density(sdf: torch.Tensor, beta: torch.Tensor) -> torch.Tensor:
    """VolSDF σ = (1/β) Ψ_β(−sdf), Ψ_β the CDF of a zero-mean Laplace with scale β.

    Only exp of non-positive numbers is evaluated, so values and gradients are finite for
    any β > 0 and any sdf.
    """
    s = -sdf
    e = torch.exp(-s.abs() / beta)
    psi = torch.where(s <= 0, 0.5 * e, 1.0 - 0.5 * e)
    return psi / beta


def pose_input(pose: torch.Tensor, eps: float = 1e-6) -> torch.Tensor:
    """The field's pose input Θ from the pose its context conditions the field on
    (:attr:`~texvocab.method.feature.PoseContext.condition`: root-relative, or global in
    old checkpoints): per joint the unit quaternion of its rotation, signed so
    that q and -q (the same rotation, e.g. θ and θ - 2π about one axis) give one input:
    w > 0, or for |w| <= eps (θ ≈ π) the first of x, y, z beyond eps positive. Identical
    to ``rotvec_to_quat`` for rotation vectors of norm < π (w > 0 already), so weights
    trained before this canonicalisation keep their meaning. (J, 3) -> (J, 4)."""
    q = rotvec_to_quat(pose)
    key = q[..., 0]
    for i in (1, 2, 3):
        key = torch.where(key.abs() <= eps, q[..., i], key)
    return torch.where((key < 0)[..., None], -q, q)


class NormalSoftplus(nn.Softplus):
    """Softplus_β(x) = log(1 + exp(βx)) / β with βx floored at -``FLOOR``: the same function
    to float32 rounding (the floor changes a value of at most e^-25 / β = 1.4e-13 / β into
    that, and the gradient there from at most 1.4e-11 into 0), without its subnormal
    numbers. Below βx ≈ -87, exp(βx) and the log1p after it compute with subnormal floats,
    which this CPU handles in microcode: a trained field's pre-activations reach there
    often enough that the activation took 4x its time (9.5 against 2.3 ms for 10k × 128
    values, forward; 2x with the backward pass). Weights keep their meaning: it has no
    parameters, and nn.Softplus(beta=100) checkpoints load unchanged."""

    FLOOR = 25.0

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return F.softplus(x.clamp(min=-self.FLOOR / self.beta), self.beta, self.threshold)


def _mlp(d_in: int, hidden: int, layers: int, d_out: int) -> nn.Sequential:
    mods: list[nn.Module] = []
    for i in range(layers):
        mods += [nn.Linear(d_in if i == 0 else hidden, hidden), NormalSoftplus(beta=100)]
    mods.append(nn.Linear(hidden if layers else d_in, d_out))
    return nn.Sequential(*mods)


class AvatarField(nn.Module):
    """The neural avatar: callable per pose context as ``field(ctx, points, dirs)``."""

    def __init__(self, pose_feature: PoseFeature, settings: FieldSettings | None = None):
        super().__init__()
        s = settings or FieldSettings()
        self.settings = s
        self.pose_feature = pose_feature
        self.body = pose_feature.body
        self.feature_proj = nn.Linear(pose_feature.feature_dim, s.feature_proj)
        self.triplane = None
        if s.position_encoding == "triplane":
            lo, hi = canonical_box(self.body.v_template, TRIPLANE_MARGIN)
            self.triplane = CanonicalTriplane(lo, hi, s.triplane_resolution, s.triplane_channels)
        d_x = self.position_dim
        d_pose = 4 * self.body.num_joints
        self.sdf_net = _mlp(d_x + s.feature_proj + d_pose, s.hidden, s.sdf_layers, 1 + s.hidden)
        last = self.sdf_net[-1]
        nn.init.zeros_(last.weight)  # geometric initialisation: SDF = the posed body's
        nn.init.zeros_(last.bias)
        d_d = 3 * (1 + 2 * s.dir_freqs)
        self.color_net = _mlp(s.hidden + d_d + s.feature_proj, s.hidden // 2, s.color_layers, 3)
        self.log_beta = nn.Parameter(torch.tensor(float(s.beta_init)).log())
        # per-joint girth (m): the SDF starts at d_body - g (texvocab.body.girth); stored in
        # the checkpoint beside the weights (``body_girth``), zero for older ones
        self.register_buffer("girth", torch.zeros(self.body.num_joints), persistent=False)
        # per-joint shell widths (m; texvocab.pipeline.shell_fit, field.shell_shape=joints):
        # outside the body a point is in the shell within sum_j w_j widths_j of it; zero
        # (one width, shell_width, for the whole body) unless fitted, and for older runs
        self.register_buffer("shell_joints", torch.zeros(self.body.num_joints), persistent=False)

    def set_girth(self, offsets) -> None:
        """Start the SDF at ``d_body - sum_j w_j offsets_j`` (offsets (J,) m; w the skinning
        weights of a point's closest body point): the surface where the clothes stand off
        the body rather than on the body."""
        o = torch.as_tensor(offsets, dtype=self.girth.dtype).reshape(-1)
        if o.shape != self.girth.shape or not torch.isfinite(o).all():
            raise ValueError(f"girth: expected {self.girth.numel()} finite offsets (m), got {tuple(o.shape)}")
        self.girth.copy_(o)

    def set_shell_joints(self, widths) -> None:
        """Give each body part its own shell: outside the body, a point farther than
        ``sum_j w_j widths_j`` (widths (J,) m, at most ``shell_width``; w the skinning weights
        of its closest body point) is empty space. Zeros: ``shell_width`` everywhere."""
        w = torch.as_tensor(widths, dtype=self.shell_joints.dtype).reshape(-1)
        cap = self.settings.shell_width
        if w.shape != self.shell_joints.shape or not torch.isfinite(w).all() or (w < 0).any():
            raise ValueError(
                f"shell widths: expected {self.shell_joints.numel()} widths >= 0 (m), got {tuple(w.shape)}"
            )
        if bool((w > cap + 1e-6).any()):
            raise ValueError(
                f"shell widths: at most field.shell_width ({cap:g} m), got up to {float(w.max()):g}"
            )
        self.shell_joints.copy_(w)

    def in_shell(self, out) -> torch.Tensor:
        """(N,) bool: the projected points (a :class:`FeatureOutput`) that lie in the shell:
        within ``shell_width`` of the body, and outside it within their part's width where
        the shell is fitted part by part (:meth:`set_shell_joints`)."""
        if not bool(self.shell_joints.any()):
            return out.valid
        local = out.skin_weights.to(self.shell_joints.dtype) @ self.shell_joints
        return out.valid & ((out.distance <= local.to(out.distance)) | (out.distance <= 0))

    @property
    def position_dim(self) -> int:
        """Width of the SDF network's position input :meth:`position_input`."""
        width = 3 * (1 + 2 * self.settings.pos_freqs)
        return width + (0 if self.triplane is None else self.triplane.out_dim)

    def position_input(self, x_c: torch.Tensor) -> torch.Tensor:
        """The SDF network's position input for canonical points (N, 3): γ(x_c), then the
        tri-plane's features where the field has them; (N, position_dim)."""
        enc = positional_encoding(x_c, self.settings.pos_freqs)
        return enc if self.triplane is None else torch.cat([enc, self.triplane(x_c)], -1)

    @property
    def beta(self) -> torch.Tensor:
        return self.log_beta.exp().clamp(min=self.settings.beta_min)

    def canonicalize(
        self, ctx: PoseContext, points: torch.Tensor, skin: torch.Tensor, dirs: torch.Tensor | None = None
    ) -> torch.Tensor | tuple[torch.Tensor, torch.Tensor]:
        """x_c = (Σ_j ω_j A_j)^-1 x with ω the closest surface point's weights: (N, 3);
        with ``dirs`` (N, 3) also d_c = R⁻¹d (R the blend's linear part), renormalised:
        ``(x_c, d_c)`` from one solve."""
        blended = torch.einsum("nj,jrc->nrc", skin, ctx.transforms.to(skin))  # (N, 4, 4)
        rot, tr = blended[:, :3, :3], blended[:, :3, 3]
        eye = torch.eye(3, dtype=skin.dtype).expand_as(rot)
        rot = torch.where(skin.sum(-1, keepdim=True)[..., None] > 0, rot, eye)
        if dirs is None:
            return torch.linalg.solve(rot, (points - tr).unsqueeze(-1)).squeeze(-1)
        both = torch.linalg.solve(rot, torch.stack([points - tr, dirs.to(points)], -1))  # (N, 3, 2)
        d_c = both[..., 1]
        return both[..., 0], d_c / d_c.norm(dim=-1, keepdim=True).clamp(min=1e-9)

    def _sdf_hidden(self, ctx: PoseContext, x: torch.Tensor) -> torch.Tensor:
        """sdf_net([x, q(Θ)]) for per-point inputs x (N, D) and the pose's quaternions q
        (4J,), the same for every point: their part of the first layer is folded into its
        bias once per call (one (hidden, 4J) mat-vec) instead of a (N, 4J) block per
        point. Same function and gradients as ``sdf_net(cat([x, q]))`` up to float
        rounding; returns (N, 1 + hidden)."""
        weight, bias = self.first_sdf_layer(ctx, x.shape[1])
        return self.sdf_net[1:](F.linear(x, weight, bias))

    def first_sdf_layer(self, ctx: PoseContext, d: int) -> tuple[torch.Tensor, torch.Tensor]:
        """sdf_net's first layer for per-point inputs of width ``d`` at ``ctx``'s pose:
        (weight (hidden, d), bias (hidden,)), the pose's quaternion columns folded into
        the bias."""
        first = self.sdf_net[0]
        pose = pose_input(ctx.condition.to(first.weight.dtype)).reshape(-1)
        bias = first.bias + first.weight[:, d:].contiguous() @ pose
        # contiguous copies: row-aligned operands keep BLAS results bitwise reproducible
        return first.weight[:, :d].contiguous(), bias

    def sdf_and_color(
        self,
        ctx: PoseContext,
        points: torch.Tensor,
        dirs: torch.Tensor,
        precision: str = "float32",
        known: torch.Tensor | None = None,
        frozen: FrozenMLPs | None = None,
    ):
        """SDF (N,), RGB (N, 3), valid (N,) for world points (N, 3) and unit dirs (N, 3).
        ``known`` (N,) long: the points' closest faces where the caller knows them (-1
        elsewhere), which the projection onto the body takes without a search.

        Gradients of the SDF w.r.t. ``points`` are exact (the body distance contributes its
        analytic gradient), so the eikonal term can use autograd. ``precision``: the
        number format of the MLPs' products and activations (:data:`PRECISIONS`); the
        body distance, the projection and the inputs' encodings stay float32, and so do
        the outputs. "bfloat16" is for rendering (AMX matrix units on CPUs that have them).
        ``frozen``: the MLPs at this pose in ``precision``, cast once (rendering; used
        only with autograd off): the same numbers without autocast's per-call casts.
        """
        s = self.settings
        out = self.pose_feature(ctx, points, max_distance=s.shell_width, known=known)
        valid = self.in_shell(out)
        # d_body with its analytic gradient: value from the projection, slope = ∇d
        diff = points - out.closest
        norm = diff.norm(dim=-1, keepdim=True)
        grad_dir = torch.where(norm > 1e-9, diff / norm.clamp(min=1e-9), torch.zeros_like(diff))
        grad_dir = grad_dir * torch.sign(out.distance)[:, None]
        d_body = torch.where(valid, out.distance, torch.full_like(out.distance, s.shell_width))
        if bool(self.girth.any()):  # the clothes' room around the body (texvocab.body.girth)
            d_body = d_body - (out.skin_weights.to(self.girth.dtype) @ self.girth) * valid
        # pose refinement (training): the field at the corrected pose is the field at the
        # warped point (texvocab.method.pose_refinement); x = points without it
        x, d = (points, dirs) if ctx.warp is None else ctx.warp(points, dirs, out.skin_weights)
        d_body = d_body + ((x - points.detach()) * grad_dir.detach()).sum(-1)
        if s.view_frame == "body":  # the direction as the body at the point sees it
            x_c, d = self.canonicalize(ctx, x, out.skin_weights, d)
        else:
            x_c = self.canonicalize(ctx, x, out.skin_weights)
        if frozen is not None and not torch.is_grad_enabled():
            feat = frozen.project(out.features)
            h = frozen.sdf_hidden(torch.cat([self.position_input(x_c).to(feat), feat], -1))
            color_in = torch.cat([h[:, 1:], positional_encoding(d, s.dir_freqs).to(h), feat.to(h)], -1)
            rgb = torch.sigmoid(frozen.color(color_in).to(points.dtype))
            sdf = d_body + h[:, 0].to(points.dtype) * valid
            return sdf, rgb, valid
        dtype = resolve_precision(precision)
        with torch.autocast("cpu", dtype=dtype, enabled=dtype != torch.float32):
            feat = self.feature_proj(out.features.to(points.dtype))
            h = self._sdf_hidden(ctx, torch.cat([self.position_input(x_c), feat.to(x_c)], -1))
            color_in = torch.cat([h[:, 1:], positional_encoding(d, s.dir_freqs).to(h), feat.to(h)], -1)
            rgb = torch.sigmoid(self.color_net(color_in).to(points.dtype))
        sdf = d_body + h[:, 0].to(points.dtype) * valid
        return sdf, rgb, valid

    def forward(self, ctx: PoseContext, points: torch.Tensor, dirs: torch.Tensor, precision: str = "float32"):
        """(density (N,), rgb (N, 3)): the callable the ray marcher integrates."""
        sdf, rgb, valid = self.sdf_and_color(ctx, points, dirs, precision)
        density = laplace_density(sdf, self.beta) * valid
        return density, rgb

    def for_pose(self, ctx: PoseContext, precision: str = "float32") -> PoseField:
        """The field at one pose, as the marchers call it, its MLPs evaluated in
        ``precision`` (:data:`PRECISIONS`; the ``render.precision`` knob)."""
        return PoseField(self, ctx, precision)


class PoseField:
    """The avatar field at one pose: ``field(points, dirs) -> (density, rgb)`` for the
    shell marcher, ``field.sdf_rgb(points, dirs) -> (sdf, rgb)`` and ``field.beta`` for the
    surface-guided one (points more than the shell width from the body read SDF =
    shell width: no density); ``precision`` as :meth:`AvatarField.sdf_and_color`'s.
    ``sdf_rgb`` takes the points' ``known`` closest faces of the posed body too
    (:attr:`takes_known`), which the guided marcher passes where the raster or its own
    mesh queries found them."""

    takes_known = True

    def __init__(self, model: AvatarField, ctx: PoseContext, precision: str = "float32"):
        resolve_precision(precision)  # a ValueError for an unknown name, here
        self.model, self.ctx, self.precision = model, ctx, precision
        self._frozen: FrozenMLPs | None = None

    def frozen(self) -> FrozenMLPs | None:
        """The MLPs at this pose cast once (:class:`FrozenMLPs`), made on the first call
        with autograd off and again if the weights changed since; None with autograd on
        (training takes the autocast path, whose gradients reach the weights)."""
        if torch.is_grad_enabled() or self.ctx.warp is not None:
            return None
        if self._frozen is None or not self._frozen.current():
            self._frozen = FrozenMLPs(self.model, self.ctx, self.precision)
        return self._frozen

    def __call__(self, points: torch.Tensor, dirs: torch.Tensor):
        frozen = self.frozen()
        with one_torch_thread(frozen is not None and points.shape[0] < ONE_THREAD_POINTS):
            sdf, rgb, valid = self.model.sdf_and_color(self.ctx, points, dirs, self.precision, frozen=frozen)
        return laplace_density(sdf, self.model.beta) * valid, rgb

    def sdf_rgb(self, points: torch.Tensor, dirs: torch.Tensor, known: torch.Tensor | None = None):
        frozen = self.frozen()
        with one_torch_thread(frozen is not None and points.shape[0] < ONE_THREAD_POINTS):
            sdf, rgb, valid = self.model.sdf_and_color(
                self.ctx, points, dirs, self.precision, known, frozen=frozen
            )
        return torch.where(valid, sdf, self.model.settings.shell_width), rgb

    @property
    def beta(self) -> float:
        return float(self.model.beta.detach())


#: a render-time field call on fewer points runs torch on one thread
#: (:mod:`texvocab.torch_threads`: a call on 16 points took 1.1 ms on one thread and 2.5 ms
#: on two, 2,048 points 6.2 and 9.0 ms, 8,000 points 22.3 and 19.6 ms)
ONE_THREAD_POINTS = 4096
