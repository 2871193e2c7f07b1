"""``texvocab shot`` over OSMesa (no display): the default body's 3D view matches committed
reference PNGs within a tolerance (a diff PNG is saved next to the output on failure), and
for a tiny checkpoint the neural render is written from the same camera as the 3D view."""

from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from scipy import ndimage
from tiny_runs import smallest_run

from texvocab.cli.main import main
from texvocab.io.images import save_png

DATA = Path(__file__).resolve().parent.parent / "data"
MEAN_TOL = 2.0 / 255  # mean absolute difference, per channel
PIXEL_TOL, PIXEL_SHARE = 32, 0.01  # under 1 % of pixels may differ by more than 32/255


def read(path: Path) -> np.ndarray:
    with Image.open(path) as im:
        return np.asarray(im.convert("RGB"))


def assert_matches_reference(out: Path, ref: Path) -> None:
    """Compare PNGs; on failure write ``<out>.diff.png`` (|difference| x 4) and name it."""
    got, want = read(out), read(ref)
    assert got.shape == want.shape, f"{out}: size {got.shape} != reference {want.shape}"
    diff = np.abs(got.astype(np.int16) - want.astype(np.int16))
    mean = diff.mean() / 255
    share = (diff.max(-1) > PIXEL_TOL).mean()
    if mean >= MEAN_TOL or share >= PIXEL_SHARE:
        diff_path = out.with_suffix(".diff.png")
        save_png(diff_path, np.clip(diff * 4, 0, 255).astype(np.uint8))
        pytest.fail(
            f"{out} differs from {ref}: mean |diff| {mean * 255:.2f}/255, "
            f"{share:.2%} of pixels off by > {PIXEL_TOL}/255; diff image: {diff_path}"
        )


@pytest.mark.parametrize(
    "ref,overlays",
    [("shot_reference.png", []), ("shot_reference_overlays.png", ["--overlay", "part_colors", "skeleton"])],
)
def test_shot_matches_reference(tmp_path, capsys, ref, overlays):
    rc = main(
        [
            "shot",
            "--pose",
            "walk",
            "--camera",
            "30,10,3.0",
            "--size",
            "192x240",
            "--out",
            str(tmp_path),
            *overlays,
        ]
    )
    assert rc == 0
    printed = capsys.readouterr().out
    for name in ("view3d.png", "shot.png"):
        assert str((tmp_path / name).resolve()) in printed
    assert not (tmp_path / "neural.png").exists()
    assert_matches_reference(tmp_path / "view3d.png", DATA / ref)


def test_reference_check_fails_and_saves_a_diff(tmp_path):
    """The comparison itself can fail: a shifted image is caught and its diff saved."""
    img = read(DATA / "shot_reference.png")
    out = save_png(tmp_path / "view3d.png", np.roll(img, 6, axis=1))
    with pytest.raises(pytest.fail.Exception, match="diff image: .*view3d.diff.png"):
        assert_matches_reference(out, DATA / "shot_reference.png")
    assert (tmp_path / "view3d.diff.png").is_file()


def test_shot_errors_are_one_line(tmp_path, capsys):
    assert main(["shot", "--pose", "7", "--out", str(tmp_path / "o")]) == 2
    assert "--pose 7: a frame index needs a capture or checkpoint" in capsys.readouterr().err
    assert main(["shot", "--camera", "1,2", "--out", str(tmp_path / "o")]) == 2
    assert "expected a capture view index or 'yaw,pitch,distance'" in capsys.readouterr().err
    assert main(["shot", "--size", "12x9000", "--out", str(tmp_path / "o")]) == 2
    assert "--size '12x9000': expected WIDTHxHEIGHT" in capsys.readouterr().err
    assert main(["shot", "--neural", "--out", str(tmp_path / "o")]) == 2
    assert "--neural needs a checkpoint" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


@pytest.fixture(scope="module")
def tiny_checkpoint(tmp_path_factory):
    """A capture of 2 frames (1 for training) x 3 views at 64 px, a 2-step run on it."""
    return smallest_run(tmp_path_factory.mktemp("shot"))


def test_shot_of_a_checkpoint_writes_the_neural_render_from_the_same_camera(
    tiny_checkpoint, tmp_path, capsys
):
    out = tmp_path / "shot"
    assert main(["shot", str(tiny_checkpoint), "--pose", "1", "--camera", "1", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "neural render in" in printed
    view, neural, both = (read(out / n) for n in ("view3d.png", "neural.png", "shot.png"))
    assert view.shape == neural.shape == (64, 64, 3)  # the capture view's size
    assert both.shape[1] > 2 * 64
    from texvocab_viewer.gl.scene import SceneOptions

    bg = np.asarray(SceneOptions().background) * 255
    gl_body = np.abs(view - bg).max(-1) > 3
    neural_fg = np.abs(neural - bg).max(-1) > 3
    assert neural_fg.sum() > 0.3 * gl_body.sum()  # the (geometry-initialised) field shows up
    # everything the field draws lies on the GL view's body (shell δ ~ 1 pixel here)
    near_body = ndimage.binary_dilation(gl_body, iterations=3)
    assert neural_fg[~near_body].sum() == 0
    inter = (neural_fg & gl_body).sum() / (neural_fg | gl_body).sum()
    print(f"silhouette IoU neural vs GL: {inter:.3f}")
    assert inter > 0.6


def test_demo_without_a_display_writes_the_viewer_shots(tiny_checkpoint, tmp_path):
    """What `texvocab demo` does at its end when there is no display."""
    from texvocab_viewer.export.shot import DEMO_LOOKS, demo_shots

    sheet = demo_shots(tiny_checkpoint, tmp_path / "viewer", poses=("1", "kick"))
    img = read(sheet)
    # two rows (one per pose) of 3D-view looks plus the neural render, 64 px tiles
    assert img.shape[0] > 2 * 64 and img.shape[1] > (len(DEMO_LOOKS) + 1) * 64
    for pose in ("1", "kick"):
        view, neural = (
            read(tmp_path / "viewer" / f"pose_{pose}" / "view3d.png"),
            read(tmp_path / "viewer" / f"pose_{pose}" / "neural.png"),
        )
        assert view.std() > 5 and neural.std() > 1  # a body is drawn in both
