"""bench/pose_refinement.py: a run's poses against the truth a noisy-fit capture keeps
aside, read from real checkpoints (a 2-step run, and the same run handed the exact
correction), and a capture without the truth refused with one error line."""

import sys
from pathlib import Path

import pytest
import torch
from train_cases import flat_settings

from texvocab.body import default_body
from texvocab.capture import open as open_capture
from texvocab.capture.motion import make_sequence
from texvocab.capture.synth import SynthSettings, synthesize
from texvocab.method.field import FieldSettings
from texvocab.pipeline.train import Trainer

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench"))

import pose_refinement  # noqa: E402

TINY = FieldSettings(hidden=16, sdf_layers=1, color_layers=1, pos_freqs=2)


def _capture(root: Path, noise: bool) -> Path:
    poses, trans = make_sequence([("walk", 4)], seed=1)
    s = SynthSettings(ring_views=3, raised_views=0, size=48, texture_size=64)
    if noise:
        s.fit_noise_deg, s.fit_noise_trans = 5.0, 0.02
    return synthesize(root, poses, trans, 3, default_body(), s, progress=False)


def _run(cap: Path, out: Path, mode: str) -> Path:
    s = flat_settings(
        encoder="small", iterations=2, field=TINY, texture_size=32, num_keys=1, k=1,
        rays_per_batch=64, coarse_samples=8, fine_samples=4, checkpoint_every=2,
        pose_refinement=mode, eval_views=(2,),
    )  # fmt: skip
    trainer = Trainer(open_capture(cap), s, out, progress=False)
    trainer.run()
    return trainer.checkpoint_path


@pytest.fixture(scope="module")
def noisy(tmp_path_factory):
    root = tmp_path_factory.mktemp("refine")
    cap = _capture(root / "cap", noise=True)
    return cap, _run(cap, root / "joints", "joints"), _run(cap, root / "off", "off")


def test_errors_before_are_the_noise_and_an_exact_correction_takes_them_to_zero(noisy, tmp_path):
    cap, joints, off = noisy
    row = pose_refinement.analyse(cap, joints, every=1)
    assert row["mode"] == "joints" and row["frames"] == 3 and row["step"] == 2
    assert 2.0 < row["joints_deg_before"] < 8.0 and 0.5 < row["trans_cm_before"] < 4.0
    assert row["iou_true"] > 0.95 > row["iou_recorded"]  # the painted person is the body
    # two steps moved the corrections by about the learning rate: barely
    assert abs(row["joints_deg_after"] - row["joints_deg_before"]) < 1.0
    # the same checkpoint handed the exact correction (refined = recorded + δ = truth)
    ck = torch.load(joints, weights_only=True)
    c = open_capture(cap)
    true_poses, true_trans = pose_refinement.true_fit(c)
    ck["pose_refinement"]["rot"] = torch.as_tensor(true_poses[:3] - c.poses[:3], dtype=torch.float32)
    ck["pose_refinement"]["trans"] = torch.as_tensor(true_trans[:3] - c.trans[:3], dtype=torch.float32)
    exact = tmp_path / "exact.pt"
    torch.save(ck, exact)
    best = pose_refinement.analyse(cap, exact, every=1)
    assert best["joints_deg_after"] < 0.05 and best["root_deg_after"] < 0.05 and best["trans_cm_after"] < 1e-3
    assert best["improved"] > 0.95 and abs(best["iou_refined"] - best["iou_true"]) < 1e-3
    # a run without refinement trains with the recorded poses
    plain = pose_refinement.analyse(cap, off, every=1)
    assert plain["mode"] == "off" and plain["joints_deg_after"] == plain["joints_deg_before"]
    assert plain["iou_refined"] is None
    md = pose_refinement.format_report([row, best, plain])
    assert "| joints | 2 |" in md and "| off | 1 |" in md
    assert f"{best['joints_deg_before']:.2f} -> {best['joints_deg_after']:.2f}" in md
    # per joint: the exact correction's rows read 0.00 after, each frame closer
    assert len(best["joint_deg_after"]) == 24 and max(best["joint_deg_after"]) < 0.05
    rows = [r for r in pose_refinement.joint_table([best]) if r.startswith("| 1")]
    assert rows and all("-> 0.00 | 100% |" in r for r in rows)


def test_a_capture_without_the_truth_is_an_error(noisy, tmp_path, capsys):
    _, joints, _ = noisy
    clean = _capture(tmp_path / "clean", noise=False)
    before = sorted(p.name for p in clean.iterdir())
    assert pose_refinement.main([str(clean), str(joints)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and "true_poses" in err[0]
    assert sorted(p.name for p in clean.iterdir()) == before
