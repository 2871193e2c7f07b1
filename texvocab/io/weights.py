"""Finding and checking pretrained files (texture encoder, LPIPS, FID); no downloads.

Checkpoints are read with ``torch.load(weights_only=True)``: a pickle that names any
code is refused before any of it runs. Missing optional files are reported on the
``texvocab`` logger once per process and message.
"""

from __future__ import annotations

import importlib.util
import logging
from collections.abc import Mapping
from pathlib import Path

import torch

from texvocab.errors import AssetError

log = logging.getLogger("texvocab")
_logged: set[str] = set()  # messages already logged in this process


def log_once(message: str) -> None:
    """Log ``message`` as a WARNING on the ``texvocab`` logger unless already logged."""
    if message not in _logged:
        _logged.add(message)
        log.warning(message)


def torch_checkpoint_dir() -> Path:
    """Where torchvision caches weights: ``torch.hub.get_dir()/checkpoints``
    (``$TORCH_HOME/hub/checkpoints``, default ~/.cache/torch/hub/checkpoints)."""
    return Path(torch.hub.get_dir()) / "checkpoints"


def package_dir(name: str) -> Path | None:
    """Directory of installed top-level package ``name``, found without importing it
    (``importlib.util.find_spec`` on a top-level name runs none of its code)."""
    try:
        spec = importlib.util.find_spec(name)
    except (ImportError, ValueError):
        return None
    if spec is None or not spec.submodule_search_locations:
        return None
    return Path(next(iter(spec.submodule_search_locations)))


def load_error_reason(e: Exception) -> str:
    """The informative line of a ``torch.load`` error (torch wraps it in generic advice,
    including re-running with ``weights_only=False``, which we never suggest)."""
    lines = [ln.strip() for ln in str(e).splitlines() if ln.strip()]
    boiler = ("Weights only load failed", "Please file an issue", "Check the documentation")
    useful = [ln for ln in lines if not ln.startswith(boiler)]
    reason = (useful or lines or [""])[0]
    return f"{type(e).__name__}: {reason}" if reason else type(e).__name__


def load_state_dict(
    path: Path,
    what: str,
    expected: Mapping[str, torch.Size],
    ignore_prefixes: tuple[str, ...] = (),
    defaults: Mapping[str, torch.Tensor] | None = None,
    cast_float: bool = True,
) -> dict[str, torch.Tensor]:
    """The state dict in ``path`` restricted to the keys of ``expected`` (key -> shape),
    read with weights-only unpickling. Keys starting with ``ignore_prefixes`` are
    dropped; keys in ``defaults`` may be absent and then take that value; any other
    missing, extra or wrongly shaped key raises :class:`AssetError` naming the file and
    the key. ``what`` names the file's content in messages."""
    if not path.is_file():
        raise AssetError(f"{path}: {what} file not found")
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as e:  # noqa: BLE001 - any unreadable/unsafe file is an asset problem
        raise AssetError(
            f"{path}: not loadable as a torch state dict with weights_only=True ({load_error_reason(e)})"
        ) from None
    if not isinstance(state, Mapping):
        raise AssetError(f"{path}: expected a {what} state dict, got {type(state).__name__}")
    out = {}
    for key, want in expected.items():
        got = state.get(key)
        if got is None and defaults is not None and key in defaults:
            got = defaults[key]
        if got is None:
            raise AssetError(
                f"{path}: key '{key}' missing (expected shape {tuple(want)}); not a {what} state dict"
            )
        if not isinstance(got, torch.Tensor) or got.shape != want:
            shape = tuple(got.shape) if isinstance(got, torch.Tensor) else type(got).__name__
            raise AssetError(f"{path}: key '{key}' expected shape {tuple(want)}, got {shape}")
        out[key] = got.float() if cast_float and got.is_floating_point() else got
    for key in state:
        if key not in expected and not str(key).startswith(ignore_prefixes):
            raise AssetError(f"{path}: unexpected key '{key}', not a {what} state dict")
    return out
