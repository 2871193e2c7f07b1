"""Pose feature f(Θ, x) (Sec. 3.4): equals the textbook blend-then-sample form, touches
only the parts a point attends to, samples across UV seams continuously."""

import numpy as np
import pytest
import torch
from torch import nn

from texvocab.body import default_body
from texvocab.body.poses import preset
from texvocab.geometry.uv import texel_map
from texvocab.method.encoder import build_encoder
from texvocab.method.feature import PoseFeature, naive_pose_feature, sample_maps
from texvocab.method.vocab import Vocabulary


class PassThrough(nn.Module):
    """Frozen 'encoder' that returns the texture itself (exact checks of the algebra)."""

    feature_dim = 3
    trainable = False

    def forward(self, x):
        return x


@pytest.fixture(scope="module")
def body():
    return default_body()


@pytest.fixture(scope="module")
def setup(body):
    rng = np.random.default_rng(0)
    poses = rng.normal(0, 0.3, (12, 24, 3)).astype(np.float32)
    vocab = Vocabulary.build(poses, "part", num_keys=6, k=3)
    textures = torch.rand(12, 3, 32, 32, generator=torch.Generator().manual_seed(0))
    return PoseFeature(body, vocab, textures, PassThrough()), poses


def _shell_points(body, pose, n=400, seed=0):
    out = body.forward(torch.as_tensor(pose)[None])
    v = out.vertices[0]
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, len(v), n)
    return v[idx] + torch.as_tensor(rng.normal(0, 0.01, (n, 3)), dtype=torch.float32)


def test_matches_blend_then_sample(setup, body):
    model, poses = setup
    pose, trans = preset("walk")
    ctx = model.context(pose, trans)
    pts = _shell_points(body, pose) + torch.as_tensor(trans)
    fast = model(ctx, pts).features
    slow = naive_pose_feature(model, ctx, pts)
    assert torch.allclose(fast, slow, atol=1e-5)
    assert fast.abs().sum() > 0


def test_only_attended_parts_are_sampled(setup, body):
    model, _ = setup
    pose = np.zeros((24, 3), np.float32)
    ctx = model.context(pose)
    w = body.weights
    hand = torch.nonzero(w[:, [18, 20, 22]].sum(1) > 0.999).squeeze(1)[:50]  # left forearm/hand
    pts = body.v_template[hand]
    out = model(ctx, pts)
    left_arm = model.vocab.part_names.index("left_arm")
    frames_used = set(ctx.frames[ctx.part_coef[left_arm] > 0].tolist())
    assert ctx.stats["samples"] <= len(pts) * len(frames_used)
    # the features equal the left arm's key blend alone
    q = model.vocab.query(pose)[left_arm]
    expect = sum(
        wk * sample_maps(model.textures[fk], out.uv) for fk, wk in zip(q.frames, q.weights, strict=True)
    )
    assert torch.allclose(out.features, expect.float(), atol=1e-5)


def test_sampling_is_continuous_across_uv_seams(body):
    size = 256
    tmap = texel_map(body, size)
    rest = body.v_template.double().numpy()
    faces = body.faces.numpy()

    def f(p):  # a smooth colour field on the body
        return np.stack(
            [
                0.5 + 0.5 * np.sin(3 * p[:, 0]),
                0.5 + 0.5 * np.cos(2 * p[:, 1]),
                0.5 + 0.5 * np.sin(4 * p[:, 2] + 1),
            ],
            1,
        )

    tex = torch.as_tensor(tmap.to_image(f(tmap.points(rest, faces))), dtype=torch.float32)
    tex = tex.permute(2, 0, 1)
    # points on seam vertices: vertices that carry more than one UV coordinate
    ft, fv = body.ft.numpy().ravel(), faces.ravel()
    n_uv = np.bincount(fv, minlength=len(rest))
    pairs = np.unique(np.stack([fv, ft], 1), axis=0)
    seam = np.flatnonzero(np.bincount(pairs[:, 0], minlength=len(rest)) > 1)
    assert len(seam) > 100 and n_uv.max() > 0
    rng = np.random.default_rng(1)
    # points just off seam vertices, on every side of the seam
    pts = rest[seam] + rng.normal(0, 0.003, (len(seam), 3))
    model = PoseFeature(body, Vocabulary.build(np.zeros((1, 24, 3))), tex[None], PassThrough())
    ctx = model.context(np.zeros((24, 3)))
    out = model(ctx, torch.as_tensor(pts, dtype=torch.float32))
    truth = f(ctx.index.project(pts).closest)
    err = np.abs(out.features.numpy() - truth)
    print(f"seam sampling error: mean {err.mean():.4f}, p99 {np.percentile(err, 99):.4f}")
    assert err.mean() < 0.01 and np.percentile(err, 99) < 0.06


