"""``synth`` never replaces what the user made: a folder that appears at OUT while the
capture renders is kept (the new capture is dropped, one error), with or without
``--overwrite``, unless it is itself a synthesised capture and ``--overwrite`` is given."""

from __future__ import annotations

import numpy as np
import pytest

from texvocab.body import default_body
from texvocab.capture import synth as synth_module
from texvocab.capture.synth import SynthSettings, synthesize
from texvocab.errors import AssetError


def _synth(out, overwrite=False):
    poses, trans = np.zeros((2, 24, 3), np.float32), np.zeros((2, 3), np.float32)
    s = SynthSettings(ring_views=1, raised_views=0, size=32, texture_size=64)
    return synthesize(out, poses, trans, 1, default_body(), s, progress=False, overwrite=overwrite)


@pytest.mark.parametrize("overwrite", [False, True])
def test_a_folder_made_at_out_while_rendering_is_kept(tmp_path, monkeypatch, overwrite):
    out = tmp_path / "cap"
    render = synth_module.SynthRenderer.render

    def render_then_user_writes(self, *args, **kwargs):
        out.mkdir(exist_ok=True)
        (out / "notes.txt").write_text("mine")
        return render(self, *args, **kwargs)

    monkeypatch.setattr(synth_module.SynthRenderer, "render", render_then_user_writes)
    with pytest.raises(AssetError, match="appeared while the capture rendered"):
        _synth(out, overwrite=overwrite)
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt"]
    assert (out / "notes.txt").read_text() == "mine"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cap"]  # no half-made capture beside it


def test_overwrite_replaces_a_synthesised_capture(tmp_path):
    out = tmp_path / "cap"
    _synth(out)
    first = (out / "texvocab_synth.json").stat().st_mtime_ns
    _synth(out, overwrite=True)
    assert (out / "texvocab_synth.json").stat().st_mtime_ns != first


def test_overwrite_refuses_a_symbolic_link_and_keeps_its_target(tmp_path):
    target = tmp_path / "cap"
    _synth(target)
    link = tmp_path / "link"
    link.symlink_to(target)
    before = sorted(p.name for p in target.iterdir())
    with pytest.raises(AssetError, match="is a symbolic link .* give the folder itself"):
        _synth(link, overwrite=True)
    assert link.is_symlink() and sorted(p.name for p in target.iterdir()) == before
