"""Numerical stability of the whole query path: pose → quaternions → vocabulary
distance (Eq. 4) → KNN weights (Eqs. 5–6) → pose feature (Eqs. 7–9) → field → render,
with a small real avatar (default body, 32² textures, small encoder and field).

Cases: rotation angles θ = 0, 1e-8, π, 2π and antipodal quaternions; K > M; all keys at
equal distance; a pose equal to a key; β → 0 and β large; rays that miss; a camera
inside or on the body; ±π on every joint; all-zero textures and zero coverage for a
part; float32 vs float64. Everywhere: no NaN or inf in values or in gradients (a scalar
loss back-propagated to the model parameters and, where differentiable, to the pose).
Pure rotation-function and analytic-field cases live in test_rotations.py / test_render.py.
"""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from stability_helpers import (
    FIELD,
    MARCH,
    NUM_FRAMES,
    TEXTURE_SIZE,
    PassThrough,
    assert_finite,
    assert_param_grads,
    front_camera,
    look_at,
    make_field,
    render_and_backprop,
    shell_points,
    training_poses,
    vocab_pose_gradient,
)

from texvocab.body import default_body
from texvocab.body.limits import JOINT_LIMITS_DEG
from texvocab.geometry.rotations import quat_distance, rotvec_distance, rotvec_to_quat
from texvocab.geometry.surface import SurfaceIndex
from texvocab.geometry.uv import texel_map
from texvocab.method.feature import PoseFeature, sample_maps
from texvocab.method.field import laplace_density
from texvocab.method.texmap import TexmapSettings, build_texture_map
from texvocab.method.vocab import Vocabulary
from texvocab.render import MarchSettings, ShellGeometry, render_image

PI = math.pi
AXIS = np.array([1.0, 2.0, 3.0]) / np.sqrt(14.0)


@pytest.fixture(scope="module")
def body():
    return default_body()


@pytest.fixture(scope="module")
def vocab():
    return Vocabulary.build(training_poses(), "part", num_keys=4, k=3)


@pytest.fixture(scope="module", params=["frequencies", "triplane"])
def avatar(body, vocab, request):
    """The avatar with the default no-weights encoder (frozen texture pyramid), with either
    position encoding (γ(x_c) alone, or with tri-plane features); trainable encoders are
    exercised by the texture tests."""
    return make_field(body, vocab, encoder="pyramid", position_encoding=request.param)


def uniform_pose(angle: float) -> np.ndarray:
    """(24, 3): every joint rotated by ``angle`` about the same axis."""
    return np.tile(angle * AXIS, (24, 1))


def random_axes(seed: int) -> np.ndarray:
    axes = np.random.default_rng(seed).normal(size=(24, 3))
    return axes / np.linalg.norm(axes, axis=1, keepdims=True)


def check_vocab_query(vocab: Vocabulary, pose: np.ndarray) -> None:
    """Query values are finite, weights are a distribution, distances match Eq. 2 computed
    joint by joint with rotations.rotvec_distance from the key frames' training poses, both
    as the vocabulary's pose condition reads them (``vocab`` must be built from a prefix
    of :func:`training_poses`), and the pose
    gradient is finite."""
    frames, weights, dists = vocab.query_tensors(pose)
    keys = vocab.condition(training_poses()).numpy()  # the poses as the vocabulary reads them
    seen = vocab.condition(pose).numpy()
    for joints, kf, f, w, d in zip(vocab.part_joints, vocab.key_frames, frames, weights, dists, strict=True):
        assert_finite(weights=w, distances=d)
        assert (w >= 0).all() and float(w.sum()) == pytest.approx(1.0, abs=1e-12)
        assert (d >= 0).all() and (d <= len(joints) + 1e-12).all()
        key_of_frame = {int(fr): m for m, fr in enumerate(kf)}
        for fr, dk in zip(f[0], d[0], strict=True):
            by_hand = rotvec_distance(
                torch.as_tensor(seen[list(joints)]), torch.as_tensor(keys[int(fr)][list(joints)])
            ).sum()
            assert float(dk) == pytest.approx(float(by_hand), abs=1e-9), key_of_frame[int(fr)]
    grad, _ = vocab_pose_gradient(vocab, torch.as_tensor(pose))
    assert_finite(vocab_pose_grad=grad)


