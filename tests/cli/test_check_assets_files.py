"""``check-assets CAPTURE`` decodes every image and mask once and reports every bad file in
one pass: each by name and what is wrong, empty masks as one line naming their frames, full
masks as a note; a capture with no bad file passes."""

import shutil

from bad_files import garbage, gif_bytes, png_declaring, truncated
from PIL import Image

from texvocab.cli.main import main


def _copy(world, name):
    dst = world / "bad" / name
    shutil.copytree(world / "cap", dst, ignore=shutil.ignore_patterns("texvocab_cache"))
    return dst


def test_every_bad_file_is_reported_in_one_pass(world, capsys):
    root = _copy(world, "many_bad")
    damaged = {
        root / "Camera_B1" / "000000.png": garbage(),  # the file the reader takes the size from
        root / "Camera_B2" / "000003.png": png_declaring(100_000, 100_000),
        root / "Camera_B4" / "000001.png": gif_bytes((64, 64)),
        root / "mask" / "Camera_B5" / "000002.png": None,  # cut short below
    }
    for path, data in damaged.items():
        path.write_bytes(truncated(path.read_bytes()) if data is None else data)
    for t in (1, 4):
        path = root / "mask" / "Camera_B6" / f"{t:06d}.png"
        with Image.open(path) as im:
            Image.new(im.mode, im.size, 0).save(path)
    assert main(["check-assets", str(root)]) == 1
    out = capsys.readouterr().out.strip().splitlines()
    fails = [ln for ln in out if ln.startswith("FAIL ")]
    for path in damaged:
        assert sum(str(path) in ln for ln in fails) == 1, (path, out)
    assert any("truncated or damaged" in ln and "Camera_B5" in ln for ln in fails)
    assert any("over the limit of 40 Mpx" in ln for ln in fails)
    empty = [ln for ln in fails if "empty mask" in ln]
    assert len(empty) == 1 and "2 of 30 masks are empty: frames 1 (view 5), 4 (view 5)" in empty[0]
    assert len(fails) == 5 and not any(ln.startswith("OK") for ln in out)


def test_full_masks_are_a_note_and_the_capture_still_passes(world, capsys):
    root = _copy(world, "one_full")
    path = root / "mask" / "Camera_B1" / "000002.png"
    with Image.open(path) as im:
        Image.new(im.mode, im.size, 255).save(path)
    assert main(["check-assets", str(root)]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    assert any(
        ln.startswith("note ") and "1 of 30 masks are full" in ln and "frames 2 (view 0)" in ln for ln in out
    )
    assert out[-1].startswith("OK ")


def test_masks_reaching_beyond_the_shell_get_a_note_of_the_shell_training_will_take(world, capsys):
    """Masks dilated by 2 px (64² images, about 3 cm a pixel: a stand-in for clothing off
    the body) reach beyond the default 4 cm shell; the untouched capture does not."""
    import numpy as np
    from scipy import ndimage

    assert main(["check-assets", str(world / "cap")]) == 0
    assert "field shell" not in capsys.readouterr().out
    root = _copy(world, "grown_masks")
    for path in sorted((root / "mask").rglob("*.png")):
        with Image.open(path) as im:
            m = np.asarray(im.convert("L")) > 127
        Image.fromarray((ndimage.binary_dilation(m, iterations=2) * 255).astype(np.uint8)).save(path)
    assert main(["check-assets", str(root)]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    notes = [ln for ln in out if ln.startswith("note ") and "field shell: " in ln]
    assert len(notes) == 1 and "4 cm reaches 0." in notes[0] and out[-1].startswith("OK ")
    width = int(notes[0].split("field shell: ")[1].split(" cm")[0])
    assert 4 < width <= 12
