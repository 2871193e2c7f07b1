"""Fuzzed capture folders (hypothesis): a copy of the world's capture with files deleted,
cut short, replaced by noise or by a bomb header, folders emptied or removed. ``check-assets``
answers with report lines (exit 0 or 1, never a traceback) and names every damaged image
file it was given; opening the capture either works or is one TexvocabError."""

import shutil

from bad_files import garbage, png_declaring, truncated
from disk_snapshot import snapshot
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from texvocab.capture import open as open_capture
from texvocab.cli.main import main
from texvocab.errors import TexvocabError

FUZZ = settings(
    max_examples=30,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
DAMAGE = ("delete", "truncate", "garbage", "bomb", "empty-folder", "remove-folder")
FILES = [f"{d}Camera_B{v}/{t:06d}.png" for d in ("", "mask/") for v in range(1, 7) for t in range(5)]
FILES += ["annots.npy", "params/0.npy", "params/3.npy", "texvocab_synth.json"]


def _damage(root, what: str, rel: str) -> None:
    path = root / rel
    if not path.parent.is_dir():
        return  # an earlier damage removed its folder
    if what == "delete":
        path.unlink(missing_ok=True)
    elif what == "truncate" and path.is_file():
        path.write_bytes(truncated(path.read_bytes(), 0.4))
    elif what == "garbage":
        path.write_bytes(garbage(300))
    elif what == "bomb":
        path.write_bytes(png_declaring(70_000, 70_000))
    elif what in ("empty-folder", "remove-folder") and path.parent != root:
        shutil.rmtree(path.parent)
        if what == "empty-folder":
            path.parent.mkdir()


@FUZZ
@given(st.lists(st.tuples(st.sampled_from(DAMAGE), st.sampled_from(FILES)), min_size=1, max_size=4))
def test_damaged_capture_folders(world, tmp_path_factory, capsys, damage):
    root = tmp_path_factory.mktemp("folder") / "cap"
    shutil.copytree(world / "cap", root, ignore=shutil.ignore_patterns("texvocab_cache"))
    for what, rel in damage:
        _damage(root, what, rel)
    before = snapshot(world)
    code = main(["check-assets", str(root)])
    out = capsys.readouterr().out.strip().splitlines()
    assert code in (0, 1) and out
    assert all(ln[:4] in ("OK  ", "FAIL", "note") for ln in out), out
    damaged_images = {
        rel
        for what, rel in damage
        if what in ("truncate", "garbage", "bomb") and rel.endswith(".png") and (root / rel).is_file()
    }
    if code == 0:
        assert not damaged_images, out  # a damaged image or mask never passes
    try:
        open_capture(root).check_image_sizes()
    except TexvocabError:
        pass
    assert snapshot(world) == before
