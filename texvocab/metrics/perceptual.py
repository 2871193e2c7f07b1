"""LPIPS (Zhang et al. 2018, "The unreasonable effectiveness..."), VGG variant v0.1,
as a metric and as a frozen perceptual loss (TexVocab Sec. 3.5 uses VGG LPIPS).

Definition (identical to the ``lpips`` package's ``LPIPS(net='vgg', version='0.1')``
with ``normalize=True``): images in [0, 1] are mapped to [-1, 1], then through the
ScalingLayer ``(x - shift) / scale`` with shift (-0.030, -0.088, -0.188) and scale
(0.458, 0.448, 0.450); VGG16 features are taken after relu1_2, relu2_2, relu3_3,
relu4_3, relu5_3 (64, 128, 256, 512, 512 channels), each normalised to unit length
over channels (``f / (||f|| + 1e-10)``); the squared difference is weighted by a 1x1
convolution ``lin0..lin4`` (one output, no bias), averaged over space, and summed over
the five layers.

Weights, never downloaded:

- VGG16 backbone: a torchvision ``vgg16`` ImageNet state dict, keys ``features.0.weight``
  ... ``features.28.bias`` (``classifier.*`` keys are ignored), found as
  ``torch.hub.get_dir()/checkpoints/vgg16-397923af.pth`` (or another ``vgg16-*.pth``;
  honours ``$TORCH_HOME``) or passed as ``vgg_weights=PATH``.
- Linear heads: the file the ``lpips`` PyPI package bundles, ``lpips/weights/v0.1/vgg.pth``,
  keys ``lin{k}.model.1.weight`` of shape ``(1, C_k, 1, 1)``; located with
  ``importlib.util.find_spec`` without importing ``lpips`` (which imports torchvision),
  or passed as ``heads=PATH``. ``pip install --no-deps lpips==0.1.4`` provides it.

Both are read with ``torch.load(weights_only=True)`` and checked key by key. When the
search finds no file, :func:`lpips` returns ``None`` and logs one line naming what is
missing and where it looked; an explicit path that does not exist, or a file with the
wrong keys/shapes, raises :class:`~texvocab.errors.AssetError`.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np
import torch
from torch import nn

from texvocab.errors import AssetError
from texvocab.io.weights import load_state_dict, log_once, package_dir, torch_checkpoint_dir

VGG16_CFG = (64, 64, "M", 128, 128, "M", 256, 256, 256, "M", 512, 512, 512, "M", 512, 512, 512, "M")
LPIPS_TAPS = (3, 8, 15, 22, 29)  # indices in vgg16.features of relu1_2 ... relu5_3
LPIPS_CHANNELS = (64, 128, 256, 512, 512)
LPIPS_SHIFT = (-0.030, -0.088, -0.188)
LPIPS_SCALE = (0.458, 0.448, 0.450)
KNOWN_VGG16_FILES = ("vgg16-397923af.pth",)  # torchvision's IMAGENET1K_V1 (preferred)
LPIPS_HEADS_IN_PACKAGE = Path("weights") / "v0.1" / "vgg.pth"

ArrayLike = np.ndarray | torch.Tensor


class VGG16Features(nn.Module):
    """torchvision's ``vgg16().features`` (31 modules; conv layers at indices 0, 2, 5,
    ... 28), so ``state_dict`` keys are ``features.{i}.weight`` / ``.bias`` as there."""

    def __init__(self):
        super().__init__()
        layers: list[nn.Module] = []
        cin = 3
        for v in VGG16_CFG:
            if v == "M":
                layers.append(nn.MaxPool2d(2, 2))
            else:
                layers += [nn.Conv2d(cin, v, 3, padding=1), nn.ReLU(inplace=True)]
                cin = v
        self.features = nn.Sequential(*layers)

    def taps(self, x: torch.Tensor) -> list[torch.Tensor]:
        """relu1_2 ``(B, 64, H, W)``, relu2_2 ``(B, 128, H/2, W/2)``, relu3_3 ``(B, 256,
        H/4, W/4)``, relu4_3 ``(B, 512, H/8, W/8)``, relu5_3 ``(B, 512, H/16, W/16)``."""
        out = []
        for i, layer in enumerate(self.features[: LPIPS_TAPS[-1] + 1]):
            x = layer(x)
            if i in LPIPS_TAPS:
                out.append(x)
        return out


class LinearHeads(nn.Module):
    """LPIPS's ``lin0..lin4``: per layer a 1x1 conv ``C_k -> 1`` without bias, at
    ``lin{k}.model.1`` as in the ``lpips`` package (index 0 there is a Dropout, which
    is the identity in eval mode)."""

    def __init__(self):
        super().__init__()
        for k, c in enumerate(LPIPS_CHANNELS):
            setattr(self, f"lin{k}", nn.Module())
            getattr(self, f"lin{k}").model = nn.Sequential(nn.Identity(), nn.Conv2d(c, 1, 1, bias=False))

    def forward(self, k: int, x: torch.Tensor) -> torch.Tensor:
        return getattr(self, f"lin{k}").model(x)


@lru_cache(maxsize=1)
def _vgg16_layout() -> dict[str, torch.Size]:
    return {f"features.{k}": v.shape for k, v in VGG16Features().features.state_dict().items()}


@lru_cache(maxsize=1)
def _heads_layout() -> dict[str, torch.Size]:
    return {k: v.shape for k, v in LinearHeads().state_dict().items()}


def find_vgg16_weights() -> Path | None:
    """The VGG16 checkpoint in the torch cache, torchvision's own name first."""
    found = [p for p in sorted(torch_checkpoint_dir().glob("vgg16-*.pth")) if p.is_file()]
    rank = {n: i for i, n in enumerate(KNOWN_VGG16_FILES)}
    found.sort(key=lambda p: rank.get(p.name, len(rank)))
    return found[0] if found else None


