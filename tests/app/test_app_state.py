"""Viewer state: clamped joints, versioning, the vocabulary query per part, moving a part
to a key, and the blended texture of a pose (a tiny capture-like stand-in: training poses
and random texture maps, no images)."""

import numpy as np
import pytest

from texvocab.body import default_body
from texvocab.body.parts import BODY_PARTS
from texvocab.errors import TexvocabError
from texvocab.geometry.uv import texel_map
from texvocab.method.vocab import Vocabulary
from texvocab.method.vocab_texture import VocabTexture
from texvocab_viewer.state import ViewerData, ViewerState, load_viewer_data

TEX = 32
LEFT_SHOULDER, LEFT_KNEE = 16, 4


def training_poses(n: int = 12, seed: int = 0) -> np.ndarray:
    """(n, 24, 3) small random poses, the left arm swinging between -40 and 40 degrees."""
    rng = np.random.default_rng(seed)
    poses = rng.normal(0, 0.1, (n, 24, 3))
    poses[:, 0] = 0.0
    poses[:, LEFT_SHOULDER] = [[0, 0, a] for a in np.radians(np.linspace(-40, 40, n))]
    return poses


@pytest.fixture(scope="module")
def body():
    return default_body()


def make_data(body, weighting="paper", k=3, num_keys=6, seed=0) -> ViewerData:
    poses = training_poses(seed=seed)
    vocab = Vocabulary.build(poses, "part", num_keys=num_keys, k=k, weighting=weighting)
    textures = np.random.default_rng(seed + 1).random((len(poses), TEX, TEX, 3)).astype(np.float32)
    return ViewerData(body, vocab, textures, source="stand-in")


def test_set_joint_clamps_and_versions(body):
    state = ViewerState(make_data(body))
    assert state.version == 0
    assert state.set_joint(LEFT_KNEE, (200.0, 10.0, -10.0))
    np.testing.assert_allclose(state.joint_deg(LEFT_KNEE), [150.0, 5.0, -5.0])
    assert state.version == 1
    assert not state.set_joint(LEFT_KNEE, (170.0, 9.0, -9.0))  # clamps to the same value
    assert state.version == 1
    state.reset_joint(LEFT_KNEE)
    assert state.version == 2 and np.all(state.pose[LEFT_KNEE] == 0)
    state.apply_preset("squat")
    assert state.version == 3 and state.trans[1] < -0.3 and np.any(state.pose[LEFT_KNEE] != 0)
    state.reset_part("left_leg")
    assert np.all(state.pose[list(BODY_PARTS["left_leg"])] == 0)
    assert np.any(state.pose[list(BODY_PARTS["right_leg"])] != 0)
    state.reset_all()
    assert np.all(state.pose == 0) and np.all(state.trans == 0) and state.version == 5
    with pytest.raises(TexvocabError, match="unknown pose preset 'moonwalk'"):
        state.apply_preset("moonwalk")


def test_values_outside_the_limits_are_flagged_and_kept_until_their_slider_moves(body):
    state = ViewerState(make_data(body))
    pose = np.zeros((24, 3))
    pose[LEFT_KNEE] = np.radians([200.0, 30.0, 0.0])  # from a file: x and y outside
    state.set_pose(pose, change="frame 3")
    assert state.out_of_limits(LEFT_KNEE).tolist() == [True, True, False]
    assert state.change == "frame 3"
    # moving z alone keeps x = 200 and y = 30 (no snap); z is clamped to its limit
    assert state.set_joint(LEFT_KNEE, (200.0, 30.0, -40.0))
    np.testing.assert_allclose(state.joint_deg(LEFT_KNEE), [200.0, 30.0, -5.0])
    assert state.change == "left knee z -5°"
    # moving x clamps x only
    state.set_joint(LEFT_KNEE, (100.0, 30.0, -5.0))
    np.testing.assert_allclose(state.joint_deg(LEFT_KNEE), [100.0, 30.0, -5.0])
    assert state.out_of_limits(LEFT_KNEE).tolist() == [False, True, False]


def test_posed_is_cached_per_version(body):
    state = ViewerState(make_data(body))
    v0, j0 = state.posed()
    assert v0.shape == (body.num_vertices, 3) and j0.shape == (24, 3)
    assert state.posed()[0] is v0
    state.set_joint(LEFT_SHOULDER, (0, 0, -60))
    v1, j1 = state.posed()
    assert v1 is not v0 and not np.allclose(j1[20], j0[20]) and np.allclose(j1[4], j0[4])