def check_field_and_render(field, pose: np.ndarray, camera_size: int = 10) -> None:
    """Pose feature, field (values, eikonal gradient, pose and parameter gradients) and a
    differentiable render for one pose."""
    ctx = field.pose_feature.context(pose)
    assert_finite(
        vertices=ctx.vertices, transforms=ctx.transforms, part_coef=ctx.part_coef, features=ctx.features.table
    )
    pts = shell_points(ctx, 300).requires_grad_(True)
    feat = field.pose_feature(ctx, pts)
    assert_finite(feature=feat.features, uv=feat.uv, distance=feat.distance)
    assert feat.valid.float().mean() > 0.5
    ctx.pose = ctx.pose.clone().requires_grad_(True)  # the field's pose conditioning
    sdf, rgb, valid = field.sdf_and_color(
        ctx, pts, torch.nn.functional.normalize(pts - pts.detach().mean(0), dim=-1)
    )
    assert_finite(sdf=sdf, rgb=rgb)
    (eik,) = torch.autograd.grad(sdf.sum(), pts, create_graph=True)
    assert_finite(eikonal_grad=eik)
    field.zero_grad(set_to_none=True)
    loss = ((eik[valid].norm(dim=-1) - 1) ** 2).mean() + rgb.square().mean() + sdf.abs().mean()
    loss.backward()
    assert_finite(point_grad=pts.grad, pose_grad=ctx.pose.grad)
    assert ctx.pose.grad.abs().sum() > 0
    assert_param_grads(field)
    ctx.features = field.pose_feature.feature_maps(ctx.frames)  # fresh graph, as Trainer
    cam = front_camera(ctx.vertices, camera_size)
    origins, dirs = cam.pixel_rays()
    out = render_and_backprop(field, ctx, origins, dirs)
    assert out.rays > 0 and float(out.opacity.max()) > 0
    assert (out.opacity >= 0).all() and (out.opacity <= 1 + 1e-6).all()
    assert_param_grads(field)
    # the surface-guided marcher (render time) on the same pose: finite and in range
    with torch.no_grad():
        guided = render_image(
            field.for_pose(ctx), cam, ctx.vertices, field.body.faces, MarchSettings.from_flat(guide="raster")
        )
    assert_finite(guided_rgb=guided.rgb, guided_alpha=guided.alpha, guided_depth=guided.depth)
    assert (guided.alpha >= 0).all() and (guided.alpha <= 1 + 1e-6).all()
    assert (guided.rgb >= 0).all() and (guided.rgb <= 1 + 1e-6).all()
    assert guided.stats.paths["residual"] > 0  # the residual rays ran at this extreme too


# --- rotations through the whole path -------------------------------------------------


@pytest.mark.parametrize(
    "angle", [0.0, 1e-8, PI - 1e-7, PI, -PI, 2 * PI], ids=["0", "1e-8", "pi-1e-7", "pi", "-pi", "2pi"]
)
def test_whole_query_path_at_extreme_angle(body, vocab, avatar, angle):
    pose = uniform_pose(angle)
    q = rotvec_to_quat(torch.as_tensor(pose))
    assert_finite(quats=q)
    assert torch.allclose(q.norm(dim=-1), torch.ones(24, dtype=q.dtype), atol=1e-12)
    check_vocab_query(vocab, pose)
    p = torch.as_tensor(pose, dtype=torch.float32)[None].requires_grad_(True)
    out = body.forward(p)
    (out.vertices.square().sum() + out.joints.sum()).backward()
    assert_finite(vertices=out.vertices, body_pose_grad=p.grad)
    check_field_and_render(avatar, pose)


def antipodal_pair(case: str) -> tuple[np.ndarray, np.ndarray]:
    """Two poses with the same rotation at every joint; joints whose quaternions are
    opposite (q vs -q) in the second."""
    if case == "theta_vs_theta_minus_2pi":
        return uniform_pose(2.0), uniform_pose(2.0 - 2 * PI)
    if case == "pi_vs_minus_pi":
        return uniform_pose(PI), uniform_pose(-PI)
    if case == "zero_vs_2pi":
        return uniform_pose(0.0), uniform_pose(2 * PI)
    rng = np.random.default_rng(3)  # mixed: random axes and angles, every other joint
    angles = rng.uniform(0.1, PI, 24)
    a = random_axes(4) * angles[:, None]
    b = a.copy()
    b[::2] = random_axes(4)[::2] * (angles[::2] - 2 * PI)[:, None]
    return a, b


