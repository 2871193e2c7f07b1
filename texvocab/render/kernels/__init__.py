"""Compiled (numba) inner loops of the shell geometry: the bounding balls' surface sampling
(:mod:`.balls`) and the balls' splat into the image and the bounded distance transform
(:mod:`.splat`). Plain array code; no torch, nothing of the renderer above."""
