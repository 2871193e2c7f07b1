"""A tiny end-to-end run of the real pipeline: synth -> prepare -> train -> eval, plus
resume after a simulated kill."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from train_cases import tiny_settings

from texvocab.capture import open as open_capture
from texvocab.pipeline.train import Trainer

TEXVOCAB = str(Path(sys.executable).parent / "texvocab")


def test_loss_falls_and_psnr_rises(capture, tmp_path):
    cap = open_capture(capture)
    trainer = Trainer(cap, tiny_settings(encoder="auto"), tmp_path / "run", progress=False)
    logs = trainer.run()
    first = np.mean([r["psnr"] for r in logs[:8]])
    last = np.mean([r["psnr"] for r in logs[-8:]])
    loss0, loss1 = np.mean([r["loss"] for r in logs[:8]]), np.mean([r["loss"] for r in logs[-8:]])
    print(f"batch PSNR {first:.2f} -> {last:.2f} dB, loss {loss0:.4f} -> {loss1:.4f}")
    assert last > first + 1.0 and loss1 < loss0
    assert all(np.isfinite(r["loss"]) for r in logs)
    assert (tmp_path / "run" / "checkpoint.pt").is_file()


def test_trainable_encoder_frames_keep_no_feature_maps(capture, tmp_path):
    """A trainable encoder's maps are recomputed for each step's frame, so the frame cache
    holds none between steps (kept for every frame they exhausted 24 GB with
    resnet34-scratch); frames drawn again still train the encoder."""
    cap = open_capture(capture)
    trainer = Trainer(cap, tiny_settings(encoder="small", iterations=8), tmp_path / "run", progress=False)
    encoder = trainer.model.pose_feature.encoder
    before = [p.detach().clone() for p in encoder.parameters()]
    drawn = []
    for _ in range(8):
        log = trainer.train_step()
        assert np.isfinite(log["loss"])
        assert all(fd.ctx.features is None for fd in trainer.frames.values())
        drawn.append(len(trainer.frames))
    assert drawn[-1] < 8  # 4 training frames: some were drawn again from the cache
    assert any(not torch.equal(a, b.detach()) for a, b in zip(before, encoder.parameters(), strict=True))


@pytest.mark.parametrize("points", [64, 200])
def test_the_eikonal_term_reads_eikonal_points_gradients(capture, tmp_path, points):
    """train.eikonal_points: the eikonal term evaluates the SDF and its gradient at that
    many points near the body each step (the one field call whose points need a gradient)."""
    cap = open_capture(capture)
    settings = tiny_settings(eikonal_points=points, iterations=2)
    trainer = Trainer(cap, settings, tmp_path / "run", progress=False)
    model, seen = trainer.model, []
    original = model.sdf_and_color

    def recording(ctx, pts, dirs, *args, **kw):
        if pts.requires_grad:
            seen.append(len(pts))
        return original(ctx, pts, dirs, *args, **kw)

    model.sdf_and_color = recording
    log = trainer.train_step()
    assert seen == [points] and np.isfinite(log["eikonal"]) and log["eikonal"] > 0


def test_beta_learns_at_its_own_rate_when_scaled(capture, tmp_path):
    """train.beta_lr_scale: β gets an optimiser group of its own at that multiple of the
    rate (Adam's first step moves a parameter by about its rate), and 1 keeps one group."""
    cap = open_capture(capture)
    moves = {}
    for scale in (1.0, 10.0):
        settings = tiny_settings(beta_lr_scale=scale, iterations=1, lr=1e-3)
        trainer = Trainer(cap, settings, tmp_path / f"run{scale}", progress=False)
        groups = trainer.optim.param_groups
        planes = trainer.model.triplane is not None  # the tri-plane's group comes after β's
        assert len(groups) == (1 if scale == 1 else 2) + planes
        before = float(trainer.model.log_beta.detach())
        trainer.train_step()
        moves[scale] = abs(float(trainer.model.log_beta.detach()) - before)
    assert groups[1]["params"] == [trainer.model.log_beta] and groups[1]["lr"] == pytest.approx(1e-2)
    assert 5 * moves[1.0] < moves[10.0] < 20 * moves[1.0]


@pytest.mark.parametrize("lr_decay", [1.0, 0.1])
def test_resume_after_kill_gives_the_same_weights(capture, tmp_path, one_thread, lr_decay):
    s = tiny_settings(iterations=6, checkpoint_every=3, lr_decay=lr_decay)
    straight = Trainer(open_capture(capture), s, tmp_path / "a", progress=False)
    straight.run()
    killed = Trainer(open_capture(capture), s, tmp_path / "b", progress=False)
    real_step = killed.train_step

    def dies_in_step_5():
        if killed.step == 4:
            raise KeyboardInterrupt  # the process is killed mid-step, after checkpoint 3
        return real_step()

    killed.train_step = dies_in_step_5
    with pytest.raises(KeyboardInterrupt):
        killed.run()
    killed_ck = torch.load(tmp_path / "b" / "checkpoint.pt", weights_only=True)
    assert killed_ck["step"] == 3
    resumed = Trainer(open_capture(capture), s, tmp_path / "b", progress=False)
    assert resumed.resume() and resumed.step == 3
    resumed.run()
    assert resumed.step == straight.step == 6
    a, b = straight.model.state_dict(), resumed.model.state_dict()
    for key in a:
        assert torch.equal(a[key], b[key]), key


@pytest.mark.slow  # the command line end to end in subprocesses
def test_train_and_eval_commands(capture, tmp_path):
    run = tmp_path / "run"
    args = [
        "--set",
        "texture_size=64",
        "--set",
        "encoder=small",
        "--set",
        "num_keys=3",
        "--set",
        "rays_per_batch=128",
        "--set",
        "field.hidden=32",
        "--set",
        "coarse_samples=8",
        "--set",
        "fine_samples=4",
    ]
    proc = subprocess.run(
        [TEXVOCAB, "train", str(capture), "--out", str(run), "--iterations", "3", *args],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    assert "step 3:" in proc.stdout and "train" in proc.stderr  # progress bar on stderr
    proc = subprocess.run(
        [TEXVOCAB, "eval", str(run / "checkpoint.pt"), str(capture), "--per-set", "1"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    report = json.loads((run / "eval" / "metrics.json").read_text())
    assert set(report["table"]) == {"training_poses", "novel_poses", "generated_novel_poses"}
    for row in report["table"].values():
        assert np.isfinite(row["psnr_bbox"]) and 0 < row["ssim_full"] <= 1
    assert (run / "eval" / "grid_novel_poses.png").is_file()
    assert "| training_poses |" in (run / "eval" / "metrics.md").read_text()
    # a checkpoint that is not one: one clear line
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"not a checkpoint")
    proc = subprocess.run(
        [TEXVOCAB, "eval", str(bad), str(capture)], capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 2 and proc.stderr.startswith("error: ") and "bad.pt" in proc.stderr


def test_image_scale_renders_smaller_and_shows_it_at_full_size(capture):
    from texvocab.metrics import metrics_in_bbox
    from texvocab.pipeline.evaluate import render_view
    from texvocab.pipeline.settings import march_settings

    cap = open_capture(capture)
    s = tiny_settings()
    model = Trainer(cap, s, capture.parent / "scale_run", progress=False).model.eval()
    cam, t = cap.cameras[1], 0
    full, full_stats = render_view(model, cap.poses[t], cap.trans[t], cam, march_settings(s))
    half, half_stats = render_view(model, cap.poses[t], cap.trans[t], cam, march_settings(s), 0.5)
    assert half.shape == full.shape == (cam.height, cam.width, 3)
    assert half_stats.pixels == cam.scaled(0.5).width * cam.scaled(0.5).height
    assert half_stats.field_evals < 0.5 * full_stats.field_evals
    # the same picture, blurred: close to the full render, far from a blank one
    mask = cap.mask(1, t)
    assert metrics_in_bbox(half, full, mask)["psnr"] > 20
    assert metrics_in_bbox(np.zeros_like(full), full, mask)["psnr"] < 15


def test_time_budget_progress_bar_counts_the_budget(capture, tmp_path, capsys):
    """With max_minutes the bar counts seconds of the budget, not steps of a nominal
    iteration count (it used to show '0/100000 steps, 33:56:08 left')."""
    cap = open_capture(capture)
    s = tiny_settings(iterations=100_000, max_minutes=0.04, checkpoint_every=1000)
    trainer = Trainer(cap, s, tmp_path / "run", progress=True)
    logs = trainer.run()
    err = capsys.readouterr().err
    assert 0 < len(logs) < 100_000
    assert "s of the time budget" in err and "/2 s of" in err
    assert "100000" not in err
    assert (tmp_path / "run" / "checkpoint.pt").is_file()


def test_a_key_per_training_frame_trains(capture, tmp_path):
    """``vocab.num_keys=0``: every training frame is a key; the model holds them all and
    a few steps train to finite losses."""
    cap = open_capture(capture)
    trainer = Trainer(cap, tiny_settings(num_keys=0, k=3, iterations=2), tmp_path / "run", progress=False)
    vocab = trainer.model.pose_feature.vocab
    assert all(sorted(kf.tolist()) == list(range(cap.num_train)) for kf in vocab.key_frames)
    logs = trainer.run()
    assert len(logs) == 2 and all(np.isfinite(r["loss"]) for r in logs)