@pytest.mark.parametrize("case", ["theta_vs_theta_minus_2pi", "pi_vs_minus_pi", "zero_vs_2pi", "mixed"])
def test_antipodal_quaternions_give_the_same_query_body_and_feature(body, vocab, avatar, case):
    a, b = antipodal_pair(case)
    qa, qb = rotvec_to_quat(torch.as_tensor(a)), rotvec_to_quat(torch.as_tensor(b))
    opposite = (qa * qb).sum(-1) < 0
    assert opposite.any()  # some joints really have q and -q
    assert float(quat_distance(qa, qb).max()) < 1e-12
    fa, wa, da = vocab.query_tensors(a)
    fb, wb, db = vocab.query_tensors(b)
    for x, y in zip(fa + wa + da, fb + wb + db, strict=True):
        assert torch.allclose(x.double(), y.double(), atol=1e-12)
    for pose in (a, b):
        grad, _ = vocab_pose_gradient(vocab, torch.as_tensor(pose))
        assert_finite(vocab_pose_grad=grad)
    va = body.forward(torch.as_tensor(a, dtype=torch.float32)[None]).vertices[0]
    vb = body.forward(torch.as_tensor(b, dtype=torch.float32)[None]).vertices[0]
    assert (va - vb).abs().max() < 2e-5
    pf = avatar.pose_feature
    ca, cb = pf.context(a), pf.context(b)
    pts = shell_points(ca, 300)
    ha, hb = pf(ca, pts), pf(cb, pts)
    assert torch.equal(ha.valid, hb.valid)
    assert (ha.distance - hb.distance).abs().max() < 1e-5
    assert_finite(feature=ha.features, other=hb.features)
    # The closest face is ambiguous where two faces are equally close (medial axis, and
    # edges on a UV seam, where one 3D point has two UVs): float-level vertex differences
    # may pick the other face there, so a few points differ — only at such ties.
    differs = (ha.features - hb.features).abs().max(1).values > 1e-4
    assert differs.float().mean() < 0.02
    x = pts.double().numpy()
    face_a, face_b = ca.index.project(x).face, cb.index.project(x).face
    assert (face_a != face_b)[differs.numpy()].all()
    # the field's pose input does not see the sign of q: same SDF and colour (up to the
    # feature ties above)
    with torch.no_grad():
        dirs = torch.nn.functional.normalize(torch.ones_like(pts), dim=-1)
        sa, ra, _ = avatar.sdf_and_color(ca, pts, dirs)
        sb, rb, _ = avatar.sdf_and_color(cb, pts, dirs)
    same = ~differs
    assert (sa - sb)[same].abs().max() < 1e-4 and (ra - rb)[same].abs().max() < 1e-4


# --- vocabulary corner cases through the field ----------------------------------------


@pytest.mark.parametrize("weighting", ["paper", "inverse"])
def test_k_larger_than_m(body, weighting):
    vocab = Vocabulary.build(training_poses()[:3], "part", num_keys=3, k=7, weighting=weighting)
    pose = uniform_pose(0.4)
    frames, weights, _ = vocab.query_tensors(pose)
    for f, w in zip(frames, weights, strict=True):
        assert f.shape == (1, 3) and sorted(f[0].tolist()) == [0, 1, 2]  # K capped at M
        assert float(w.sum()) == pytest.approx(1.0, abs=1e-12) and (w > 0).all()
    check_vocab_query(vocab, pose)
    field = make_field(body, vocab, encoder="pyramid")
    check_field_and_render(field, pose)


def equidistant_setup(case: str) -> tuple[np.ndarray, np.ndarray, float | None]:
    """Training poses, a query with every key of every part at one distance, and the
    per-joint distance (None: the maximum, |q·q_key| = 0)."""
    if case == "max_distance":  # rest-pose keys, query π on every joint: q·q_key = 0
        return np.zeros((NUM_FRAMES, 24, 3)), uniform_pose(PI), None
    poses = np.zeros((NUM_FRAMES, 24, 3))
    for f in range(NUM_FRAMES):  # 0.5 rad about x, y or z: all at 1 - cos(0.25) from rest
        poses[f, :, f % 3] = 0.5 * (1 if f < 3 else -1)
    return poses, np.zeros((24, 3)), 1 - math.cos(0.25)


@pytest.mark.parametrize("case", ["max_distance", "equal_ties"])
def test_all_keys_at_equal_distance(body, case):
    poses, query, per_joint = equidistant_setup(case)
    vocab = Vocabulary.build(poses, "part", num_keys=4, k=3)
    frames, weights, dists = vocab.query_tensors(query)
    for joints, f, w, d in zip(vocab.part_joints, frames, weights, dists, strict=True):
        seen = [j for j in joints if j not in vocab.ignored_joints]  # not the root's rotation
        expect = len(seen) * (1.0 if per_joint is None else per_joint)
        assert torch.allclose(d, torch.full_like(d, expect), atol=1e-12)
        assert torch.allclose(w, torch.full_like(w, 1 / 3), atol=1e-12)  # uniform, no NaN
    check_vocab_query_finite_only(vocab, query)
    textures = torch.rand(
        NUM_FRAMES, 3, TEXTURE_SIZE, TEXTURE_SIZE, generator=torch.Generator().manual_seed(1)
    )
    pf = PoseFeature(body, vocab, textures, PassThrough())
    ctx = pf.context(query)
    pts = shell_points(ctx, 200)
    out = pf(ctx, pts)
    # each part blends its 3 keys' textures equally; Ω sums to one over the parts
    omega = out.skin_weights @ pf.membership / out.skin_weights.sum(-1, keepdim=True)
    expect = torch.zeros_like(out.features)
    for p, f in enumerate(frames):
        blend = sum(sample_maps(textures[int(fr)], out.uv) for fr in f[0]) / 3
        expect += omega[:, p : p + 1] * blend
    assert torch.allclose(out.features, expect * out.valid[:, None], atol=1e-5)
    check_field_and_render(make_field(body, vocab, textures, "pyramid"), query)