def find_lpips_heads() -> Path | None:
    """``lpips/weights/v0.1/vgg.pth`` of the installed ``lpips`` package, if any."""
    pkg = package_dir("lpips")
    path = pkg / LPIPS_HEADS_IN_PACKAGE if pkg is not None else None
    return path if path is not None and path.is_file() else None


def load_vgg16_state_dict(path: str | Path) -> dict[str, torch.Tensor]:
    """``features.*`` of a torchvision VGG16 state dict (weights-only load), checked
    against :class:`VGG16Features`; ``classifier.*`` is ignored. AssetError otherwise."""
    return load_state_dict(Path(path), "torchvision VGG16", _vgg16_layout(), ("classifier.",))


def load_lpips_heads_state_dict(path: str | Path) -> dict[str, torch.Tensor]:
    """``lin0..lin4`` of an lpips v0.1 VGG heads file (weights-only load), checked."""
    return load_state_dict(Path(path), "LPIPS VGG linear heads", _heads_layout())


def _missing_message() -> str | None:
    """One line naming what the default search could not find, or ``None``."""
    missing = []
    if find_vgg16_weights() is None:
        missing.append(
            f"no VGG16 ImageNet weights (vgg16-*.pth, e.g. {KNOWN_VGG16_FILES[0]}) "
            f"in {torch_checkpoint_dir()}"
        )
    if find_lpips_heads() is None:
        pkg = package_dir("lpips")
        where = (
            f"{pkg / LPIPS_HEADS_IN_PACKAGE} does not exist"
            if pkg is not None
            else "Python package 'lpips' is not installed (pip install --no-deps lpips==0.1.4)"
        )
        missing.append(f"no LPIPS VGG heads: {where}")
    if not missing:
        return None
    return "LPIPS unavailable, reported as None: " + "; ".join(missing)


