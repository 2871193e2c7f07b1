"""The number formats the avatar field's MLPs can be evaluated in at render time."""

from __future__ import annotations

import functools

import torch

__all__ = ["PRECISIONS", "native_bfloat16", "resolve_precision"]

#: the number formats the field's MLPs can be evaluated in at render time (name -> dtype;
#: "auto": bfloat16 where the CPU multiplies it natively, else float32)
PRECISIONS = {"float32": torch.float32, "bfloat16": torch.bfloat16, "auto": None}


@functools.cache
def native_bfloat16() -> bool:
    """Whether this CPU multiplies bfloat16 natively (AMX or AVX512-BF16, from Linux's
    /proc/cpuinfo, read once; False where it cannot be read): elsewhere bf16 products are
    emulated and slower than float32."""
    try:
        with open("/proc/cpuinfo") as f:
            flags = set(f.read().split())
    except OSError:
        return False
    return bool(flags & {"amx_bf16", "avx512_bf16"})


def resolve_precision(name: str) -> torch.dtype:
    """The dtype of a :data:`PRECISIONS` name; ValueError naming the choices otherwise."""
    if name not in PRECISIONS:
        raise ValueError(f"precision {name!r}: expected one of {', '.join(PRECISIONS)}")
    dtype = PRECISIONS[name]
    if dtype is None:
        return torch.bfloat16 if native_bfloat16() else torch.float32
    return dtype
