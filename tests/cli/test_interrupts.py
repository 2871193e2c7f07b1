"""Ctrl-C and kill on real commands (subprocesses): one ``error:`` line, status 130
(SIGINT) or 143 (SIGTERM), no traceback, no temporary file left; and the temporary files
of a killed writer are swept by the next run, while files texvocab did not name stay."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from texvocab.body import default_body
from texvocab.capture.motion import make_sequence
from texvocab.capture.synth import SynthSettings, synthesize
from texvocab.cli.main import main
from texvocab.io.temp_files import TEMP_NAME, host_tag

TEXVOCAB = str(Path(sys.executable).parent / "texvocab")


def _interactive() -> None:
    """In the child, before exec: SIGINT as a terminal's foreground job has it. A suite
    started in the background (``cmd &``, as CI may) hands its children SIGINT ignored,
    and Python then installs no KeyboardInterrupt handler."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _start(argv, cwd, **kwargs):
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    return subprocess.Popen(
        [TEXVOCAB, *argv],
        cwd=cwd,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        preexec_fn=_interactive,
        **kwargs,
    )


def _wait_for(proc, ready, timeout=90.0):
    """Poll until ``ready()`` (the command is working) or fail."""
    t0 = time.monotonic()
    while not ready():
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() - t0 < timeout, "the command never started working"
        time.sleep(0.05)


def _stop(proc, sig):
    proc.send_signal(sig)
    out, err = proc.communicate(timeout=60)
    return proc.returncode, err.decode()


def _temps(folder: Path):
    return [p for p in folder.rglob(".*") if TEMP_NAME.match(p.name)]


def _one_error_line(err, line):
    errors = [ln for ln in err.replace("\r", "\n").splitlines() if ln.startswith("error:")]
    assert errors == [line], err
    assert "Traceback" not in err, err


STOPS = [(signal.SIGINT, 130, "error: interrupted"), (signal.SIGTERM, 143, "error: terminated")]


@pytest.mark.parametrize("sig, status, line", STOPS)
def test_synth_stopped_midway_leaves_nothing(tmp_path, sig, status, line):
    argv = ["synth", "cap", "--frames", "60", "--size", "48", "--ring-views", "2", "--raised-views", "0"]
    proc = _start(argv + ["--texture-size", "64"], tmp_path)
    _wait_for(proc, lambda: any(p.suffix == ".png" for d in _temps(tmp_path) for p in d.rglob("*.png")))
    code, err = _stop(proc, sig)
    assert code == status, err
    _one_error_line(err, line)
    assert list(tmp_path.iterdir()) == []  # neither the capture nor its temporary folder


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    """12 training frames of 6 views at 64²: prepare takes a few seconds at 256² texels."""
    poses, trans = make_sequence([("walk", 6), ("arm_raise", 6)], seed=3)
    settings = SynthSettings(ring_views=6, raised_views=0, size=64, texture_size=64)
    root = tmp_path_factory.mktemp("interrupts") / "cap"
    return synthesize(root, poses, trans, 12, default_body(), settings, progress=False)


def test_prepare_interrupted_keeps_whole_maps_only(capture):
    proc = _start(["prepare", str(capture), "--texture-size", "256"], capture.parent)
    cache = capture / "texvocab_cache"
    _wait_for(proc, lambda: any(cache.rglob("frame_*.npz")))
    code, err = _stop(proc, signal.SIGINT)
    assert code == 130, err
    _one_error_line(err, "error: interrupted")
    assert _temps(capture) == [] and len(list(cache.rglob("frame_*.npz"))) < 12


def _dead_pid() -> int:
    proc = subprocess.Popen(["true"])
    proc.wait()
    return proc.pid


def test_a_killed_writers_temp_files_are_swept_and_nothing_else(capture, capsys):
    argv = ["prepare", str(capture), "--texture-size", "16"]
    assert main(argv) == 0
    folder = next((capture / "texvocab_cache").glob("texmaps_16_*"))
    dead, host = _dead_pid(), host_tag()
    stale = folder / f".frame_000000.npz.tmp-{dead}-{host}-k2x9_a0q.npz"
    live = folder / f".frame_000001.npz.tmp-{os.getppid()}-{host}-abcd1234.npz"  # pytest's parent runs
    elsewhere = ("0" if host[0] != "0" else "1") + host[1:]
    other_host = folder / f".frame_000002.npz.tmp-{dead}-{elsewhere}-abcd1234.npz"
    foreign = [folder / ".frame_000000.npz.bak", folder / "notes.txt", folder / f".x.tmp-{dead}-nothex-a"]
    for p in [stale, live, other_host, *foreign]:
        p.write_bytes(b"half")
    (folder / "frame_000003.npz").unlink()  # one map to build: the folder is written again
    code = subprocess.run([TEXVOCAB, *argv], capture_output=True, timeout=120).returncode
    assert code == 0
    assert not stale.exists()
    assert live.exists() and other_host.exists() and all(p.exists() for p in foreign)


def test_synth_sweeps_a_killed_synths_folder(tmp_path, capsys):
    dead = _dead_pid()
    stale = tmp_path / f".cap.tmp-{dead}-{host_tag()}-q1w2e3r4"
    (stale / "images").mkdir(parents=True)
    keep = tmp_path / ".cap.old"
    keep.mkdir()
    argv = ["synth", str(tmp_path / "cap"), "--frames", "1", "--size", "16", "--texture-size", "16"]
    assert main(argv) == 0
    assert not stale.exists() and keep.is_dir() and (tmp_path / "cap").is_dir()