def check_vocab_query_finite_only(vocab: Vocabulary, pose: np.ndarray) -> None:
    grad, parts = vocab_pose_gradient(vocab, torch.as_tensor(pose))
    assert_finite(vocab_pose_grad=grad)
    for w, d in parts:
        assert_finite(weights=w, distances=d)


@pytest.mark.parametrize("offset", [0.0, 1e-6], ids=["exact", "1e-6_away"])
@pytest.mark.parametrize("weighting", ["inverse", "paper"])
def test_pose_equal_to_a_key(body, weighting, offset):
    poses = training_poses()
    vocab = Vocabulary.build(poses, "part", num_keys=4, k=3, weighting=weighting)
    query = poses[0].copy()  # frame 0 (rest) is key 0 of every part (FPS starts there)
    query[:, 0] += offset
    frames, weights, dists = vocab.query_tensors(query)
    textures = torch.rand(
        NUM_FRAMES, 3, TEXTURE_SIZE, TEXTURE_SIZE, generator=torch.Generator().manual_seed(2)
    )
    pf = PoseFeature(body, vocab, textures, PassThrough())
    ctx = pf.context(query)
    out = pf(ctx, shell_points(ctx, 200))
    key_only = sample_maps(textures[0], out.uv) * out.valid[:, None]
    blend = torch.zeros_like(out.features)
    omega = out.skin_weights @ pf.membership / out.skin_weights.sum(-1, keepdim=True)
    for joints, f, w, d in zip(vocab.part_joints, frames, weights, dists, strict=True):
        assert int(f[0, 0]) == 0 and float(d[0, 0]) <= len(joints) * offset**2
        if weighting == "inverse" and offset == 0:
            assert w[0].tolist() == [1.0, 0.0, 0.0]  # exactly one, the others exactly zero
        elif weighting == "inverse":
            assert float(w[0, 0]) > 1 - 1e-6  # 1/d dominates: continuous with the exact case
        else:
            # Eq. 4: w = J_p - d, normalised; the matching key gets J_p / Σ_k (J_p - d_k):
            # the largest weight, but never one while K > 1 and the other keys are within J_p
            raw = len(joints) - d[0]
            assert torch.allclose(w[0], raw / raw.sum(), atol=1e-12)
            assert 1 / 3 < float(w[0, 0]) < 1 and float(w[0, 0]) == float(w[0].max())
    for p, (f, w) in enumerate(zip(frames, weights, strict=True)):
        part = sum(
            float(wk) * sample_maps(textures[int(fr)], out.uv) for fr, wk in zip(f[0], w[0], strict=True)
        )
        blend += omega[:, p : p + 1] * part
    assert torch.allclose(out.features, blend * out.valid[:, None], atol=1e-5)
    if weighting == "inverse" and offset == 0:
        assert torch.allclose(out.features, key_only, atol=1e-5)
    elif weighting == "paper":
        assert (out.features - key_only).abs().max() > 1e-3  # a blend, not the key alone
    check_vocab_query(vocab, query)


# --- density --------------------------------------------------------------------------


@settings(max_examples=60, deadline=None)
@given(
    log_beta=st.floats(-15, 38),
    sdf=st.lists(st.floats(-1e6, 1e6), min_size=1, max_size=8),
    double=st.booleans(),
)
def test_laplace_density_values_and_gradients_are_finite(log_beta, sdf, double):
    dtype = torch.float64 if double else torch.float32
    beta = torch.tensor(10.0**log_beta, dtype=dtype, requires_grad=True)
    s = torch.tensor(sdf + [0.0], dtype=dtype, requires_grad=True)
    sigma = laplace_density(s, beta)
    (sigma.sum() + sigma.square().sum() * 1e-30).backward()
    assert_finite(sigma=sigma, sdf_grad=s.grad, beta_grad=beta.grad)
    assert (sigma >= 0).all() and (sigma <= 1 / beta.detach() * (1 + 1e-6)).all()
    order = torch.argsort(s.detach())
    assert (sigma.detach()[order].diff() <= 1e-6 * sigma.detach().max()).all()  # denser inside


