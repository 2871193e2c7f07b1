"""The vocabulary and the field's Θ read the root-relative pose: a body turned about the
vertical axis selects the same keys with the same weights and gets the same avatar, turned
with it; a global (old) vocabulary and field see the turn exactly as before."""

import numpy as np
import pytest
import torch

from texvocab.body import default_body
from texvocab.body.parts import BODY_PARTS
from texvocab.geometry.rotations import quat_multiply, quat_to_rotvec, rotvec_to_quat, rotvec_to_rotmat
from texvocab.method.encoder import build_encoder
from texvocab.method.feature import PoseFeature
from texvocab.method.field import AvatarField, FieldSettings, pose_input
from texvocab.method.vocab import Vocabulary, knn_weights, part_distance

MAIN = list(BODY_PARTS).index("main_body")
UP_143 = np.array([0.0, np.radians(143.0), 0.0])  # 143° about the world's up axis y


def turned(pose, rotvec) -> np.ndarray:
    """(..., 24, 3) with the root turned in the world by ``rotvec``: R0' = R · R0."""
    pose = np.array(pose, dtype=np.float64)
    q = quat_multiply(
        rotvec_to_quat(torch.as_tensor(np.broadcast_to(rotvec, pose[..., 0, :].shape).copy())),
        rotvec_to_quat(torch.as_tensor(pose[..., 0, :])),
    )
    pose[..., 0, :] = quat_to_rotvec(q).numpy()
    return pose


@pytest.fixture(scope="module")
def training_poses():
    """16 frames of one subject who faces every which way (random headings, small tilts)."""
    rng = np.random.default_rng(0)
    poses = rng.normal(0, 0.3, (16, 24, 3))
    poses[:, 0] = 0.0
    facing = np.stack([rng.normal(0, 0.1, 16), rng.uniform(-np.pi, np.pi, 16), rng.normal(0, 0.1, 16)], -1)
    return np.stack([turned(p, f) for p, f in zip(poses, facing, strict=True)])


def test_a_turned_key_pose_selects_the_same_keys_root_relative_not_global(training_poses):
    for condition, same in (("root-relative", True), ("global", False)):
        vocab = Vocabulary.build(training_poses, "part", num_keys=6, k=3, pose_condition=condition)
        frame = int(vocab.key_frames[MAIN][2])  # a main-body key: its novelty is 0
        pose = training_poses[frame]
        before, after = vocab.query(pose), vocab.query(turned(pose, UP_143))
        assert before[MAIN].novelty == pytest.approx(0.0, abs=1e-12)
        print(condition, "main-body novelty, turned 143°:", round(after[MAIN].novelty, 4))
        for p, (a, b) in enumerate(zip(before, after, strict=True)):
            if p != MAIN:  # the other parts do not hold joint 0: never moved by the turn
                assert np.array_equal(a.key_ids, b.key_ids) and np.array_equal(a.weights, b.weights)
        a, b = before[MAIN], after[MAIN]
        if same:
            assert np.array_equal(a.key_ids, b.key_ids) and np.array_equal(a.frames, b.frames)
            assert np.array_equal(a.weights, b.weights)
            assert np.array_equal(a.distances, b.distances)
        else:
            assert b.novelty > 0.1
            assert not np.allclose(a.weights, b.weights)
        # the batched query the pose feature uses answers the same
        frames, weights, dists = vocab.query_tensors(np.stack([pose, turned(pose, UP_143)]))
        assert torch.equal(frames[MAIN][0], frames[MAIN][1]) == same
        assert torch.equal(dists[MAIN][0], dists[MAIN][1]) == same


