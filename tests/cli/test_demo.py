"""`texvocab demo` (current stage): the body in six poses, rendered offscreen (OSMesa)."""

import numpy as np
from PIL import Image

from texvocab.cli.demo import DEMO_POSES, run_demo


def _body_fraction(rgb):
    return float((np.asarray(rgb, dtype=np.float32)[..., :3].min(-1) < 0.97).mean())


def test_demo_writes_a_sheet_of_six_poses(tmp_path):
    paths = run_demo(tmp_path, size=96)
    sheet = np.asarray(Image.open(paths[0]))
    assert paths[0].name == "poses.png" and sheet.ndim == 3
    assert len(paths) == 1 + 2 * len(DEMO_POSES)
    tiles = {p.stem: np.asarray(Image.open(p)) / 255.0 for p in paths[1:]}
    for name, tile in tiles.items():
        assert tile.shape == (96, 96, 3)
        assert 0.03 < _body_fraction(tile) < 0.6, name  # the body is there, not a blank frame

    # different poses and views give different silhouettes
    def sil(t):
        return t.min(-1) < 0.97

    def iou(a, b):
        return (sil(a) & sil(b)).sum() / (sil(a) | sil(b)).sum()

    assert iou(tiles["t_pose_front"], tiles["squat_front"]) < 0.6
    assert iou(tiles["t_pose_front"], tiles["t_pose_side"]) < 0.6

    # a T-pose seen from the front is wider than tall-thin side view
    def width(t):
        cols = np.where((t.min(-1) < 0.97).any(0))[0]
        return cols.max() - cols.min()

    assert width(tiles["t_pose_front"]) > 2 * width(tiles["t_pose_side"])


def test_demo_capture_is_reused(tmp_path):
    from texvocab.cli.demo import demo_capture

    root, sheet = demo_capture(tmp_path, frames=2)
    assert (root / "annots.npy").is_file() and sheet.is_file()
    stamp = (root / "annots.npy").stat().st_mtime_ns
    demo_capture(tmp_path, frames=2)
    assert (root / "annots.npy").stat().st_mtime_ns == stamp  # second run renders nothing