def test_query_weights_and_keys_follow_the_left_arm(body):
    state = ViewerState(make_data(body))
    state.set_pose(training_poses()[3])
    before = state.query()
    assert [q.part for q in before] == list(BODY_PARTS)
    for q in before:
        assert q.weights.sum() == pytest.approx(1.0) and np.all(q.weights >= 0)
        assert len(q.key_ids) == 3 and q.novelty == pytest.approx(q.distances[0])
    arm = list(BODY_PARTS).index("left_arm")
    state.set_joint(LEFT_SHOULDER, (0.0, 0.0, 90.0))  # far outside the training swing
    after = state.query()
    assert set(after[arm].key_ids) != set(before[arm].key_ids)
    assert after[arm].novelty > before[arm].novelty + 0.05
    for p in range(len(after)):
        if p != arm:
            assert after[p].key_ids.tolist() == before[p].key_ids.tolist()


def test_set_part_to_key_makes_that_key_nearest(body):
    state = ViewerState(make_data(body))
    state.set_joint(LEFT_SHOULDER, (0.0, 0.0, 90.0))
    arm = list(BODY_PARTS).index("left_arm")
    assert state.novelty()[arm] > 0.05
    v = state.version
    assert state.set_part_to_key("left_arm", 2)
    assert state.version == v + 1
    q = state.query()[arm]
    assert q.novelty == pytest.approx(0.0, abs=1e-9) and q.key_ids[0] == 2
    with pytest.raises(TexvocabError, match="part left_arm has keys 0..5"):
        state.set_part_to_key("left_arm", 6)


def test_moving_the_main_body_to_a_key_keeps_the_way_the_body_faces(body):
    """The vocabulary reads the root-relative pose: a body facing away (143° about y) is
    as near its keys as one facing forward, and moving its main body to a key keeps the
    root's orientation (the key holds none)."""
    data = make_data(body)
    state = ViewerState(data)
    main = list(BODY_PARTS).index("main_body")
    pose = training_poses()[int(data.vocab.key_frames[main][1])].copy()  # a main-body key
    pose[0] = [0.0, np.radians(143.0), 0.0]
    state.set_pose(pose)
    assert state.novelty()[main] == pytest.approx(0.0, abs=1e-12)
    state.set_joint(9, (25.0, 0.0, 0.0))  # spine3 bends: away from every key
    assert state.novelty()[main] > 1e-3
    assert state.set_part_to_key("main_body", 2)
    assert state.novelty()[main] == pytest.approx(0.0, abs=1e-12)
    assert state.query()[main].key_ids[0] == 2
    np.testing.assert_array_equal(state.pose[0], pose[0])


def test_blended_texture_is_the_key_texture_where_its_weight_is_one(body):
    data = make_data(body, weighting="inverse")
    state = ViewerState(data)
    for part in BODY_PARTS:  # every part exactly on one of its keys: weight one
        state.set_part_to_key(part, 1)
    tex = state.blended_texture()
    assert tex.shape == (TEX, TEX, 3) and tex.dtype == np.float32
    assert state.blended_texture() is tex  # cached per version
    vt = VocabTexture(body, data.vocab, data.textures)
    covered = texel_map(body, TEX).covered
    for p, (q, part) in enumerate(zip(state.query(), BODY_PARTS, strict=True)):
        assert q.weights[0] == pytest.approx(1.0, abs=1e-9)
        pure = vt.attention[:, p] > 1 - 1e-12  # texels attending to this part only
        assert pure.sum() > 5, part
        got = tex[covered][pure]
        want = data.textures[q.frames[0]][covered][pure]
        np.testing.assert_allclose(got, want, atol=1e-5, err_msg=part)
    # with the paper's weights the same pose blends K keys: not a single key's texture
    paper = ViewerState(make_data(body, weighting="paper"))
    paper.set_pose(state.pose)
    q = paper.query()[0]
    assert np.all(q.weights > 0.2)
    mixed = paper.blended_texture()[covered][vt.attention[:, 0] > 1 - 1e-12]
    assert np.abs(mixed - data.textures[q.frames[0]][covered][vt.attention[:, 0] > 1 - 1e-12]).mean() > 0.05