@pytest.mark.parametrize(
    "log_beta",
    [-1e4, math.log(FIELD.beta_min), 0.0, math.log(1e3), 60.0],
    ids=["to_zero", "beta_min", "1", "1e3", "1e26"],
)
def test_field_beta_extremes_render_and_backprop(body, vocab, log_beta):
    field = make_field(body, vocab, encoder="pyramid")
    with torch.no_grad():
        field.log_beta.fill_(log_beta)
    beta = float(field.beta.detach())
    assert math.isfinite(beta) and beta >= FIELD.beta_min * (1 - 1e-6)  # float32 clamp
    ctx = field.pose_feature.context(uniform_pose(0.3))
    origins, dirs = front_camera(ctx.vertices, 10).pixel_rays()
    out = render_and_backprop(field, ctx, origins, dirs)
    assert_param_grads(field)
    assert torch.isfinite(field.log_beta.grad)
    if log_beta <= math.log(FIELD.beta_min):
        assert float(field.log_beta.grad) == 0.0  # clamped at beta_min
        assert float(out.opacity.max()) > 0.99  # a sharp surface is still found
    if beta >= 1e3:
        assert float(out.opacity.max()) < 1e-3  # σ ≤ 1/β: nearly transparent


# --- rays and cameras -----------------------------------------------------------------


def test_rays_that_miss_the_body(body, avatar):
    pose = uniform_pose(0.3)
    ctx = avatar.pose_feature.context(pose)
    shell = ShellGeometry.build(ctx.vertices.detach(), body.faces, FIELD.shell_width, index=ctx.index)
    cam = front_camera(ctx.vertices, 8)
    away = look_at(2 * cam.center - ctx.vertices.detach().double().mean(0).numpy(), cam.center, 8)
    image = render_image(
        avatar.for_pose(ctx),
        away,
        ctx.vertices.detach(),
        body.faces,
        MARCH,
        background=(0.2, 0.4, 0.6),
        shell=shell,
    )
    assert image.stats.field_evals == 0 and image.stats.rays == 0
    assert torch.equal(image.rgb, torch.tensor([0.2, 0.4, 0.6]).expand(8, 8, 3))
    assert (image.alpha == 0).all() and (image.depth == 0).all()
    # a training batch mixing rays that hit with rays that miss
    o_hit, d_hit = cam.pixel_rays()
    o_miss, d_miss = away.pixel_rays()
    out = render_and_backprop(avatar, ctx, torch.cat([o_hit, o_miss]), torch.cat([d_hit, d_miss]), shell)
    n = len(o_hit)
    assert torch.equal(out.rgb[n:], torch.tensor([0.2, 0.4, 0.6]).expand(n, 3))
    assert (out.opacity[n:] == 0).all() and float(out.opacity[:n].max()) > 0.5
    assert_param_grads(avatar)
    # a batch of misses only: the background, and no graph to back-propagate through
    ctx = avatar.pose_feature.context(pose)
    out = render_and_backprop(avatar, ctx, o_miss, d_miss, shell)
    assert out.rays == 0 and (out.opacity == 0).all()


def camera_at(body, ctx, where: str, size: int):
    """A camera at the pelvis joint (inside the body) or at the frontmost chest vertex,
    looking out of (+z) or into (-z) the torso."""
    v = ctx.vertices.detach().double()
    if where == "inside":
        centre = body.rest_joints[0].double().numpy()  # the rest pose's pelvis joint
        assert float(ctx.index.project(centre[None]).distance[0]) < -FIELD.shell_width
        return look_at(centre + np.array([0.0, 0.0, 1.0]), centre, size, focal=0.8 * size)
    chest = v[:, :2].mean(0)
    near_axis = ((v[:, :2] - chest).norm(dim=1) < 0.08).double()
    centre = v[int((v[:, 2] * near_axis - 9 * (1 - near_axis)).argmax())].numpy()
    ahead = centre + np.array([0.0, 0.0, 1.0 if where == "surface_out" else -1.0])
    return look_at(ahead, centre, size, focal=0.8 * size)