def test_float32_and_float64_agree(setup, body):
    model, _ = setup
    pose, trans = preset("squat")
    ctx = model.context(pose, trans)
    pts = _shell_points(body, pose, 200, seed=3) + torch.as_tensor(trans)
    a = model(ctx, pts.float()).features
    b = model(ctx, pts.double()).features
    assert torch.allclose(a.double(), b, atol=1e-5)


def test_trainable_encoder_gets_gradients(body):
    enc = build_encoder("small")
    vocab = Vocabulary.build(np.random.default_rng(2).normal(0, 0.3, (4, 24, 3)), num_keys=4, k=2)
    model = PoseFeature(body, vocab, torch.rand(4, 3, 64, 64), enc)
    ctx = model.context(np.zeros((24, 3)))
    out = model(ctx, _shell_points(body, np.zeros((24, 3)), 100))
    assert out.features.shape == (100, enc.feature_dim)
    out.features.square().sum().backward()
    grads = [p.grad for p in enc.parameters()]
    assert all(g is not None for g in grads) and sum(g.abs().sum() for g in grads) > 0


def test_points_far_from_the_body_get_zero_features(setup):
    model, _ = setup
    ctx = model.context(np.zeros((24, 3)))
    out = model(ctx, torch.tensor([[0.0, 0.0, 5.0], [0.0, 0.4, 0.05]]), max_distance=0.1)
    assert out.valid.tolist() == [False, True]
    assert torch.equal(out.features[0], torch.zeros(3)) and out.features[1].abs().sum() > 0


def test_a_subjects_shape_is_the_same_mesh_everywhere(tmp_path):
    """With a body that has a shape space and a capture with non-zero betas, the pose
    feature's posed mesh (and so the shell and the field's surface index built from it)
    is the texture maps' mesh (``Capture.posed_body``), not the template shape."""
    from texvocab.body.model import BodyModel
    from texvocab.capture.camera import Camera, look_at
    from texvocab.capture.capture import Capture
    from texvocab.pipeline.model import build_model
    from texvocab.pipeline.settings import DataSettings, Settings, VocabSettings

    base = default_body()
    rng = np.random.default_rng(0)
    v = base.num_vertices
    joint_reg = torch.zeros(24, v, dtype=torch.float64)
    for j in range(24):  # each joint: mean of its 8 most-weighted vertices, so it follows shape
        joint_reg[j, torch.topk(base.weights[:, j], 8).indices] = 1 / 8
    shaped = BodyModel(
        base.v_template,
        base.faces,
        base.weights,
        base.parents,
        J_regressor=joint_reg.numpy(),
        vt=base.vt,
        ft=base.ft,
        shapedirs=rng.normal(0, 0.03, (v, 3, 4)),
        name="shape stand-in",
    )
    poses = np.stack([preset("walk")[0], preset("squat")[0]]).astype(np.float32)
    R, t = look_at(np.array([0.0, 0.0, 3.0]), np.zeros(3))
    cam = Camera(K=np.array([[300.0, 0, 64], [0, 300.0, 64], [0, 0, 1]]), R=R, t=t, width=128, height=128)
    cap = Capture(
        tmp_path,
        "zju",
        [cam, cam],
        poses,
        np.zeros((2, 3), np.float32),
        [[tmp_path / "x.png"] * 2] * 2,
        [[tmp_path / "m.png"] * 2] * 2,
        [0, 1],
        2,
        shaped,
        betas=np.array([2.0, -1.5, 1.0, 0.5, 9.0]),
    )
    assert cap.shape().shape == (1, 4)
    s = Settings(
        data=DataSettings(texture_size=32, eval_views=(1,)),
        vocab=VocabSettings(encoder="pyramid", num_keys=2, k=1),
    )
    model = build_model(cap, s, torch.rand(2, 3, 32, 32))
    for t in range(2):
        ctx = model.pose_feature.context(cap.poses[t], cap.trans[t])
        truth = cap.posed_body(t).vertices[0]
        template = shaped.forward(torch.as_tensor(poses[t])[None]).vertices[0]
        assert torch.allclose(ctx.vertices, truth, atol=1e-5)
        assert (template - truth).norm(dim=-1).max() > 0.05  # the shape really moves the mesh
        on_surface = ctx.index.project(truth.double().numpy()).distance
        assert np.abs(on_surface).max() < 1e-6


