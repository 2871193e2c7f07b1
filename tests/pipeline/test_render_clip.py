"""``texvocab render``: a raw AMASS-layout file (written here) drives a trained avatar to
an MP4 whose frame count, size and rate are read back from the file; an interrupted
render resumes from its cached frames; bad input changes nothing."""

import os

import numpy as np
import pytest
from pose_file_cases import amass_file
from tiny_runs import smallest_run

from texvocab.cli.main import main
from texvocab.pipeline.clip import frame_cameras, read_video_info


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory):
    return smallest_run(tmp_path_factory.mktemp("clip"))


def test_amass_file_renders_to_an_mp4_read_back(checkpoint, tmp_path, capsys):
    amass_file(tmp_path / "walk.npz", frames=49, rate=120.0)  # 0.4 s -> 13 frames at 30 fps
    out = tmp_path / "clip.mp4"
    assert (
        main(
            [
                "render",
                str(checkpoint),
                "--poses",
                str(tmp_path / "walk.npz"),
                "--out",
                str(out),
                "--preset",
                "fast",
            ]
        )
        == 0
    )
    frames, size, fps = read_video_info(out)
    assert (frames, size, fps) == (13, (64, 64), 30.0)
    pngs = sorted((tmp_path / "clip.frames").glob("frame_*.png"))
    assert len(pngs) == 13
    from PIL import Image

    first = np.asarray(Image.open(pngs[0]))
    assert first.shape == (64, 64, 3) and first.max() > 30  # the body is in view
    # interrupted: two frames lost; the same command (with --overwrite for the finished
    # video) renders only those two and keeps the others byte for byte
    kept = pngs[0].read_bytes(), os.stat(pngs[0]).st_mtime_ns
    pngs[5].unlink()
    pngs[9].unlink()
    capsys.readouterr()
    assert (
        main(
            [
                "render",
                str(checkpoint),
                "--poses",
                str(tmp_path / "walk.npz"),
                "--out",
                str(out),
                "--preset",
                "fast",
                "--overwrite",
            ]
        )
        == 0
    )
    assert "rendered 2 frames (11 cached)" in capsys.readouterr().out
    assert (pngs[0].read_bytes(), os.stat(pngs[0]).st_mtime_ns) == kept
    assert read_video_info(out)[0] == 13


