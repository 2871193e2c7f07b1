"""The console script: --help everywhere, check-assets verdicts, one-line errors."""

import subprocess
import sys
from pathlib import Path

import pytest
from smpl_files import write_official_pickle

from texvocab.cli.main import build_parser

TEXVOCAB = str(Path(sys.executable).parent / "texvocab")


ONE_SMALL_VIEW = ("--size", "32", "--ring-views", "1", "--raised-views", "0")  # synth's smallest


def run(*args, check_rc=None):
    proc = subprocess.run([TEXVOCAB, *args], capture_output=True, text=True, timeout=120)
    if check_rc is not None:
        assert proc.returncode == check_rc, proc.stdout + proc.stderr
    return proc


def _subcommands():
    parser = build_parser()
    action = next(a for a in parser._actions if a.dest == "command")
    return sorted(action.choices)


def test_help_on_every_subcommand():
    out = run("--help", check_rc=0).stdout
    for cmd in _subcommands():
        assert cmd in out
        sub = run(cmd, "--help", check_rc=0).stdout
        assert sub.startswith("usage: texvocab " + cmd)


def test_check_assets_ok_and_wrong_shape(tmp_path, toy_arrays, monkeypatch):
    good = tmp_path / "good" / "SMPL_NEUTRAL.pkl"
    good.parent.mkdir()
    write_official_pickle(good, toy_arrays, monkeypatch)
    out = run("check-assets", str(good), check_rc=0).stdout
    assert out.startswith("OK") and "valid smpl model" in out

    toy_arrays["posedirs"] = toy_arrays["posedirs"][..., :200]
    bad = tmp_path / "bad" / "SMPL_NEUTRAL.pkl"
    bad.parent.mkdir()
    write_official_pickle(bad, toy_arrays, monkeypatch)
    out = run("check-assets", str(bad.parent), check_rc=1).stdout
    assert "FAIL" in out and "'posedirs' has shape (96, 3, 200), expected (96, 3, 207)" in out


def test_missing_smpl_is_one_error_line(tmp_path):
    missing = tmp_path / "nowhere" / "SMPL_NEUTRAL.pkl"
    proc = run("demo", "--smpl", str(missing), "--out", str(tmp_path / "o"), check_rc=2)
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: SMPL model file not found")
    assert str(missing) in lines[0] and "assets_spec/smpl_model.json" in lines[0]
    assert not (tmp_path / "o").exists()  # nothing written


def test_check_assets_missing_path(tmp_path):
    proc = run("check-assets", str(tmp_path / "nope"), check_rc=2)
    assert "no such file or folder" in proc.stderr


@pytest.mark.parametrize("args", [["frobnicate"], []])
def test_unknown_command_is_usage_error(args):
    assert run(*args).returncode == 2


def test_synth_contact_sheet_and_check_assets(tmp_path):
    cap = tmp_path / "cap"
    out = run(
        "synth",
        str(cap),
        "--frames",
        "3",
        "--train-frames",
        "2",
        "--size",
        "64",
        "--ring-views",
        "2",
        "--raised-views",
        "1",
        "--texture-size",
        "256",
        check_rc=0,
    )
    assert "3 frames x 3 views (zju layout, 2 training frames)" in out.stdout
    assert "synth cap" in out.stderr  # progress bar
    out = run("check-assets", str(cap), check_rc=0).stdout.splitlines()
    assert out[0].startswith("note ") and "eval_views" in out[0]  # 3 views: not 1 and 5
    assert out[1].startswith("OK")
    sheet = tmp_path / "sheet.png"
    run("contact-sheet", str(cap), "--out", str(sheet), check_rc=0)
    from PIL import Image

    assert Image.open(sheet).size[0] > 3 * 64
    # refusing to overwrite, and a pose file with NaN, each a single error line; nothing written
    assert "already exists" in run("synth", str(cap), "--frames", "1", check_rc=2).stderr
    import numpy as np

    bad = tmp_path / "bad.npz"
    poses = np.zeros((2, 24, 3))
    poses[1, 5, 2] = np.inf
    np.savez(bad, poses=poses)
    proc = run("synth", str(tmp_path / "novel"), "--poses", str(bad), "--like", str(cap), check_rc=2)
    assert proc.stderr.strip().count("\n") == 0
    assert "bad.npz: 'poses' frame 1 joint 5 (right_knee) is not finite" in proc.stderr
    assert not (tmp_path / "novel").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.npz", "cap", "sheet.png"]