def test_keys_of_a_subject_turned_round_are_the_keys_of_one_facing_forward(training_poses):
    """FPS over training poses that face every way picks the keys it picks when they all
    face the same way, root-relative; globally the headings spread the keys."""
    forward = training_poses.copy()
    forward[:, 0] = 0.0
    rel = Vocabulary.build(training_poses, "part", num_keys=6, k=3)
    ref = Vocabulary.build(forward, "part", num_keys=6, k=3, pose_condition="global")
    glob = Vocabulary.build(training_poses, "part", num_keys=6, k=3, pose_condition="global")
    assert rel.pose_condition == "root-relative"  # new vocabularies
    for a, b in zip(rel.key_frames, ref.key_frames, strict=True):
        assert torch.equal(a, b)
    for a, b in zip(rel.key_quats, ref.key_quats, strict=True):
        assert torch.equal(a, b)
    assert not torch.equal(glob.key_frames[MAIN], ref.key_frames[MAIN])
    assert torch.equal(
        rel.key_quats[MAIN][:, 0], torch.tensor([[1.0, 0, 0, 0]]).double().expand(len(rel.key_quats[MAIN]), 4)
    )


def test_an_old_vocabulary_keeps_the_global_pose(training_poses):
    """A checkpoint's vocabulary written before the condition existed (no
    ``pose_condition`` key) is global: its queries are the ones texvocab computed then."""
    vocab = Vocabulary.build(training_poses, "part", num_keys=6, k=3, pose_condition="global")
    old = vocab.to_dict()
    del old["pose_condition"]
    loaded = Vocabulary.from_dict(old)
    assert loaded.pose_condition == "global" and loaded.ignored_joints == ()
    pose = turned(training_poses[3], UP_143)
    quats = rotvec_to_quat(torch.as_tensor(pose))  # the query as it was: the pose itself
    for q, joints, keys, kf in zip(
        loaded.query(pose), loaded.part_joints, loaded.key_quats, loaded.key_frames, strict=True
    ):
        d = part_distance(quats[list(joints)], keys)
        idx, w = knn_weights(d, 3, len(joints))
        assert np.array_equal(q.key_ids, idx.numpy()) and np.array_equal(q.weights, w.numpy())
        assert np.array_equal(q.frames, kf[idx].numpy())
    new = Vocabulary.from_dict(Vocabulary.build(training_poses, num_keys=6).to_dict())
    assert new.pose_condition == "root-relative" and new.ignored_joints == (0,)
    assert "pose=root-relative" in new.format_query(pose)
    new.pose_condition = "facing"
    with pytest.raises(ValueError, match="unknown pose condition 'facing'"):
        new.check(len(training_poses))
    with pytest.raises(ValueError, match="unknown pose condition"):
        Vocabulary.build(training_poses, pose_condition="yaw")


def _field(poses, condition: str) -> AvatarField:
    body = default_body()
    vocab = Vocabulary.build(poses, "part", num_keys=6, k=3, pose_condition=condition)
    textures = torch.rand(len(poses), 3, 32, 32, generator=torch.Generator().manual_seed(1))
    with torch.random.fork_rng():
        torch.manual_seed(0)
        pf = PoseFeature(body, vocab, textures, build_encoder("small"))
        f = AvatarField(pf, FieldSettings(hidden=32))
    gen = torch.Generator().manual_seed(2)
    with torch.no_grad():  # a "trained" field: the zero-initialised residual made non-zero
        for p in f.parameters():
            p.add_(0.05 * torch.randn(p.shape, generator=gen))
    return f