@pytest.mark.parametrize("path", ["render_image", "render_rays_backprop"])
@pytest.mark.parametrize("where", ["inside", "surface_out", "surface_in"])
def test_camera_inside_or_at_the_surface(body, avatar, where, path):
    ctx = avatar.pose_feature.context(np.zeros((24, 3)))
    shell = ShellGeometry.build(ctx.vertices.detach(), body.faces, FIELD.shell_width, index=ctx.index)
    cam = camera_at(body, ctx, where, 8)
    if path == "render_image":
        with torch.no_grad():
            image = render_image(avatar.for_pose(ctx), cam, ctx.vertices, body.faces, MARCH, shell=shell)
        assert_finite(rgb=image.rgb, alpha=image.alpha, depth=image.depth)
        assert (image.alpha >= 0).all() and (image.alpha <= 1 + 1e-6).all()
        assert (image.rgb >= 0).all() and (image.rgb <= 1 + 1e-6).all()
        if where != "surface_out":
            assert image.stats.rays == 64 and float(image.alpha.min()) > 0.5  # in the body
        return
    origins, dirs = cam.pixel_rays()
    out = render_and_backprop(avatar, ctx, origins, dirs, shell)
    assert out.rays > 0
    assert (out.opacity >= 0).all() and (out.opacity <= 1 + 1e-6).all()
    assert_param_grads(avatar)


@pytest.mark.parametrize("case", ["inside", "surface_in", "miss", "limits_high"])
def test_bfloat16_field_renders_stay_finite_at_the_extremes(body, avatar, case):
    """render.precision=bfloat16 on both render paths: the camera inside the body or at
    its surface looking in, rays that miss, joints at their limits."""
    pose = extreme_pose("limits_high") if case == "limits_high" else np.zeros((24, 3))
    ctx = avatar.pose_feature.context(pose)
    cam = front_camera(ctx.vertices, 8) if case in ("miss", "limits_high") else camera_at(body, ctx, case, 8)
    if case == "miss":
        away = 2 * cam.center - ctx.vertices.detach().double().mean(0).numpy()
        cam = look_at(away, cam.center, 8)
    for guide in ("raster", "shell"):
        march = MARCH.replace(guide=guide)
        with torch.no_grad():
            ref, image = (
                render_image(avatar.for_pose(ctx, p), cam, ctx.vertices, body.faces, march, index=ctx.index)
                for p in ("float32", "bfloat16")
            )
        assert_finite(rgb=image.rgb, alpha=image.alpha, depth=image.depth)
        assert (image.alpha >= 0).all() and (image.alpha <= 1 + 1e-6).all()
        assert (image.rgb >= 0).all() and (image.rgb <= 1 + 1e-6).all()
        assert (image.alpha - ref.alpha).abs().max() < 0.05 and (image.rgb - ref.rgb).abs().mean() < 0.01
        if case == "miss":
            assert image.stats.field_evals == 0 and (image.alpha == 0).all()
        elif case in ("inside", "surface_in"):
            assert float(image.alpha.min()) > 0.5, guide  # in the body
        else:
            assert image.stats.field_evals > 0 and float(image.alpha.max()) > 0.05, guide


@pytest.mark.parametrize("case", ["inside", "surface_in", "miss", "limits_high"])
def test_surface_reuse_renders_as_the_search_at_the_extremes(body, avatar, case):
    """The guided marcher's reuse of the closest faces it knows (the raster's hit faces,
    the residual rays' mesh samples) and its grouped residual quadrature give the image
    of every point searched and one padded quadrature: the camera inside the body or at
    its surface looking in, rays that miss, joints at their limits."""
    pose = extreme_pose("limits_high") if case == "limits_high" else np.zeros((24, 3))
    ctx = avatar.pose_feature.context(pose)
    cam = (
        front_camera(ctx.vertices, 12) if case in ("miss", "limits_high") else camera_at(body, ctx, case, 12)
    )
    if case == "miss":
        cam = look_at(2 * cam.center - ctx.vertices.detach().double().mean(0).numpy(), cam.center, 12)
    march = MARCH.replace(guide="raster")
    with torch.no_grad():
        new, old = (
            render_image(avatar.for_pose(ctx), cam, ctx.vertices, body.faces, m, index=ctx.index)
            for m in (march, march.replace(surface_reuse=False, residual_groups=1))
        )
    assert_finite(rgb=new.rgb, alpha=new.alpha, depth=new.depth)
    # equivalent computations: rounding may move a residual ray's quantile by one sample
    assert (new.stats.kind != old.stats.kind).sum() <= 1
    assert (new.rgb - old.rgb).abs().max() < 1e-3 and (new.alpha - old.alpha).abs().max() < 1e-3
    if case == "miss":
        assert new.stats.field_evals == 0
    else:
        assert new.stats.field_evals > 0 and float(new.alpha.max()) > 0.05


# --- extreme joint angles -------------------------------------------------------------


