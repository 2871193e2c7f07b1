"""Vocabulary (Sec. 3.3–3.4): FPS and KNN on hand-computed cases, weights at the extremes."""

import numpy as np
import pytest
import torch

from texvocab.geometry.rotations import rotvec_to_quat
from texvocab.method.vocab import Vocabulary, farthest_point_sampling, knn_weights, part_distance


def _quats(angles_deg, axis=(1.0, 0.0, 0.0)):
    """(T, 1, 4) one-joint part-poses rotated about ``axis``."""
    rv = torch.tensor(np.array([[np.radians(a) * np.asarray(axis)] for a in angles_deg]))
    return rotvec_to_quat(rv)


def test_part_distance_matches_eq2_by_hand():
    q = _quats([0, 60, 180, -180])
    d = part_distance(q, q)
    # 1 - |cos(Δθ/2)|: 60° -> 1 - cos 30°, 180° -> 1 - cos 90° = 1; ±180° are the same rotation
    assert d[0, 1] == pytest.approx(1 - np.cos(np.radians(30)))
    assert d[0, 2] == pytest.approx(1.0)
    assert d[2, 3] == pytest.approx(0.0, abs=1e-12)
    two = torch.cat([q, q], dim=1)  # a 2-joint part: distances add up
    assert part_distance(two, two)[0, 1] == pytest.approx(2 * d[0, 1])


def test_fps_hand_computed():
    # angles 0, 10, 20, 90, 100: from 0 the farthest is 100, then 20 or 90? d(20)=min(d(0,20),
    # d(100,20)) = 1-cos10°; d(90) = min(1-cos45°, 1-cos5°) = 1-cos5° -> 20 wins, then 90 or 10
    q = _quats([0, 10, 20, 90, 100])
    assert farthest_point_sampling(q, 3).tolist() == [0, 4, 2]
    assert sorted(farthest_point_sampling(q, 10).tolist()) == [0, 1, 2, 3, 4]  # M > T: all


def test_fps_with_repeated_poses_and_ties():
    q = _quats([0, 0, 50, 50, -50])
    idx = farthest_point_sampling(q, 3).tolist()
    assert idx == [0, 2, 4]  # ties between 2/3 resolved to the lowest index
    assert farthest_point_sampling(q, 5).tolist()[:3] == [0, 2, 4]


def test_knn_weights_eq4():
    d = torch.tensor([0.3, 0.1, 0.2, 0.9])
    idx, w = knn_weights(d, 3, num_joints=5)
    assert idx.tolist() == [1, 2, 0]
    raw = 5 - torch.tensor([0.1, 0.2, 0.3])
    assert torch.allclose(w, raw / raw.sum())


def test_knn_extremes():
    # K >= M: all keys, weights still sum to one
    idx, w = knn_weights(torch.tensor([0.5, 0.2]), 5, num_joints=3)
    assert idx.tolist() == [1, 0] and w.sum() == pytest.approx(1.0)
    # every key at the maximum distance J_p: w = J_p - d = 0 for all -> uniform, no NaN
    idx, w = knn_weights(torch.full((4,), 3.0), 3, num_joints=3)
    assert torch.equal(w, torch.full((3,), 1 / 3)) and idx.tolist() == [0, 1, 2]
    # ties: lower key index first, equal weights
    idx, w = knn_weights(torch.tensor([0.2, 0.2, 0.2]), 2, num_joints=2)
    assert idx.tolist() == [0, 1] and w[0] == w[1]
    # a query equal to a key: 'inverse' weighting gives that key weight exactly one
    idx, w = knn_weights(torch.tensor([0.4, 0.0, 0.2]), 3, num_joints=2, weighting="inverse")
    assert idx[0] == 1 and w.tolist() == [1.0, 0.0, 0.0]
    # two exact matches share the weight
    _, w = knn_weights(torch.tensor([0.0, 0.0, 0.2]), 3, num_joints=2, weighting="inverse")
    assert w.tolist() == [0.5, 0.5, 0.0]


@pytest.mark.parametrize("strategy,parts", [("part", 5), ("joint", 24), ("global", 1)])
def test_vocabulary_build_and_query(strategy, parts):
    rng = np.random.default_rng(0)
    poses = rng.normal(0, 0.4, (30, 24, 3))
    poses[10] = poses[3]  # a repeated pose
    vocab = Vocabulary.build(poses, strategy, num_keys=8, k=3)
    assert vocab.num_parts == parts
    for joints, kf in zip(vocab.part_joints, vocab.key_frames, strict=True):
        if set(joints) <= set(vocab.ignored_joints):  # the pelvis alone ("joint"): one pose
            assert kf.tolist() == list(range(8))  # root-relative, so its keys tie (lowest first)
        else:
            assert len(kf) == 8 and len(set(kf.tolist())) == 8 and kf[0] == 0
    # querying a training frame that is a key: its own frame is the nearest, distance 0
    key_frame = int(vocab.key_frames[-1][1])
    res = vocab.query(poses[key_frame])
    assert res[-1].frames[0] == key_frame and res[-1].novelty == pytest.approx(0.0, abs=1e-9)
    for q in res:
        assert q.weights.sum() == pytest.approx(1.0) and np.all(q.weights >= 0)
        assert np.all(np.diff(q.distances) >= 0)
    # batched query agrees with the single one
    frames, weights, _ = vocab.query_tensors(np.stack([poses[key_frame], poses[5]]))
    assert frames[-1][0].tolist() == res[-1].frames.tolist()
    assert torch.allclose(weights[-1][0], torch.as_tensor(res[-1].weights))


def test_vocabulary_handles_identical_training_poses():
    poses = np.zeros((6, 24, 3))
    vocab = Vocabulary.build(poses, "part", num_keys=4, k=4)
    res = vocab.query(np.zeros((24, 3)))
    for q in res:
        assert np.isfinite(q.weights).all() and q.weights.sum() == pytest.approx(1.0)


def test_format_query_prints_every_part():
    vocab = Vocabulary.build(np.random.default_rng(1).normal(0, 0.3, (12, 24, 3)), k=2, num_keys=4)
    text = vocab.format_query(np.zeros((24, 3)))
    for name in ("main_body", "left_leg", "right_leg", "left_arm", "right_arm"):
        assert name in text


def test_every_training_frame_a_key_when_num_keys_is_zero():
    """``vocab.num_keys=0``: M = T, each training frame a key of every part once, so a
    training frame's nearest key is itself (distance 0, and weight 1 with ``inverse``)."""
    from texvocab.errors import TexvocabError
    from texvocab.pipeline.settings import Settings

    rng = np.random.default_rng(1)
    poses = rng.normal(0, 0.4, (12, 24, 3))
    vocab = Vocabulary.build(poses, "part", num_keys=0, k=3, weighting="inverse")
    for kf in vocab.key_frames:
        assert sorted(kf.tolist()) == list(range(12))
    for q in vocab.query(poses[7]):
        assert q.frames[0] == 7 and q.weights[0] == pytest.approx(1.0)
    with pytest.raises(ValueError, match="num_keys must be >= 0"):
        Vocabulary.build(poses, "part", num_keys=-1, k=3)
    # the setting: 0 takes any K; otherwise K is one of the M keys
    assert Settings().with_overrides(["vocab.num_keys=0", "vocab.k=5"]).vocab.num_keys == 0
    with pytest.raises(TexvocabError, match="vocab.k"):
        Settings().with_overrides(["vocab.num_keys=2", "vocab.k=3"])
