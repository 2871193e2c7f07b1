"""The front door: the bad-input probe's cases as a table. Each runs the real command line
(``texvocab.cli.main.main``) on a tiny capture and checkpoint and asserts exit status 2,
exactly one ``error:`` line naming the field or file, and a disk left exactly as it was."""

import os
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
from bad_capture_cases import CAPTURE_CASES
from bad_output_cases import OUTPUT_CASES
from disk_snapshot import snapshot
from identity_cases import identity_cases
from train_cases import set_arguments, tiny_settings

from texvocab.body import default_body
from texvocab.capture import open as open_capture
from texvocab.capture.motion import make_sequence
from texvocab.capture.synth import SynthSettings, synthesize
from texvocab.cli.main import main


def _ckpt_with(world, name, change):
    ck = torch.load(world / "run" / "checkpoint.pt", weights_only=True)
    change(ck)
    path = world / "bad" / f"{name}.pt"
    path.parent.mkdir(exist_ok=True)
    torch.save(ck, path)
    return str(path)


def _capture_copy(world, name, change):
    dst = world / "bad" / name
    if not dst.exists():
        shutil.copytree(world / "cap", dst, ignore=shutil.ignore_patterns("texvocab_cache"))
        change(dst)
    return str(dst)


def _annots(key, value):
    def change(root):
        a = np.load(root / "annots.npy", allow_pickle=True).item()
        if key == "K":
            a["cams"]["K"] = [np.zeros((4, 2, 2))] * len(a["cams"]["K"])
        else:
            a[key] = value
        np.save(root / "annots.npy", a, allow_pickle=True)

    return change


def _resize_one_image(root):
    from PIL import Image

    path = open_capture(root).image_paths[1][2]
    with Image.open(path) as im:
        im.resize((48, 48)).save(path)


def _empty_one_mask(root):
    from PIL import Image

    path = open_capture(root).mask_paths[1][2]
    with Image.open(path) as im:
        Image.new(im.mode, im.size).save(path)


def _huge_pose(root):
    path = Path(root) / "params" / "1.npy"
    p = np.load(path, allow_pickle=True).item()
    p["poses"] = np.full_like(np.asarray(p["poses"]), 1e30)
    np.save(path, p, allow_pickle=True)


def _file(world, name, content: bytes):
    path = world / "bad" / name
    path.parent.mkdir(exist_ok=True)
    path.write_bytes(content)
    return str(path)


def _poses_file(world, name, **arrays):
    path = world / "bad" / name
    path.parent.mkdir(exist_ok=True)
    np.savez(path, **arrays)
    return str(path)


def _vocab_junk(ck):
    ck["vocab"]["key_frames"] = ["junk"]


def _wrong_shape(ck):
    key = next(k for k, v in ck["model"].items() if v.ndim == 2)
    ck["model"][key] = torch.zeros(3, 3)


def _still_poses(world):
    path = world / "bad" / "still.npz"
    path.parent.mkdir(exist_ok=True)
    np.savez(path, poses=np.zeros((2, 72)))
    return str(path)


def _nan_weight(ck):
    key = next(k for k, v in ck["model"].items() if v.ndim == 2)
    ck["model"][key] = ck["model"][key].clone().fill_(float("nan"))


def _settings_str(ck):
    ck["settings"] = "fast"


def _frames_out_of_range(ck):
    ck["vocab"]["key_frames"] = [f + 100 for f in ck["vocab"]["key_frames"]]


class _Evil:
    def __reduce__(self):
        return (os.system, ("touch PWNED",))


def _evil_checkpoint(world):
    path = world / "bad" / "evil.pt"
    path.parent.mkdir(exist_ok=True)
    torch.save({"format": "texvocab-checkpoint", "x": _Evil()}, path)
    return str(path)


def _user_folder(world):
    d = world / "bad" / "my_photos"
    d.mkdir(parents=True, exist_ok=True)
    (d / "holiday.jpg").write_bytes(b"not really a jpeg, but the user's")
    return str(d)


def _out_file(world):
    return _file(world, "a_file", b"x")


CAP = "{cap}"
RUN = "{run}"
T = [
    "train",
    CAP,
    "--out",
    "{base}/new_run",
    "--set",
    "perceptual=off",
    "--set",
    "num_keys=3",
    "--iterations",
    "1",
]