@pytest.mark.parametrize("condition", ["root-relative", "global"])
def test_a_turned_body_gets_the_same_avatar_turned_root_relative(training_poses, condition):
    """Turning the root by R about the pelvis turns the posed body rigidly; with the
    root-relative Θ the field's SDF and colour at the turned points are the unturned ones.
    (The colour's γ(d) reads the viewing direction in the world, so the colour is compared
    for the same world direction.) Globally Θ sees the turn and the avatar changes."""
    field = _field(training_poses, condition)
    pose = training_poses[5]
    pose_b = turned(pose, UP_143)
    ctx_a, ctx_b = (field.pose_feature.context(p) for p in (pose, pose_b))
    assert torch.equal(ctx_a.part_coef, ctx_b.part_coef) == (condition == "root-relative")
    rng = np.random.default_rng(3)
    v = ctx_a.vertices.detach().double()
    pts = v[rng.integers(0, len(v), 300)] + torch.as_tensor(rng.normal(0, 0.01, (300, 3)))
    dirs = torch.nn.functional.normalize(torch.as_tensor(rng.normal(0, 1, (300, 3))), dim=-1)
    rot = rotvec_to_rotmat(torch.as_tensor(UP_143))  # world turn about the posed pelvis
    pelvis = field.body.forward(torch.as_tensor(pose, dtype=torch.float32)[None]).joints[0, 0]
    pelvis = pelvis.double()
    pts_b = (pts - pelvis) @ rot.T + pelvis
    assert torch.allclose(ctx_b.vertices.double(), (v - pelvis) @ rot.T + pelvis, atol=1e-5)
    with torch.no_grad():
        sdf_a, rgb_a, valid_a = field.sdf_and_color(ctx_a, pts.float(), dirs.float())
        sdf_b, rgb_b, valid_b = field.sdf_and_color(ctx_b, pts_b.float(), dirs.float())
        # a point whose closest surface point lies on a UV seam may take either chart's UV
        # (a tie broken by rounding): those few are left out of the comparison
        uv_a = field.pose_feature(ctx_a, pts.float(), field.settings.shell_width).uv
        uv_b = field.pose_feature(ctx_b, pts_b.float(), field.settings.shell_width).uv
    ok = valid_a & valid_b & ((uv_a - uv_b).abs().max(-1).values < 1e-5)
    assert ok.float().mean() > 0.95
    gap = max(float((sdf_a - sdf_b)[ok].abs().max()), float((rgb_a - rgb_b)[ok].abs().max()))
    print(condition, "largest SDF/RGB change under the 143° turn:", gap)
    if condition == "root-relative":
        assert torch.equal(ctx_a.condition, ctx_b.condition)
        assert gap < 1e-4
    else:
        assert ctx_b.condition is ctx_b.pose  # global: the pose itself, as before
        assert gap > 1e-3


def test_a_global_field_reads_the_full_pose_as_before(training_poses):
    """An old-style (global) field's first layer is sdf_net on [x, q(Θ)] of the full pose,
    root orientation included, as texvocab computed it before the condition existed."""
    field = _field(training_poses, "global")
    pose = turned(training_poses[5], UP_143)
    ctx = field.pose_feature.context(pose)
    x = torch.randn(50, field.sdf_net[0].in_features - 96, generator=torch.Generator().manual_seed(4))
    theta = pose_input(ctx.pose.to(x.dtype)).reshape(1, -1).expand(len(x), -1)
    before = field.sdf_net(torch.cat([x, theta], -1))
    assert torch.allclose(field._sdf_hidden(ctx, x), before, atol=1e-5)
    rel = _field(training_poses, "root-relative")
    theta = pose_input(torch.as_tensor(pose, dtype=x.dtype)).reshape(1, -1).expand(len(x), -1)
    assert not torch.allclose(
        rel._sdf_hidden(rel.pose_feature.context(pose), x), rel.sdf_net(torch.cat([x, theta], -1)), atol=1e-3
    )


def test_gradients_reach_the_pose_through_the_condition(training_poses):
    """Pose refinement (a learnable pose) gets gradients through Θ for joints 1–23; the
    root's orientation reaches the field only through the posed body."""
    field = _field(training_poses, "root-relative")
    ctx = field.pose_feature.context(training_poses[5])
    ctx.pose = ctx.pose.clone().requires_grad_(True)
    x = torch.randn(20, field.sdf_net[0].in_features - 96, generator=torch.Generator().manual_seed(5))
    field._sdf_hidden(ctx, x).sum().backward()
    assert ctx.pose.grad[1:].abs().sum() > 0 and not ctx.pose.grad[0].any()