@pytest.mark.parametrize("strategy", ["none", "part"])
def test_none_strategy_conditions_the_field_on_the_pose_only(setup, body, strategy):
    """The no-vocabulary baseline: the same field, its texture feature all zeros, so its
    output does not change when the texture maps change; with a vocabulary it does."""
    from texvocab.method.field import AvatarField, FieldSettings

    _, poses = setup
    vocab = Vocabulary.build(poses, strategy, num_keys=6, k=3)
    assert (vocab.num_parts == 0) == (strategy == "none")
    outs = []
    for seed in (0, 1):
        textures = torch.rand(12, 3, 32, 32, generator=torch.Generator().manual_seed(seed))
        pf = PoseFeature(body, vocab, textures, PassThrough())
        torch.manual_seed(0)
        field = AvatarField(pf, FieldSettings(hidden=32))
        ctx = pf.context(poses[3])
        pts = _shell_points(body, poses[3], n=200)
        feats = pf(ctx, pts).features
        assert (feats.abs().sum() == 0) == (strategy == "none")
        sdf, rgb, _ = field.sdf_and_color(ctx, pts, torch.nn.functional.normalize(pts, dim=-1))
        outs.append(rgb)
    assert torch.equal(outs[0], outs[1]) == (strategy == "none")
    assert f"strategy={strategy}" in vocab.format_query(poses[3])


def test_warm_feature_maps_encodes_every_key_once_up_front(body):
    """PoseFeature.warm_feature_maps: a frozen encoder's cache holds every key frame's
    maps afterwards, so no pose's context runs the encoder; the maps are the ones a
    context would have encoded; a trainable encoder is left alone."""

    class Counting(PassThrough):
        calls = 0

        def forward(self, x):
            Counting.calls += len(x)
            return x

    vocab = Vocabulary.build(np.random.default_rng(5).normal(0, 0.3, (12, 24, 3)), num_keys=4, k=2)
    textures = torch.rand(12, 3, 16, 16)
    keys = {int(f) for frames in vocab.key_frames for f in frames}
    warm = PoseFeature(body, vocab, textures, Counting())
    assert warm.warm_feature_maps(batch=3) == len(keys) == Counting.calls
    assert warm.warm_feature_maps() == 0  # nothing left to encode
    cold = PoseFeature(body, vocab, textures, PassThrough())
    for seed in range(4):
        pose = np.random.default_rng(seed).normal(0, 0.3, (24, 3))
        a, b = warm.context(pose), cold.context(pose)
        assert torch.equal(a.frames, b.frames)
        fa, fb, n = a.features, b.features, a.features.height * a.features.width
        for ra, rb in zip(fa.rows.tolist(), fb.rows.tolist(), strict=True):
            assert torch.equal(fa.table[ra : ra + n], fb.table[rb : rb + n])
    assert Counting.calls == len(keys)  # no context encoded anything
    trainable = PoseFeature(body, vocab, textures, build_encoder("small"))
    assert trainable.warm_feature_maps() == 0