SETS = set_arguments(tiny_settings(iterations=2, perceptual="off"))  # the fixture run's
R = ["train", CAP, "--out", RUN, "--resume"] + SETS
# (case id, argv with {cap}/{run}/{base} placeholders or a callable building it, expected
# words in the error line)
CASES = [
    ("set-encoder-foo", T + ["--set", "encoder=foo"], "encoder"),
    ("set-field-3", T + ["--set", "field=3"], "field"),
    ("set-lr-nan", T + ["--set", "lr=nan"], "lr"),
    ("set-lr-zero", T + ["--set", "lr=0"], "lr"),
    ("set-pos-freqs-negative", T + ["--set", "field.pos_freqs=-1"], "field.pos_freqs"),
    ("set-lambda-color-nan", T + ["--set", "lambda_color=nan"], "lambda_color"),
    ("set-lambda-mask-inf", T + ["--set", "lambda_mask=inf"], "lambda_mask"),
    ("set-checkpoint-every-0", T + ["--set", "checkpoint_every=0"], "checkpoint_every"),
    ("set-max-minutes-negative", T + ["--set", "max_minutes=-1"], "max_minutes"),
    ("set-k-above-m", T + ["--set", "num_keys=3", "--set", "k=5"], "k="),
    ("set-num-keys-above-frames", T + ["--set", "num_keys=50"], "num_keys"),
    ("set-eval-views-outside", T + ["--set", "eval_views=1,99"], "eval_views"),
    ("set-train-eval-overlap", T + ["--set", "train_views=1,2"], "train_views"),
    ("set-eval-views-none", T + ["--set", "eval_views=none"], "eval_views"),
    ("set-strategy-bogus", T + ["--set", "strategy=bogus"], "strategy"),
    ("set-weighting-bogus", T + ["--set", "weighting=bogus"], "weighting"),
    ("set-unknown", T + ["--set", "nosuch=1"], "nosuch"),
    ("set-unknown-field", T + ["--set", "field.nosuch=1"], "field.nosuch"),
    ("set-no-equals", T + ["--set", "lr"], "key=value"),
    ("set-texture-size-abc", T + ["--set", "texture_size=abc"], "texture_size"),
    ("set-perceptual-vgg", T + ["--set", "perceptual=vgg"], "perceptual"),
    ("set-patch-size-4", T + ["--set", "patch_size=4"], "patch_size"),
    ("set-view-weighting-max", T + ["--set", "view_weighting=max"], "view_weighting"),
    ("set-fg-fraction-2", T + ["--set", "fg_fraction=2"], "fg_fraction"),
    ("set-dotted-range", T + ["--set", "render.coarse_samples=0"], "render.coarse_samples=0"),
    ("set-dotted-type", T + ["--set", "train.coarse_samples=2.5"], "train.coarse_samples"),
    ("set-dotted-unknown", T + ["--set", "train.nosuch=1"], "train.nosuch"),
    ("set-group", T + ["--set", "render=3"], "group of settings"),
    (
        "eval-set-train-knob",
        ["eval", RUN + "/checkpoint.pt", CAP, "--set", "train.coarse_samples=3"],
        "only render knobs",
    ),
    (
        "eval-set-misspelt",
        ["eval", RUN + "/checkpoint.pt", CAP, "--set", "render.coarse_sample=3"],
        "render.coarse_samples",
    ),
    ("iterations-negative", ["train", CAP, "--out", "{base}/new_run", "--iterations", "-5"], "iterations"),
    ("out-is-a-file", lambda w: ["train", str(w / "cap"), "--out", _out_file(w)], "is a file"),
    ("out-holds-checkpoint", ["train", CAP, "--out", RUN, "--iterations", "3"], "--resume"),
    ("resume-and-overwrite", ["train", CAP, "--out", RUN, "--resume", "--overwrite"], "exclude"),
    ("resume-past-iterations", R + ["--iterations", "1"], "already at step 2"),
    ("resume-other-settings", R + ["--set", "lr=0.1"], "written with train.lr"),
    ("synth-frames-0", ["synth", "{base}/new_cap", "--frames", "0"], "--frames"),
    ("synth-frames-negative", ["synth", "{base}/new_cap", "--frames", "-3"], "--frames"),
    ("synth-size-0", ["synth", "{base}/new_cap", "--size", "0"], "--size"),
    (
        "synth-overwrite-user-folder",
        lambda w: ["synth", _user_folder(w), "--overwrite", "--frames", "1"],
        "not one",
    ),
    (
        "synth-poses-empty",
        lambda w: [
            "synth",
            str(w / "new_cap"),
            "--poses",
            _poses_file(w, "empty.npz", poses=np.zeros((0, 72))),
        ],
        "0 frames",
    ),
    (
        "synth-poses-text-npz",
        lambda w: ["synth", str(w / "new_cap"), "--poses", _file(w, "text.npz", b"this is text, not numpy")],
        "text.npz: not an .npz archive",
    ),
    (
        "synth-poses-wrong-shape",
        lambda w: [
            "synth",
            str(w / "new_cap"),
            "--poses",
            _poses_file(w, "shape.npz", poses=np.zeros((4, 5))),
        ],
        "poses",
    ),
    (
        "synth-poses-huge",
        lambda w: [
            "synth",
            str(w / "new_cap"),
            "--poses",
            _poses_file(w, "huge.npz", poses=np.full((2, 72), 1e30)),
        ],
        "pose",
    ),
    ("eval-per-set-negative", ["eval", RUN + "/checkpoint.pt", CAP, "--per-set", "-1"], "--per-set"),
    (
        "eval-vocab-junk",
        lambda w: ["eval", _ckpt_with(w, "vocab", _vocab_junk), str(w / "cap")],
        "vocabulary",
    ),
    (
        "eval-vocab-frames-outside",
        lambda w: ["eval", _ckpt_with(w, "frames", _frames_out_of_range), str(w / "cap")],
        "vocabulary",
    ),
    (
        "eval-settings-string",
        lambda w: ["eval", _ckpt_with(w, "settings", _settings_str), str(w / "cap")],
        "settings",
    ),
    (
        "eval-wrong-tensor-shape",
        lambda w: ["eval", _ckpt_with(w, "shape", _wrong_shape), str(w / "cap")],
        "weights do not fit",
    ),
    (
        "eval-nan-weights",
        lambda w: ["eval", _ckpt_with(w, "nan", _nan_weight), str(w / "cap")],
        "holds NaN or inf",
    ),
    (
        "render-nan-weights",
        lambda w: [
            "render",
            _ckpt_with(w, "nan", _nan_weight),
            "--poses",
            _still_poses(w),
            "--out",
            str(w / "bad" / "nan.mp4"),
        ],
        "holds NaN or inf",
    ),
    ("eval-text-checkpoint", lambda w: ["eval", _file(w, "text.pt", b"hello"), str(w / "cap")], "text.pt"),
    (
        "eval-malicious-checkpoint",
        lambda w: ["eval", _evil_checkpoint(w), str(w / "cap")],
        "refused by the weights-only reader",
    ),
    ("eval-missing-checkpoint", ["eval", "{base}/nope.pt", CAP], "nope.pt"),
    ("eval-missing-capture", ["eval", RUN + "/checkpoint.pt", "{base}/nope_cap"], "nope_cap"),
    (
        "view-neural-processes-0",
        ["view", RUN + "/checkpoint.pt", "--neural-processes", "0"],
        "--neural-processes",
    ),
    (
        "view-preview-wait-negative",
        ["view", RUN + "/checkpoint.pt", "--neural-preview-wait", "-5"],
        "--neural-preview-wait -5: expected 0..200",
    ),
    (
        "view-preview-wait-huge",
        ["view", RUN + "/checkpoint.pt", "--neural-preview-wait", "1000"],
        "--neural-preview-wait 1000",
    ),
    ("vocab-k-0", ["vocab", CAP, "--pose", "frame:0", "-k", "0"], "k"),
    ("vocab-keys-0", ["vocab", CAP, "--pose", "frame:0", "--keys", "0"], "keys"),
    (
        "vocab-k-over-keys",
        ["vocab", CAP, "--pose", "frame:0", "--keys", "3", "-k", "50"],
        "number of keys (3)",
    ),
    ("vocab-frame-abc", ["vocab", CAP, "--pose", "frame:abc"], "frame:abc"),
    ("vocab-frame-999", ["vocab", CAP, "--pose", "frame:999"], "frame"),
    (
        "vocab-min-distance-negative",
        ["vocab", CAP, "--pose", "frame:0", "--min-distance", "-1"],
        "--min-distance",
    ),
    (
        "sheet-frames-abc",
        ["contact-sheet", CAP, "--frames", "1,abc", "--out", "{base}/sheet.png"],
        "--frames",
    ),
    (
        "annots-K-4x2x2",
        lambda w: ["vocab", _capture_copy(w, "k422", _annots("K", None)), "--pose", "frame:0"],
        "K",
    ),
    (
        "annots-ims-abc",
        lambda w: ["vocab", _capture_copy(w, "imsabc", _annots("ims", "abc")), "--pose", "frame:0"],
        "ims",
    ),
    (
        "annots-not-a-dict",
        lambda w: [
            "vocab",
            _capture_copy(w, "notdict", lambda r: np.save(r / "annots.npy", np.arange(3))),
            "--pose",
            "frame:0",
        ],
        "annots.npy",
    ),
    (
        "synth-json-broken",
        lambda w: [
            "vocab",
            _capture_copy(w, "json", lambda r: (r / "texvocab_synth.json").write_text("{broken")),
            "--pose",
            "frame:0",
        ],
        "texvocab_synth.json",
    ),
    (
        "train-image-other-size",
        lambda w: [
            "train",
            _capture_copy(w, "resized", _resize_one_image),
            "--out",
            str(w / "new_run"),
            "--set",
            "num_keys=3",
        ],
        "48x48",
    ),
    (
        "capture-pose-1e30",
        lambda w: ["vocab", _capture_copy(w, "hugepose", _huge_pose), "--pose", "frame:0"],
        "SMPL parameters",
    ),
    ("capture-missing", ["vocab", "{base}/nope_cap", "--pose", "frame:0"], "nope_cap"),
    ("check-assets-missing", ["check-assets", "{base}/nope_cap"], "nope_cap"),
] + CAPTURE_CASES
CASES += identity_cases(SETS)  # another capture than the checkpoint's
CASES += OUTPUT_CASES  # outputs that cannot be written (bad_output_cases.py)


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_bad_input_gives_one_error_line_and_changes_nothing(case, world, capsys):
    _, argv, words = case
    argv = (
        argv(world)
        if callable(argv)
        else [a.format(cap=world / "cap", run=world / "run", base=world) for a in argv]
    )
    before = snapshot(world)
    cwd = os.getcwd()
    try:
        code = main(argv)
    finally:
        os.chdir(cwd)
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip() and "WARNING" not in ln]
    assert code == 2, err
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    assert words in lines[0], lines[0]
    assert "weights_only" not in lines[0]  # never advise loading untrusted pickles
    assert snapshot(world) == before