def test_no_vocabulary_and_bad_sources(tmp_path):
    data = load_viewer_data(None)
    state = ViewerState(data)
    assert data.vocab is None and state.query() == [] and state.blended_texture() is None
    assert state.novelty().shape == (0,)
    with pytest.raises(TexvocabError, match="no vocabulary"):
        state.set_part_to_key("left_arm", 0)
    missing = tmp_path / "nope"
    with pytest.raises(TexvocabError, match=f"{missing}: no such file or folder; expected a checkpoint"):
        load_viewer_data(str(missing))
    with pytest.raises(TexvocabError, match="not a capture folder"):
        load_viewer_data(str(tmp_path))
    junk = tmp_path / "junk.pt"
    junk.write_bytes(b"junk")
    with pytest.raises(TexvocabError, match="junk.pt: not a loadable texvocab checkpoint"):
        load_viewer_data(str(junk))


def test_numpy_posing_equals_the_body_model(body, toy_arrays):
    """texvocab_viewer.posing (NumPy LBS for display) against BodyModel.forward, with and without
    pose correctives."""
    import torch

    from texvocab.body import BodyModel
    from texvocab.body.smpl_io import parents_from_kintree
    from texvocab_viewer.posing import BodyPoser

    toy = BodyModel(
        v_template=toy_arrays["v_template"],
        faces=toy_arrays["f"],
        weights=toy_arrays["weights"],
        parents=parents_from_kintree(toy_arrays["kintree_table"]),
        J_regressor=toy_arrays["J_regressor"],
        posedirs=toy_arrays["posedirs"],
        dtype=torch.float64,
    )
    rng = np.random.default_rng(3)
    for model in (body, toy):
        pose, trans = rng.normal(0, 0.6, (24, 3)), rng.normal(0, 0.3, 3)
        verts, joints = BodyPoser(model)(pose, trans)
        ref = model.forward(torch.as_tensor(pose)[None], torch.as_tensor(trans)[None])
        tol = 1e-9 if model is toy else 1e-5  # the default body's model is float32
        np.testing.assert_allclose(verts, ref.vertices[0].double().numpy(), atol=tol)
        np.testing.assert_allclose(joints, ref.joints[0].double().numpy(), atol=tol)


def test_compiled_blend_equals_the_numpy_reference(body):
    """VocabTexture.blend (compiled, one pass) against blend_reference (numpy, part by
    part) on random poses, both weightings."""
    rng = np.random.default_rng(3)
    for weighting in ("paper", "inverse"):
        data = make_data(body, weighting=weighting)
        vt = VocabTexture(body, data.vocab, data.textures)
        for _ in range(3):
            pose = rng.normal(0, 0.4, (24, 3))
            got, want = vt.blend(pose), vt.blend_reference(pose)
            assert got.shape == want.shape == (TEX, TEX, 3) and got.dtype == np.float32
            np.testing.assert_allclose(got, want, atol=2e-6)
            assert want.std() > 0.01  # a real texture, not zeros


def test_blend_coefficients_from_the_panels_query_equal_the_batched_query(body):
    """part_coefficients from a pose's ``vocab.query`` (what the viewer's frame already
    has for the vocabulary panel) against the batched tensor query, summed per frame."""
    from texvocab.method.vocab_texture import part_coefficients

    rng = np.random.default_rng(5)
    data = make_data(body)
    vocab = data.vocab
    for _ in range(4):
        pose = rng.normal(0, 0.4, (24, 3))
        frames, coef = part_coefficients(vocab, pose, vocab.query(pose))
        part_frames, part_weights, _ = vocab.query_tensors(pose)
        want = np.zeros((vocab.num_parts, int(max(f.max() for f in part_frames)) + 1))
        for p, (f, w) in enumerate(zip(part_frames, part_weights, strict=True)):
            np.add.at(want[p], f[0].numpy(), w[0].numpy())
        assert np.array_equal(frames, np.nonzero(want.sum(0))[0])
        np.testing.assert_allclose(coef, want[:, frames], atol=1e-12)
        np.testing.assert_allclose(coef.sum(1), 1.0, atol=1e-9)
        again = part_coefficients(vocab, pose)  # without a query: the same
        assert np.array_equal(again[0], frames) and np.allclose(again[1], coef)