def test_train_interrupted_releases_its_run_folder(capture, tmp_path):
    sets = ["texture_size=16", "num_keys=2", "k=1", "encoder=small", "rays_per_batch=64", "perceptual=off"]
    argv = ["train", str(capture), "--out", "run", "--iterations", "100000"]
    proc = _start(argv + sum((["--set", s] for s in sets), []), tmp_path)
    lock = tmp_path / "run" / ".texvocab-train.lock"
    _wait_for(proc, lock.is_file)  # the run folder is taken: training starts
    time.sleep(1.0)
    code, err = _stop(proc, signal.SIGINT)
    assert code == 130, err
    _one_error_line(err, "error: interrupted")
    assert not lock.exists() and _temps(tmp_path) == []


def test_render_interrupted_as_ctrl_c_does_keeps_whole_frames_only(capture, tmp_path):
    """SIGINT to the render's whole process group (what Ctrl-C in a terminal sends): one
    line, status 130; the frames already cached are whole PNGs, no temporary file stays."""
    import numpy as np
    from tiny_runs import smallest_run

    ckpt = smallest_run(tmp_path / "avatar")
    poses = np.zeros((200, 24, 3), np.float32)
    poses[:, 18, 1] = np.radians(np.linspace(-10, -100, 200))
    np.savez(tmp_path / "walk.npz", poses=poses, trans=np.zeros((200, 3), np.float32))
    frames = tmp_path / "frames"
    argv = ["render", str(ckpt), "--poses", str(tmp_path / "walk.npz"), "--out", str(frames)]
    proc = _start(argv, tmp_path, start_new_session=True)
    # whole frames only: a frame being written is a hidden temporary file ending .png too
    _wait_for(proc, lambda: len(list(frames.glob("frame_*.png"))) >= 2, timeout=180)
    os.killpg(proc.pid, signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    err = err.decode()
    assert proc.returncode == 130, err
    _one_error_line(err, "error: interrupted")
    written = sorted(frames.glob("frame_*.png"))
    assert 2 <= len(written) < 200 and _temps(tmp_path) == []
    assert all(
        p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and p.read_bytes()[-8:-4] == b"IEND" for p in written
    )


def test_an_interrupt_wrapped_by_an_extension_is_still_one_line(monkeypatch, capsys):
    """Ctrl-C landing inside numba's dispatcher comes out as a SystemError raised from the
    KeyboardInterrupt: still one line and status 130; other errors are not swallowed."""
    import texvocab.cli.main as cli

    def wrapped(argv):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as e:
            raise SystemError("returned a result with an exception set") from e

    monkeypatch.setattr(cli, "run", wrapped)
    assert cli.main(["synth", "x"]) == 130
    assert capsys.readouterr().err.strip().splitlines() == ["error: interrupted"]

    def broken(argv):
        raise SystemError("a real bug")

    monkeypatch.setattr(cli, "run", broken)
    with pytest.raises(SystemError, match="a real bug"):
        cli.main(["synth", "x"])


def test_a_stop_that_ctypes_wrapped_without_a_chain_is_still_one_line(monkeypatch, capsys):
    """SIGTERM landing in ctypes' argument conversion (OSMesa's make-current) comes out
    as a ctypes.ArgumentError with no cause: the recorded signal makes it one line and
    status 143; the same error with no signal recorded is not swallowed."""
    import ctypes

    import texvocab.cli.main as cli
    from texvocab.io.stop_flag import Terminated, note_stop

    def wrapped(argv):
        note_stop(Terminated)
        raise ctypes.ArgumentError("argument 1: Terminated: ")

    monkeypatch.setattr(cli, "run", wrapped)
    assert cli.main(["synth", "x"]) == 143
    assert capsys.readouterr().err.strip().splitlines() == ["error: terminated"]

    def broken(argv):
        raise ctypes.ArgumentError("argument 1: wrong type")

    monkeypatch.setattr(cli, "run", broken)
    with pytest.raises(ctypes.ArgumentError, match="wrong type"):
        cli.main(["synth", "x"])


@pytest.mark.parametrize("sig, kind", [(signal.SIGINT, KeyboardInterrupt), (signal.SIGTERM, "Terminated")])
def test_a_swallowed_stop_signal_still_stops_the_next_write(tmp_path, sig, kind):
    """A library that catches every exception (trimesh's vertex normals do) swallows the
    interrupt; the signal was noted, so the write that would commit the command's output
    raises it instead, and nothing is put in place (texvocab.io.stop_flag)."""
    from texvocab.cli.interrupts import Terminated, stop_signals
    from texvocab.io.images import atomic_write_bytes

    kind = Terminated if kind == "Terminated" else kind
    before = signal.signal(signal.SIGINT, signal.default_int_handler)  # as a terminal's job has it
    out = tmp_path / "out.bin"
    try:
        _swallowed_then_written(stop_signals, sig, kind, out, tmp_path)
    finally:
        signal.signal(signal.SIGINT, before)
    # outside a command nothing is noted: the same write goes through
    atomic_write_bytes(out, lambda t: Path(t).write_bytes(b"x"))
    assert out.read_bytes() == b"x"


def _swallowed_then_written(stop_signals, sig, kind, out, tmp_path):
    from texvocab.io.images import atomic_write_bytes

    with stop_signals():
        try:
            os.kill(os.getpid(), sig)
            time.sleep(1)  # the handler runs here
        except BaseException:  # the library's catch-all
            pass
        with pytest.raises(kind):
            atomic_write_bytes(out, lambda t: Path(t).write_bytes(b"x"))
    assert list(tmp_path.iterdir()) == []
