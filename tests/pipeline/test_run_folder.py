"""A run folder is one writer's and is never lost silently: the lock, stale temp files,
refusing to replace a trained checkpoint, extending a run with --resume, stopping on a
non-finite loss with the last checkpoint intact, absolute capture paths."""

import os
import subprocess
import sys

import pytest
import torch
from train_cases import tiny_settings

from texvocab.capture import open as open_capture
from texvocab.cli.main import main
from texvocab.errors import TexvocabError
from texvocab.io.checkpoint import load_checkpoint
from texvocab.pipeline.avatar import load_avatar
from texvocab.pipeline.run_folder import LOCK_NAME, RunLock
from texvocab.pipeline.train import Trainer


def test_a_second_writer_is_refused_and_a_dead_ones_lock_is_taken_over(tmp_path):
    sleeper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        (tmp_path / LOCK_NAME).write_text(f"{sleeper.pid}\n")
        with pytest.raises(TexvocabError, match=f"another training \\(pid {sleeper.pid}\\)"):
            with RunLock(tmp_path):
                pass
    finally:
        sleeper.kill()
        sleeper.wait()
    (tmp_path / ".checkpoint.pt.abc123.pt").write_bytes(b"")  # a killed save's leftover
    (tmp_path / "notes.txt").write_text("the user's")
    with RunLock(tmp_path) as lock:  # the pid is gone: stale lock taken over
        assert (tmp_path / LOCK_NAME).read_text().split()[0] == str(os.getpid())
        assert lock.held
    assert not (tmp_path / LOCK_NAME).exists()
    assert not (tmp_path / ".checkpoint.pt.abc123.pt").exists()
    assert (tmp_path / "notes.txt").read_text() == "the user's"


def test_resume_extends_a_run_and_overwrite_replaces_it(capture, tmp_path, capsys):
    run = tmp_path / "run"
    sets = [
        "--set",
        "texture_size=64",
        "--set",
        "num_keys=3",
        "--set",
        "k=2",
        "--set",
        "encoder=small",
        "--set",
        "rays_per_batch=128",
        "--set",
        "perceptual=off",
        "--set",
        "coarse_samples=8",
        "--set",
        "fine_samples=4",
    ]
    assert main(["train", str(capture), "--out", str(run), "--iterations", "2"] + sets) == 0
    first = load_checkpoint(run / "checkpoint.pt")
    assert first["step"] == 2 and os.path.isabs(first["capture"])
    assert main(["train", str(capture), "--out", str(run), "--iterations", "4", "--resume"] + sets) == 0
    assert load_checkpoint(run / "checkpoint.pt")["step"] == 4
    assert main(["train", str(capture), "--out", str(run), "--iterations", "5"] + sets) == 2
    assert "--resume" in capsys.readouterr().err
    assert load_checkpoint(run / "checkpoint.pt")["step"] == 4  # untouched
    assert main(["train", str(capture), "--out", str(run), "--iterations", "1", "--overwrite"] + sets) == 0
    assert load_checkpoint(run / "checkpoint.pt")["step"] == 1
    assert not (run / LOCK_NAME).exists()


def test_a_non_finite_loss_stops_training_naming_step_and_term(capture, tmp_path):
    trainer = Trainer(
        open_capture(capture),
        tiny_settings(iterations=6, checkpoint_every=2, perceptual="off"),
        tmp_path / "run",
        progress=False,
    )
    trainer.run(until=2)
    good = {k: v.clone() for k, v in load_checkpoint(trainer.checkpoint_path)["model"].items()}
    with torch.no_grad():
        next(p for p in trainer.model.parameters() if p.requires_grad).fill_(float("nan"))
    with pytest.raises(
        TexvocabError,
        match=r"step 3: the (loss|color|mask|eikonal) term is nan; "
        r"the last checkpoint .* is intact",
    ):
        trainer.run()
    after = load_checkpoint(trainer.checkpoint_path)
    assert after["step"] == 2
    assert all(torch.equal(after["model"][k], v) for k, v in good.items())
    assert not (tmp_path / "run" / LOCK_NAME).exists()  # released on the way out


