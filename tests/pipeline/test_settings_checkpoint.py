"""Settings (one object for every knob) and checkpoint I/O (atomic, weights-only)."""
import os

import pytest
import torch

from texvocab.errors import AssetError, TexvocabError
from texvocab.io.checkpoint import load_checkpoint, save_checkpoint
from texvocab.pipeline.settings import Settings


def test_settings_round_trip_and_overrides():
    s = Settings().with_overrides(["k=5", "field.hidden=64", "eval_views=0,3",
                                   "max_minutes=2.5", "encoder=small", "train_views=none"])
    assert (s.k, s.field.hidden, s.eval_views, s.max_minutes, s.encoder) == \
        (5, 64, (0, 3), 2.5, "small")
    assert Settings.from_dict(s.to_dict()) == s
    for bad, msg in (["nope=1"], "unknown setting"), (["k=three"], "expected a int"), \
            (["field.nope=1"], "unknown setting"), (["k"], "expected key=value"):
        with pytest.raises(TexvocabError, match=msg):
            Settings().with_overrides(bad)


def test_checkpoint_round_trip_is_atomic(tmp_path):
    path = tmp_path / "run" / "checkpoint.pt"
    save_checkpoint(path, {"step": 3, "settings": Settings().to_dict(),
                           "model": {"w": torch.ones(2)}})
    ck = load_checkpoint(path)
    assert ck["step"] == 3 and torch.equal(ck["model"]["w"], torch.ones(2))
    assert [p.name for p in path.parent.iterdir()] == ["checkpoint.pt"]  # no temp files left

    def explode(tmp):
        open(tmp, "wb").write(b"partial")
        raise OSError("disk full")

    from texvocab.io.images import atomic_write_bytes

    with pytest.raises(OSError):
        atomic_write_bytes(path, explode)
    assert load_checkpoint(path)["step"] == 3  # the old checkpoint survives intact
    assert [p.name for p in path.parent.iterdir()] == ["checkpoint.pt"]


class _Evil:
    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


def test_malicious_checkpoint_is_refused(tmp_path):
    marker = tmp_path / "pwned"
    path = tmp_path / "checkpoint.pt"
    torch.save({"format": "texvocab-checkpoint", "model": _Evil(marker)}, path)
    with pytest.raises(AssetError, match="not a loadable texvocab checkpoint"):
        load_checkpoint(path)
    assert not marker.exists()


def test_foreign_or_newer_checkpoints(tmp_path):
    path = tmp_path / "x.pt"
    torch.save({"state_dict": {}}, path)
    with pytest.raises(AssetError, match="not a texvocab checkpoint"):
        load_checkpoint(path)
    torch.save({"format": "texvocab-checkpoint", "version": 99, "step": 0, "settings": {},
                "model": {}}, path)
    with pytest.raises(AssetError, match="version 99 is newer"):
        load_checkpoint(path)
    with pytest.raises(AssetError, match="checkpoint not found"):
        load_checkpoint(tmp_path / "missing.pt")