def extreme_pose(case: str) -> np.ndarray:
    if case in ("plus_pi", "minus_pi"):
        return (PI if case == "plus_pi" else -PI) * random_axes(7)
    lim = np.radians(JOINT_LIMITS_DEG.astype(np.float64))  # (24, 3, 2)
    return lim[..., 0] if case == "limits_low" else lim[..., 1]


@pytest.mark.parametrize("case", ["plus_pi", "minus_pi", "limits_low", "limits_high"])
def test_extreme_joint_angles(body, vocab, avatar, case):
    pose = extreme_pose(case)
    p = torch.as_tensor(pose, dtype=torch.float32)[None].requires_grad_(True)
    out = body.forward(p)
    (out.vertices.square().sum() + out.transforms.sum()).backward()
    assert_finite(vertices=out.vertices, transforms=out.transforms, body_pose_grad=p.grad)
    v = out.vertices[0].detach()
    index = SurfaceIndex(v.double().numpy(), body.faces.numpy())
    pts = (
        (v[::23] + 0.02 * torch.randn(len(v[::23]), 3, generator=torch.Generator().manual_seed(0)))
        .double()
        .numpy()
    )
    proj = index.project(pts, body.vt.numpy(), body.ft.numpy(), body.weights.numpy())
    for name in ("distance", "closest", "uv", "weights"):
        assert np.isfinite(getattr(proj, name)).all(), name
    assert (proj.face >= 0).all() and np.allclose(proj.weights.sum(1), 1, atol=1e-5)
    assert ((proj.uv >= -1e-6) & (proj.uv <= 1 + 1e-6)).all()
    assert (np.abs(proj.distance) <= 0.02 * np.sqrt(3) * 5 + 1e-6).all()
    check_vocab_query(vocab, pose)
    check_field_and_render(avatar, pose)


SPECIAL = [0.0, 1e-8, -1e-8, PI - 1e-7, PI, -PI, 2 * PI, 1.0]


@settings(max_examples=15, deadline=None)
@given(
    kinds=st.lists(st.sampled_from(range(len(SPECIAL))), min_size=24, max_size=24), seed=st.integers(0, 2**16)
)
def test_body_and_vocabulary_at_special_angles_on_random_axes(body, vocab, kinds, seed):
    angles = np.array([SPECIAL[k] for k in kinds])
    pose = random_axes(seed) * angles[:, None]
    p = torch.as_tensor(pose, dtype=torch.float32)[None].requires_grad_(True)
    out = body.forward(p)
    (out.vertices.square().sum() + out.joints.sum()).backward()
    assert_finite(vertices=out.vertices, body_pose_grad=p.grad)
    check_vocab_query_finite_only(vocab, pose)
    for w in vocab.query_tensors(pose)[1]:
        assert float(w.sum()) == pytest.approx(1.0, abs=1e-12)


# --- textures -------------------------------------------------------------------------


@pytest.mark.parametrize("encoder", ["small", "pyramid", "resnet34-scratch", "pass_through"])
def test_all_zero_textures(body, vocab, encoder):
    textures = torch.zeros(NUM_FRAMES, 3, TEXTURE_SIZE, TEXTURE_SIZE)
    enc = PassThrough() if encoder == "pass_through" else encoder
    field = make_field(body, vocab, textures, enc)
    pose = uniform_pose(0.3)
    ctx = field.pose_feature.context(pose)
    out = field.pose_feature(ctx, shell_points(ctx, 200))
    assert_finite(features=ctx.features.table, feature=out.features)
    valid = out.features[out.valid]
    if encoder == "pass_through":
        assert torch.equal(out.features, torch.zeros_like(out.features))
    elif encoder == "pyramid":  # ImageNet-normalised black: one constant feature
        assert torch.allclose(valid, valid[:1].expand_as(valid), atol=1e-6)
    if encoder == "resnet34-scratch":  # BatchNorm of a constant batch: variance zero
        field.zero_grad(set_to_none=True)
        sdf, rgb, _ = field.sdf_and_color(ctx, shell_points(ctx, 200), torch.ones(200, 3) / 3**0.5)
        (out.features.square().mean() + sdf.abs().mean() + rgb.mean()).backward()
        assert_finite(sdf=sdf, rgb=rgb)
        assert_param_grads(field)
    else:
        check_field_and_render(field, pose)
    if encoder in ("small", "resnet34-scratch"):
        grads = {n: p.grad for n, p in field.pose_feature.encoder.named_parameters() if p.grad is not None}
        assert grads
        assert_finite(**grads)