def test_an_old_relative_capture_path_is_found_from_another_folder(capture, tmp_path, monkeypatch):
    project = tmp_path / "project"
    (project / "runs" / "a").mkdir(parents=True)
    os.symlink(capture, project / "cap")
    trainer = Trainer(
        open_capture(project / "cap"),
        tiny_settings(iterations=1, perceptual="off"),
        project / "runs" / "a",
        progress=False,
    )
    state = trainer.state()
    state["capture"] = "cap"  # as checkpoints before this change stored it (relative)
    torch.save(
        {"format": "texvocab-checkpoint", "version": 1, **state}, project / "runs" / "a" / "checkpoint.pt"
    )
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    avatar = load_avatar(project / "runs" / "a" / "checkpoint.pt", progress=False)
    assert avatar.capture.root.resolve() == (project / "cap").resolve()


def test_a_damaged_texture_map_cache_file_is_rebuilt(capture, tmp_path, caplog):
    from texvocab.pipeline.model import load_textures

    cap = open_capture(capture)
    s = tiny_settings()
    before = load_textures(cap, s, progress=False)
    from texvocab.method.texmap import texture_map_path
    from texvocab.pipeline.model import texmap_settings

    victim = texture_map_path(cap, 1, texmap_settings(cap, s))
    victim.write_bytes(b"PK\x03\x04 not really a zip")  # truncated / foreign
    with caplog.at_level("WARNING", logger="texvocab"):
        after = load_textures(cap, s, progress=False)
    assert torch.equal(before, after)
    assert any("damaged texture-map cache" in r.getMessage() for r in caplog.records)


@pytest.mark.slow  # kill -9 of a training process
def test_kill_9_mid_training_then_resume_matches_an_uninterrupted_run(capture, tmp_path):
    """A real SIGKILL (no cleanup runs): the checkpoint stays loadable, the dead writer's
    lock is taken over, and the resumed run ends where an uninterrupted one does."""
    import signal
    import time

    texvocab = os.path.join(os.path.dirname(sys.executable), "texvocab")
    sets = [
        "--set",
        "texture_size=64",
        "--set",
        "num_keys=3",
        "--set",
        "k=2",
        "--set",
        "encoder=small",
        "--set",
        "rays_per_batch=128",
        "--set",
        "perceptual=off",
        "--set",
        "coarse_samples=8",
        "--set",
        "fine_samples=4",
        "--set",
        "checkpoint_every=1",
        "--set",
        "field.hidden=32",
    ]
    env = dict(os.environ, OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")

    def train(out, *extra, wait=True):
        cmd = [texvocab, "train", str(capture), "--out", str(out), *sets, *extra]
        if wait:
            proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600)
            assert proc.returncode == 0, proc.stderr
            return None
        return subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)

    train(tmp_path / "straight", "--iterations", "8")
    proc = train(tmp_path / "killed", "--iterations", "400", wait=False)
    ckpt = tmp_path / "killed" / "checkpoint.pt"
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and not (ckpt.is_file() and load_checkpoint(ckpt)["step"] >= 3):
        time.sleep(0.2)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert (tmp_path / "killed" / LOCK_NAME).exists()  # SIGKILL left it behind
    step = load_checkpoint(ckpt)["step"]
    assert 3 <= step < 8
    train(tmp_path / "killed", "--resume", "--iterations", "8")
    a = load_checkpoint(tmp_path / "straight" / "checkpoint.pt")
    b = load_checkpoint(ckpt)
    assert b["step"] == 8 and not (tmp_path / "killed" / LOCK_NAME).exists()
    for key, value in a["model"].items():
        assert torch.allclose(value, b["model"][key], atol=1e-5), key


def test_a_moved_capture_is_named_and_capture_points_to_it(capture, tmp_path, capsys):
    import shutil

    from texvocab_viewer.state import load_viewer_data

    moved = tmp_path / "moved_cap"
    shutil.copytree(capture, moved)
    trainer = Trainer(
        open_capture(moved), tiny_settings(iterations=1, perceptual="off"), tmp_path / "run", progress=False
    )
    trainer.run()
    shutil.move(moved, tmp_path / "elsewhere_cap")  # the recorded (absolute) path is gone
    ckpt = str(trainer.checkpoint_path)
    assert main(["shot", ckpt, "--out", str(tmp_path / "shot")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and "moved_cap" in err and "missing" in err
    assert not (tmp_path / "shot").exists()
    data = load_viewer_data(ckpt, capture=str(tmp_path / "elsewhere_cap"))
    assert data.model is not None and data.capture.root == tmp_path / "elsewhere_cap"
    with pytest.raises(TexvocabError, match="--capture applies to a checkpoint"):
        load_viewer_data(str(tmp_path / "elsewhere_cap"), capture=str(capture))