def test_other_settings_never_reuse_or_destroy_cached_frames(checkpoint, tmp_path, capsys):
    amass_file(tmp_path / "walk.npz", frames=9, rate=120.0)
    folder = tmp_path / "seq"
    args = [
        "render",
        str(checkpoint),
        "--poses",
        str(tmp_path / "walk.npz"),
        "--out",
        str(folder),
        "--preset",
        "fast",
    ]
    assert main(args) == 0
    before = {p.name: p.read_bytes() for p in folder.glob("frame_*.png")}
    assert len(before) == 3
    capsys.readouterr()
    assert main(args + ["--camera", "2"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and "view" in err[0]
    assert {p.name: p.read_bytes() for p in folder.glob("frame_*.png")} == before
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("keep")
    assert main(args[:5] + [str(tmp_path / "mine")]) == 2
    assert (tmp_path / "mine" / "notes.txt").read_text() == "keep"


def test_render_knobs_by_either_name_are_the_same_clip(checkpoint, tmp_path, capsys):
    amass_file(tmp_path / "walk.npz", frames=9, rate=120.0)
    args = [
        "render",
        str(checkpoint),
        "--poses",
        str(tmp_path / "walk.npz"),
        "--out",
        str(tmp_path / "seq"),
        "--preset",
        "fast",
    ]
    assert main(args + ["--set", "render.fine_samples=1"]) == 0
    assert "rendered 3 frames (0 cached)" in capsys.readouterr().out
    assert main(args + ["--set", "fine_samples=1"]) == 0  # the flat name: the same knob
    assert "rendered 0 frames (3 cached)" in capsys.readouterr().out


@pytest.mark.parametrize(
    "extra,needle",
    [
        (["--camera", "7"], "--camera 7"),
        (["--frames", "5:2"], "--frames"),
        (["--fps", "0"], "--fps"),
        (["--set", "render.fine_sample=1"], "did you mean render.fine_samples"),
        (["--set", "vocab.k=1"], "only render knobs"),
    ],
)
def test_bad_render_arguments_give_one_error_line(checkpoint, tmp_path, capsys, extra, needle):
    amass_file(tmp_path / "walk.npz", frames=9, rate=120.0)
    code = main(
        ["render", str(checkpoint), "--poses", str(tmp_path / "walk.npz"), "--out", str(tmp_path / "c.mp4")]
        + extra
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("error:") and needle in err[0]
    assert not (tmp_path / "c.mp4").exists() and not (tmp_path / "c.frames").exists()


def test_follow_camera_keeps_the_root_where_the_capture_had_it():
    from texvocab.capture.camera import Camera

    K = np.array([[100.0, 0, 32], [0, 100.0, 32], [0, 0, 1]])
    cam = Camera(K, np.eye(3), np.array([0.0, 0.0, 3.0]), 64, 64)
    roots = np.array([[0.0, 0, 0], [1.0, 0.2, -0.5]])
    for c, r in zip(frame_cameras(cam, roots, np.zeros(3), True, 0.0), roots, strict=True):
        px, _ = c.project(r[None])
        assert np.allclose(px[0], [32, 32])
    # one turn over 2 frames: frame 1 looks at the root from the other side
    turned = frame_cameras(cam, roots, np.zeros(3), True, 1.0)[1]
    px, z = turned.project(roots[1:])
    assert np.allclose(px[0], [32, 32]) and z[0] == pytest.approx(3.0)
    assert np.allclose(cam.center, [0, 0, -3.0]) and np.allclose(
        turned.center - roots[1], [0, 0, 3.0], atol=1e-9
    )


@pytest.mark.slow  # a local Ray cluster
def test_ray_frames_equal_the_serial_render(checkpoint, tmp_path):
    """`--ray` on a local 2-worker Ray: the same frames as the serial render (to one 8-bit
    level: the workers run 1 torch thread, the serial render the process's)."""
    from PIL import Image

    amass_file(tmp_path / "walk.npz", frames=17, rate=120.0)  # 5 frames at 30 fps
    base = [
        "render",
        str(checkpoint),
        "--poses",
        str(tmp_path / "walk.npz"),
        "--preset",
        "fast",
        "--orbit",
        "0.5",
    ]
    assert main(base + ["--out", str(tmp_path / "serial")]) == 0
    assert main(base + ["--out", str(tmp_path / "ray"), "--ray", "--workers", "2"]) == 0
    names = sorted(p.name for p in (tmp_path / "serial").glob("frame_*.png"))
    assert len(names) == 5 and names == sorted(p.name for p in (tmp_path / "ray").glob("*.png"))
    for name in names:
        a = np.asarray(Image.open(tmp_path / "serial" / name)).astype(int)
        b = np.asarray(Image.open(tmp_path / "ray" / name)).astype(int)
        assert np.abs(a - b).max() <= 1 and (a == b).mean() > 0.99


def test_side_by_side_panels_show_the_same_body(checkpoint, tmp_path):
    """--panels neural,vocab,novelty: three 64² panels per frame, the GL views (OSMesa)
    drawn from the same camera as the neural render: their silhouettes coincide."""
    from PIL import Image

    amass_file(tmp_path / "walk.npz", frames=9, rate=120.0)
    out = tmp_path / "p.mp4"
    assert (
        main(
            [
                "render",
                str(checkpoint),
                "--poses",
                str(tmp_path / "walk.npz"),
                "--out",
                str(out),
                "--preset",
                "fast",
                "--panels",
                "neural,vocab,novelty",
            ]
        )
        == 0
    )
    assert read_video_info(out)[:2] == (3, (192, 64))
    frame = np.asarray(Image.open(tmp_path / "p.frames" / "frame_00000.png")).astype(int)
    masks = [frame[:, 64 * i : 64 * (i + 1)].sum(-1) > 30 for i in range(3)]
    for m in masks[1:]:
        iou = (m & masks[0]).sum() / (m | masks[0]).sum()
        assert iou > 0.6, iou
    novelty = frame[:, 128:][masks[2]]
    assert novelty[:, 2].mean() > 60 or novelty[:, 0].mean() > 60  # heat colours, not grey


@pytest.mark.parametrize(
    "extra,needle", [(["--panels", "neural,depth"], "--panels"), (["--panels", "vocab", "--ray"], "--ray")]
)
def test_bad_panels_give_one_error_line(checkpoint, tmp_path, capsys, extra, needle):
    amass_file(tmp_path / "walk.npz", frames=9, rate=120.0)
    code = main(
        ["render", str(checkpoint), "--poses", str(tmp_path / "walk.npz"), "--out", str(tmp_path / "c.mp4")]
        + extra
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and needle in err[0]
    assert not (tmp_path / "c.frames").exists()