class FrontOnlyCapture:
    """Stand-in capture for texmap.build_texture_map: the rest-pose default body seen by
    one narrow camera on the chest (the arms are out of its view), a constant image."""

    colour = np.array([0.8, 0.3, 0.1], np.float32)

    def __init__(self, body):
        self.body = body
        chest = body.rest_joints[9].double().numpy()
        self.cameras = [look_at(chest, chest + np.array([0.0, 0.0, 2.0]), 48, focal=150.0)]
        self.num_views = 1

    def posed_body(self, frame: int):
        return self.body.forward(torch.zeros(1, 24, 3))

    def image(self, view: int, frame: int) -> np.ndarray:
        return np.broadcast_to(self.colour, (48, 48, 3)).copy()

    def mask(self, view: int, frame: int) -> np.ndarray:
        return np.ones((48, 48), bool)


def part_texels(body, size: int, joints: tuple[int, ...]) -> np.ndarray:
    """(S, S) bool: covered texels of faces skinned mostly to ``joints``."""
    tmap = texel_map(body, size)
    w = body.weights.numpy()[body.faces.numpy()].mean(1)  # (F, J) per face
    mostly = w[:, list(joints)].sum(1) > 0.9
    out = np.zeros((size, size), bool)
    out[tmap.covered] = mostly[tmap.face]
    return out


@pytest.mark.parametrize("encoder", ["small", "pyramid"])
def test_zero_coverage_for_a_part(body, vocab, encoder):
    capture = FrontOnlyCapture(body)
    texture, coverage = build_texture_map(capture, 0, TexmapSettings(size=TEXTURE_SIZE * 2))
    left_forearm_hand = part_texels(body, TEXTURE_SIZE * 2, (18, 20, 22))
    assert left_forearm_hand.sum() > 20 and coverage[left_forearm_hand].max() == 0
    assert coverage.max() >= 1  # the chest was seen
    assert np.isfinite(texture).all() and np.isfinite(coverage).all()
    # unseen texels take the nearest seen texel's colour: the constant image colour (seen
    # texels up to half a pixel past the outer pixel centres were once blended with black)
    assert np.allclose(texture, capture.colour, atol=1e-5)
    textures = torch.from_numpy(texture).permute(2, 0, 1)[None].repeat(NUM_FRAMES, 1, 1, 1)
    field = make_field(body, vocab, textures, encoder)
    ctx = field.pose_feature.context(np.zeros((24, 3)))
    hand = torch.nonzero(body.weights[:, [20, 22]].sum(1) > 0.99).squeeze(1)
    out = field.pose_feature(ctx, body.v_template[hand])
    assert out.valid.all()
    assert_finite(feature=out.features)
    check_field_and_render(field, np.zeros((24, 3)))


def test_texture_map_seen_by_no_view(body):
    texture, coverage = build_texture_map(
        FrontOnlyCapture(body), 0, TexmapSettings(size=TEXTURE_SIZE), views=[]
    )
    assert texture.shape == (TEXTURE_SIZE, TEXTURE_SIZE, 3) and texture.dtype == np.float32
    assert (texture == 0).all() and (coverage == 0).all()


# --- float32 vs float64 ---------------------------------------------------------------


@pytest.mark.parametrize("case", ["pi", "1e-8", "2pi", "limits_high"])
def test_float32_and_float64_agree_at_extreme_poses(body, vocab, case):
    pose = (
        extreme_pose(case)
        if case == "limits_high"
        else uniform_pose({"pi": PI, "1e-8": 1e-8, "2pi": 2 * PI}[case])
    )
    textures = torch.rand(
        NUM_FRAMES, 3, TEXTURE_SIZE, TEXTURE_SIZE, generator=torch.Generator().manual_seed(3)
    )
    field32 = make_field(body, vocab, textures, "pyramid")
    field64 = copy.deepcopy(field32).double()
    ctx32 = field32.pose_feature.context(pose)
    ctx64 = field64.pose_feature.context(pose)
    assert ctx64.features.table.dtype == torch.float64
    pts = shell_points(ctx32, 300, seed=4)
    f32 = field32.pose_feature(ctx32, pts).features
    f64 = field64.pose_feature(ctx64, pts.double()).features
    assert f64.dtype == torch.float64
    assert torch.allclose(f32.double(), f64, atol=1e-5)
    dirs = torch.nn.functional.normalize(pts - pts.mean(0), dim=-1)
    sdf32, rgb32, valid32 = field32.sdf_and_color(ctx32, pts, dirs)
    sdf64, rgb64, valid64 = field64.sdf_and_color(ctx64, pts.double(), dirs.double())
    assert torch.equal(valid32, valid64)
    assert torch.allclose(sdf32.double(), sdf64, atol=1e-4)
    assert torch.allclose(rgb32.double(), rgb64, atol=1e-4)
