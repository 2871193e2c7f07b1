"""The one reader of capture images and masks: good files decode; damaged, foreign-format and
over-sized ones are one AssetError naming the file, before any pixel of a huge image is
allocated (the memory test runs the refusal in a fresh process and reads its peak RSS)."""

import json
import subprocess
import sys

import numpy as np
import pytest
from bad_files import garbage, gif_bytes, png_bytes, png_declaring, truncated
from PIL import Image

from texvocab.capture import image_reader
from texvocab.capture.image_reader import (
    MAX_PIXELS,
    first_size,
    image_size,
    read_image,
    read_mask,
    verify_image,
)
from texvocab.errors import AssetError


def _write(tmp_path, name, data: bytes):
    path = tmp_path / name
    path.write_bytes(data)
    return path


def test_a_good_png_and_jpeg_decode(tmp_path):
    rgb = np.zeros((6, 8, 3), np.uint8)
    rgb[2:4, 3:6] = 255
    Image.fromarray(rgb).save(tmp_path / "a.png")
    Image.fromarray(rgb).save(tmp_path / "a.jpg", quality=100)
    for name in ("a.png", "a.jpg"):
        assert image_size(tmp_path / name) == (8, 6)
        img = read_image(tmp_path / name)
        assert img.shape == (6, 8, 3) and img.dtype == np.float32
        assert abs(float(img[3, 4, 0]) - 1.0) < 0.05 and float(img[0, 0, 0]) < 0.05
        mask = read_mask(tmp_path / name)
        assert mask.dtype == bool and mask.sum() == 6


@pytest.mark.parametrize(
    "name,data,words",
    [
        ("garbage.png", garbage(), "not a readable (image|mask)"),
        ("empty.png", b"", "not a readable (image|mask)"),
        ("anim.gif", gif_bytes(), "expected a PNG or JPEG"),
        ("bomb.png", png_declaring(100_000, 100_000), "10000 Mpx is over the limit of 40 Mpx"),
        ("wide.png", png_declaring(8000, 8000), "8000x8000 pixels, 64 Mpx is over the limit"),
    ],
)
def test_a_bad_header_is_refused_naming_the_file(tmp_path, name, data, words):
    path = _write(tmp_path, name, data)
    for call in (image_size, read_image, read_mask, verify_image):
        with pytest.raises(AssetError, match=words) as err:
            call(path)
        assert str(err.value).startswith(f"{path}: ")


@pytest.mark.parametrize("keep", [0.3, 0.6, 0.9])
def test_a_truncated_png_is_refused_on_decoding(tmp_path, keep):
    path = _write(tmp_path, "cut.png", truncated(png_bytes((64, 48)), keep))
    assert image_size(path) == (64, 48)  # the header survived: only decoding finds it
    for call in (read_image, read_mask, verify_image):
        with pytest.raises(AssetError, match="truncated or damaged") as err:
            call(path)
        assert str(err.value).startswith(f"{path}: ")


def test_a_missing_file_is_named(tmp_path):
    with pytest.raises(AssetError, match=r"nope\.png: mask not found"):
        read_mask(tmp_path / "nope.png")


def test_first_size_skips_damaged_headers_and_names_the_first_when_all_are(tmp_path):
    bad = _write(tmp_path, "0.png", garbage())
    good = _write(tmp_path, "1.png", png_bytes((10, 7)))
    assert first_size([bad, good]) == (10, 7)
    with pytest.raises(AssetError, match=r"0\.png: not a readable image"):
        first_size([bad, _write(tmp_path, "2.png", b"")])


def test_the_limit_is_below_pils_own_bomb_warning():
    # pixels between the two limits are refused by this reader, not warned about by PIL
    assert MAX_PIXELS < Image.MAX_IMAGE_PIXELS


PROBE = """
import importlib.util, json, sys
from PIL import Image
# the reader's module alone (texvocab.errors aside): the package would bring torch along
spec = importlib.util.spec_from_file_location("image_reader", sys.argv[1])
reader = importlib.util.module_from_spec(spec)
spec.loader.exec_module(reader)
out = []
for path, guard in zip(sys.argv[2::2], sys.argv[3::2]):
    Image.MAX_IMAGE_PIXELS = None if guard == "off" else 89_478_485  # off: a library did so
    for read in (reader.read_image, reader.read_mask, reader.verify_image):
        try:
            read(path)
            out.append("decoded " + path)
        except reader.AssetError as e:
            out.append(str(e))
# this process's peak RSS (ru_maxrss would carry the forking parent's over exec)
peak = next(ln for ln in open("/proc/self/status") if ln.startswith("VmHWM:"))
print(json.dumps([out, int(peak.split()[1])]))
"""


def test_decompression_bombs_are_refused_in_little_memory(tmp_path):
    """PNGs of a few hundred bytes declaring 100000² and 30000² (with PIL's own guard switched
    off) pixels, and a complete 8000² one of 64 KB (below PIL's guard: decoded, its float
    copy alone would be 768 MB): refused, and the process's peak RSS stays far under 1 GB."""
    args = []
    for size, guard in ((100_000, "on"), (30_000, "off"), (8000, "on")):
        path = _write(tmp_path, f"bomb{size}.png", png_declaring(size, size, complete=size == 8000))
        assert path.stat().st_size < 70_000
        args += [str(path), guard]
    run = subprocess.run(
        [sys.executable, "-c", PROBE, image_reader.__file__, *args],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert run.returncode == 0, run.stderr
    messages, peak_kb = json.loads(run.stdout.strip().splitlines()[-1])
    assert len(messages) == 9
    assert all("over the limit of 40 Mpx" in m and "bomb" in m for m in messages), messages
    assert run.stderr.strip() == ""  # no PIL warning line either
    assert peak_kb < 300_000, f"peak RSS {peak_kb / 1024:.0f} MB"
