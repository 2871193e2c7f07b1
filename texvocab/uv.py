"""The one place where UV coordinates meet texture-image pixels.

``vt`` is in [0, 1]² with the origin at the bottom-left (OBJ); a texture image's row 0 is
the top (v = 1). Texel centres sit at ``(i + 0.5) / size``.
"""
from __future__ import annotations

import torch


def uv_to_pixel(uv: torch.Tensor, width: int, height: int) -> torch.Tensor:
    """(..., 2) UV -> (..., 2) continuous pixel coordinates (x, y), texel centres integral."""
    x = uv[..., 0] * width - 0.5
    y = (1.0 - uv[..., 1]) * height - 0.5
    return torch.stack([x, y], -1)


def pixel_to_uv(pix: torch.Tensor, width: int, height: int) -> torch.Tensor:
    """Inverse of :func:`uv_to_pixel`."""
    u = (pix[..., 0] + 0.5) / width
    v = 1.0 - (pix[..., 1] + 0.5) / height
    return torch.stack([u, v], -1)


def uv_to_grid(uv: torch.Tensor) -> torch.Tensor:
    """UV -> ``torch.nn.functional.grid_sample`` coordinates in [-1, 1] (align_corners=False)."""
    return torch.stack([uv[..., 0] * 2 - 1, 1 - uv[..., 1] * 2], -1)
