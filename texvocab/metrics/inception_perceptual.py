"""An offline perceptual distance: LPIPS's recipe on the early blocks of the InceptionV3
that every install has (``texvocab.io.inception``), for training when LPIPS-VGG's
weights are absent (TexVocab Sec. 3.5 trains with LPIPS-VGG; this is a stand-in, named
for what it is and never reported as LPIPS).

Definition: both images ``(B, 3, H, W)`` in [0, 1] are upsampled ``upsample`` times
(bilinear; a 24-pixel patch becomes 48, enough for the unpadded blocks), passed through
the frozen blocks up to ``conv_2`` (64 channels) and ``conv_4`` (192 channels); each map
is normalised to unit length over channels, and the squared difference is summed over
channels, averaged over space and summed over the two taps — LPIPS with uniform layer
weights instead of learned linear heads (Zhang et al. 2018 call this variant
"baseline"). 0 for equal images; at most 4 (two taps, each at most 2).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from texvocab.io.inception import InceptionTaps

PERCEPTUAL_TAPS = 2  # conv_2 and conv_4: a 24-pixel patch upsampled to 48 reaches both
MIN_PATCH = 14  # smallest side that still yields a conv_4 map at upsample 2


class InceptionPerceptual(nn.Module):
    """``forward(pred, gt) -> (B,)`` perceptual distance (module docstring), differentiable
    with respect to both inputs; the network stays frozen."""

    name = "inception-perceptual"

    def __init__(self, network=None, upsample: float = 2.0):
        super().__init__()
        self.taps = InceptionTaps(network, PERCEPTUAL_TAPS)
        self.upsample = float(upsample)

    def forward(self, pred: torch.Tensor, gt: torch.Tensor) -> torch.Tensor:
        if pred.shape != gt.shape or pred.ndim != 4 or pred.shape[1] != 3:
            raise ValueError(
                f"inception-perceptual expects pred and gt (B, 3, H, W) of equal "
                f"shape, got {tuple(pred.shape)} and {tuple(gt.shape)}"
            )
        if min(pred.shape[-2:]) * self.upsample < MIN_PATCH * 2:
            raise ValueError(
                f"inception-perceptual needs images of at least {MIN_PATCH}² "
                f"pixels at upsample 2, got {tuple(pred.shape[-2:])}"
            )
        b = pred.shape[0]
        x = torch.cat([pred, gt]).float()
        if self.upsample != 1.0:
            x = F.interpolate(x, scale_factor=self.upsample, mode="bilinear", align_corners=False)
        total = x.new_zeros(b)
        for f in self.taps(x):
            f = f / (torch.linalg.vector_norm(f, dim=1, keepdim=True) + 1e-10)
            total = total + ((f[:b] - f[b:]) ** 2).sum(1).mean(dim=(1, 2))
        return total
