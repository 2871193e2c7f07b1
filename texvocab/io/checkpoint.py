"""Checkpoints: written atomically (temp file + rename), read with ``weights_only=True``
(tensors and plain Python containers only: loading one never runs code).

Layout (see assets_spec/checkpoint.md): {"format": "texvocab-checkpoint", "version": 2,
"step": int, "settings": dict, "capture": str, "num_train": int, "capture_identity": dict
(:mod:`texvocab.capture.identity`; absent before it existed), "model": state_dict,
"optimizer": state_dict, "vocab": {...}, "rng": {"torch": ByteTensor}}. Version 2 stores
the settings as a dict per group; version 1 stored them flat. Both are read
(:meth:`texvocab.pipeline.settings.Settings.from_dict`).
"""

from __future__ import annotations

import os
from pathlib import Path

import torch

from texvocab.errors import AssetError
from texvocab.io.images import atomic_write_bytes
from texvocab.io.weights import load_error_reason

FORMAT = "texvocab-checkpoint"
VERSION = 2  # 2: settings grouped; 1: flat
REQUIRED = ("format", "version", "step", "settings", "model")


def save_checkpoint(path: str | Path, payload: dict) -> Path:
    """Atomically write ``payload`` (plus format/version tags) to ``path``. Through a
    Python file, so a full disk is an OSError (ENOSPC) rather than torch's RuntimeError;
    on any error the temporary file is removed and ``path`` is left as it was."""
    data = {"format": FORMAT, "version": VERSION, **payload}

    def write(tmp: str) -> None:
        with open(tmp, "wb") as fh:
            torch.save(data, fh)
            fh.flush()
            os.fsync(fh.fileno())

    return atomic_write_bytes(path, write)


def load_checkpoint(path: str | Path) -> dict:
    """Read a checkpoint safely; one clear error for anything that is not one."""
    path = Path(path)
    if not path.is_file():
        raise AssetError(f"checkpoint not found: {path}")
    try:
        data = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # unpickling refused / truncated / not a torch file
        raise AssetError(
            f"{path}: not a loadable texvocab checkpoint, refused by the "
            f"weights-only reader ({load_error_reason(exc)})"
        ) from None
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise AssetError(
            f"{path}: not a texvocab checkpoint (no format tag {FORMAT!r}); see assets_spec/checkpoint.md"
        )
    missing = [k for k in REQUIRED if k not in data]
    if missing:
        raise AssetError(f"{path}: checkpoint lacks {missing}; see assets_spec/checkpoint.md")
    if data["version"] > VERSION:
        raise AssetError(
            f"{path}: checkpoint version {data['version']} is newer than this "
            f"texvocab understands ({VERSION})"
        )
    return data