class LPIPS(nn.Module):
    """Frozen LPIPS-VGG network: ``forward(pred, gt) -> (B,)`` for images ``(B, 3, H, W)``
    in [0, 1] (H, W >= 16). Differentiable with respect to both inputs (use it as the
    perceptual loss ``L_perceptual``); its own weights never train and it stays in eval
    mode. ``vgg_weights``/``heads`` default to the search described in the module
    docstring; raises AssetError when a file is missing or malformed."""

    def __init__(self, vgg_weights: str | Path | None = None, heads: str | Path | None = None):
        super().__init__()
        vgg_path = Path(vgg_weights) if vgg_weights is not None else find_vgg16_weights()
        heads_path = Path(heads) if heads is not None else find_lpips_heads()
        if vgg_path is None or heads_path is None:
            raise AssetError(_missing_message() or "LPIPS weights not found")
        self.vgg_path, self.heads_path = vgg_path, heads_path
        self.net = VGG16Features()
        self.net.features.load_state_dict(
            {k.removeprefix("features."): v for k, v in load_vgg16_state_dict(vgg_path).items()}, strict=True
        )
        self.lins = LinearHeads()
        self.lins.load_state_dict(load_lpips_heads_state_dict(heads_path), strict=True)
        self.register_buffer("shift", torch.tensor(LPIPS_SHIFT).view(1, 3, 1, 1), False)
        self.register_buffer("scale", torch.tensor(LPIPS_SCALE).view(1, 3, 1, 1), False)
        self.requires_grad_(False)
        self.eval()

    def train(self, mode: bool = True) -> LPIPS:
        return super().train(False)

    def forward(self, pred: torch.Tensor, gt: torch.Tensor) -> torch.Tensor:
        """LPIPS distance ``(B,)`` between ``pred`` and ``gt`` ``(B, 3, H, W)`` in [0, 1]."""
        if pred.shape != gt.shape or pred.ndim != 4 or pred.shape[1] != 3:
            raise ValueError(
                f"LPIPS expects pred and gt (B, 3, H, W) of equal shape, got "
                f"{tuple(pred.shape)} and {tuple(gt.shape)}"
            )
        b = pred.shape[0]
        x = torch.cat([pred, gt]).to(self.shift.dtype)
        feats = self.net.taps(((2 * x - 1) - self.shift) / self.scale)
        total = x.new_zeros(b)
        for k, f in enumerate(feats):
            f = f / (torch.linalg.vector_norm(f, dim=1, keepdim=True) + 1e-10)
            total = total + self.lins(k, (f[:b] - f[b:]) ** 2).mean(dim=(1, 2, 3))
        return total


def _to_batch(image: ArrayLike) -> torch.Tensor:
    """``(H, W, 3)`` numpy/torch image -> float32 ``(1, 3, H, W)`` tensor."""
    t = image.detach() if isinstance(image, torch.Tensor) else torch.from_numpy(np.asarray(image))
    if t.ndim != 3 or t.shape[-1] != 3:
        raise ValueError(f"lpips expects images (H, W, 3), got {tuple(t.shape)}")
    return t.to(torch.float32).permute(2, 0, 1)[None]


def lpips_with(model: LPIPS, pred: ArrayLike, gt: ArrayLike) -> float:
    """LPIPS of images ``(H, W, 3)`` in [0, 1] under a loaded :class:`LPIPS`."""
    p, g = _to_batch(pred), _to_batch(gt)
    if p.shape != g.shape:
        raise ValueError(f"pred and gt must have the same shape, got {tuple(p.shape)} and {tuple(g.shape)}")
    with torch.no_grad():
        return float(model(p.to(model.shift.device), g.to(model.shift.device))[0])


@lru_cache(maxsize=2)
def _cached_model(vgg_path: Path, heads_path: Path) -> LPIPS:
    return LPIPS(vgg_path, heads_path)


def lpips_available(vgg_weights: str | Path | None = None, heads: str | Path | None = None) -> bool:
    """Whether both files are found (explicit paths must exist); does not load them."""
    vgg = Path(vgg_weights) if vgg_weights is not None else find_vgg16_weights()
    lin = Path(heads) if heads is not None else find_lpips_heads()
    return vgg is not None and lin is not None and vgg.is_file() and lin.is_file()


def lpips(
    pred: ArrayLike, gt: ArrayLike, vgg_weights: str | Path | None = None, heads: str | Path | None = None
) -> float | None:
    """LPIPS (VGG, v0.1) between images ``(H, W, 3)`` in [0, 1] (numpy or torch), or
    ``None`` when the default search finds no weights (one log line per process). The
    network is built once per pair of files and reused."""
    vgg = Path(vgg_weights) if vgg_weights is not None else find_vgg16_weights()
    lin = Path(heads) if heads is not None else find_lpips_heads()
    if vgg is None or lin is None:
        log_once(_missing_message() or "LPIPS unavailable, reported as None")
        return None
    return lpips_with(_cached_model(vgg.resolve(), lin.resolve()), pred, gt)