def test_prepare_and_vocab_commands(tmp_path):
    cap = tmp_path / "cap"
    run(
        "synth",
        str(cap),
        "--frames",
        "4",
        "--train-frames",
        "3",
        "--size",
        "64",
        "--ring-views",
        "2",
        "--raised-views",
        "0",
        "--texture-size",
        "128",
        check_rc=0,
    )
    err = run("prepare", str(cap), "--texture-size", "32", check_rc=2).stderr
    assert err.startswith("error: setting data.eval_views=[1, 5]") and "views 0..1" in err  # no 5
    out = run("prepare", str(cap), "--texture-size", "32", "--eval-views", "1", check_rc=0).stdout
    assert out.startswith("3 texture maps (32² texels, views 0)")  # view 1 is held out
    assert len(list((cap / "texvocab_cache" / "texmaps_32_views_0").glob("frame_*.npz"))) == 3
    out = run("prepare", str(cap), "--texture-size", "32", "--eval-views", check_rc=0).stdout
    assert out.startswith("3 texture maps (32² texels, views 0,1)")
    share = int(out.splitlines()[1].split("coverage: ")[1].split(" %")[0])
    assert 40 <= share <= 100  # two ring views see most of the body
    out = run("vocab", str(cap), "--pose", "frame:3", "-k", "2", "--keys", "3", check_rc=0).stdout
    lines = out.strip().splitlines()
    assert "strategy=part, M=3 keys/part, K=2" in lines[1] and len(lines) == 3 + 5
    err = run("vocab", str(cap), "--pose", "frame:9", check_rc=2).stderr
    assert "the capture has frames 0..3" in err


def test_synth_compositional_motion_writes_that_motion(tmp_path):
    """--motion compositional: the capture's poses are compositional_motion's, not the
    default motion's."""
    import numpy as np

    from texvocab.capture import open as open_capture
    from texvocab.capture.compositional import compositional_motion
    from texvocab.capture.motion import default_motion

    cap = tmp_path / "comp"
    run(
        "synth",
        str(cap),
        "--motion",
        "compositional",
        "--frames",
        "5",
        *ONE_SMALL_VIEW,
        "--texture-size",
        "64",
        check_rc=0,
    )
    got = open_capture(cap)
    want, _, num_train = compositional_motion(0)
    assert np.allclose(got.poses, want[:5], atol=1e-5) and got.num_train == 5 <= num_train
    assert not np.allclose(got.poses, default_motion(0)[0][:5], atol=1e-3)


def test_contact_sheet_never_replaces_a_file_that_is_not_a_png(tmp_path):
    cap = tmp_path / "cap"
    run("synth", str(cap), "--frames", "2", *ONE_SMALL_VIEW, check_rc=0)
    notes = tmp_path / "notes.txt"
    notes.write_text("mine")
    proc = run("contact-sheet", str(cap), "--out", str(notes), check_rc=2)
    assert proc.stderr.strip().splitlines() == [
        f"error: --out {notes}: exists and is not a PNG; expected a new file, or a PNG to replace "
        "(nothing was changed)"
    ]
    assert notes.read_text() == "mine"
    sheet = tmp_path / "sheet.png"
    run("contact-sheet", str(cap), "--out", str(sheet), check_rc=0)
    run("contact-sheet", str(cap), "--out", str(sheet), check_rc=0)  # a PNG is replaced
    assert sheet.read_bytes()[:4] == b"\x89PNG"
