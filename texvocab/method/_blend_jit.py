"""Compiled inner loop of :meth:`texvocab.method.vocab_texture.VocabTexture.blend`: each
covered texel's colour Σ_p Ω(x, p) Σ_u c_{p,u} U_u[x] in one pass over the parts' texel
lists, without the per-frame gathers and temporaries of the numpy version (numba,
``nogil``; ``cache`` keeps the machine code in ``__pycache__``)."""

from __future__ import annotations

from numba import njit


@njit(cache=True, nogil=True)
def blend_texels(flat, frames, coef, ptr, idx, omega, out):
    """Add each part's blend into ``out`` (N, 3) float32, zeroed by the caller.

    flat (T, N, 3) float32: the training frames' covered texels; frames (U,) and coef
    (P, U): the pose's frames and their blend weight per part; the texels of part p are
    idx[ptr[p]:ptr[p + 1]] with attention omega (same slice).
    """
    for p in range(len(ptr) - 1):
        for u in range(len(frames)):
            w = coef[p, u]
            if w <= 0.0:
                continue
            src = flat[frames[u]]
            for j in range(ptr[p], ptr[p + 1]):
                i = idx[j]
                a = omega[j] * w
                out[i, 0] += a * src[i, 0]
                out[i, 1] += a * src[i, 1]
                out[i, 2] += a * src[i, 2]
