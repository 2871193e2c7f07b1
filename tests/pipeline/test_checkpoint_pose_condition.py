"""A checkpoint records the pose its vocabulary and field read: new runs root-relative;
one written before the record existed loads as global (its weights keep their meaning) and
is not resumed by a run that would read the pose otherwise."""

import numpy as np
import pytest
import torch
from train_cases import tiny_settings

from texvocab.capture import open as open_capture
from texvocab.errors import TexvocabError
from texvocab.geometry.rotations import quat_multiply, quat_to_rotvec, rotvec_to_quat
from texvocab.io.checkpoint import load_checkpoint, save_checkpoint
from texvocab.method.field import pose_input
from texvocab.method.vocab import Vocabulary
from texvocab.pipeline.avatar import load_avatar
from texvocab.pipeline.train import Trainer


def turned_143(pose: np.ndarray) -> np.ndarray:
    out = np.array(pose, dtype=np.float64)
    turn = rotvec_to_quat(torch.tensor([0.0, np.radians(143.0), 0.0], dtype=torch.float64))
    out[0] = quat_to_rotvec(quat_multiply(turn, rotvec_to_quat(torch.as_tensor(out[0])))).numpy()
    return out


def test_an_old_checkpoint_reads_the_global_pose_and_is_not_resumed_root_relative(capture, tmp_path):
    cap = open_capture(capture)
    s = tiny_settings(iterations=2, checkpoint_every=2)
    Trainer(cap, s, tmp_path / "run", progress=False).run()
    path = tmp_path / "run" / "checkpoint.pt"
    ck = load_checkpoint(path)
    assert ck["vocab"]["pose_condition"] == "root-relative"
    new = load_avatar(path, open_capture(capture), progress=False)
    assert new.model.pose_feature.vocab.pose_condition == "root-relative"

    # the same checkpoint as texvocab wrote it before the record existed: global keys
    old_vocab = Vocabulary.build(
        cap.poses[: cap.num_train],
        s.vocab.strategy,
        s.vocab.num_keys,
        s.vocab.k,
        s.vocab.weighting,
        pose_condition="global",
    ).to_dict()
    del old_vocab["pose_condition"]
    ck["vocab"] = old_vocab
    save_checkpoint(path, ck)
    old = load_avatar(path, open_capture(capture), progress=False)
    vocab = old.model.pose_feature.vocab
    assert vocab.pose_condition == "global"
    pose = turned_143(cap.poses[1])
    ctx = old.model.pose_feature.context(pose)
    assert ctx.condition is ctx.pose  # Θ of the full pose, root orientation included
    x = torch.randn(30, old.model.sdf_net[0].in_features - 96, generator=torch.Generator().manual_seed(0))
    theta = pose_input(ctx.pose).reshape(1, -1).expand(len(x), -1)
    assert torch.allclose(
        old.model._sdf_hidden(ctx, x), old.model.sdf_net(torch.cat([x, theta], -1)), atol=1e-5
    )
    turned_key = vocab.query(pose)[0]
    assert turned_key.novelty > 0.1  # the global keys see the turn, as they always did
    assert new.model.pose_feature.vocab.query(pose)[0].novelty == pytest.approx(
        new.model.pose_feature.vocab.query(cap.poses[1])[0].novelty, abs=1e-12
    )

    with pytest.raises(
        TexvocabError, match="pose_condition='global'.*pose_condition='root-relative'; choose another --out"
    ):
        Trainer(open_capture(capture), s, tmp_path / "run", progress=False).resume()