def test_case_table_covers_the_probe():
    assert len(CASES) >= 40 and len({c[0] for c in CASES}) == len(CASES)


@pytest.mark.parametrize("name", ["k422", "imsabc", "notdict", "json", "resized", "emptymask"])
def test_check_assets_reports_a_bad_capture_as_one_fail_line(name, world, capsys):
    change = {
        "k422": _annots("K", None),
        "imsabc": _annots("ims", "abc"),
        "notdict": lambda r: np.save(r / "annots.npy", np.arange(3)),
        "json": lambda r: (r / "texvocab_synth.json").write_text("{broken"),
        "resized": _resize_one_image,
        "emptymask": _empty_one_mask,
    }[name]
    root = _capture_copy(world, name, change)
    assert main(["check-assets", root]) == 1
    out = capsys.readouterr().out.strip().splitlines()
    assert len(out) == 1 and out[0].startswith("FAIL ") and root in out[0], out


def test_check_assets_passes_the_good_capture_and_flags_missing_eval_views(world, tmp_path, capsys):
    assert main(["check-assets", str(world / "cap")]) == 0
    assert capsys.readouterr().out.startswith("OK ")
    poses, trans = make_sequence([("walk", 2)], seed=1)
    four = synthesize(
        tmp_path / "four",
        poses,
        trans,
        2,
        default_body(),
        SynthSettings(ring_views=4, raised_views=0, size=32, texture_size=64),
        progress=False,
    )
    assert main(["check-assets", str(four)]) == 0  # a valid capture; the defaults do not fit
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("note ") and "default eval_views are [1, 5]" in out[0]
    assert "--set data.eval_views" in out[0] and out[1].startswith("OK ")
