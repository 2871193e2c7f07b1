"""Render work too small for torch's second thread runs on one.

texvocab lets OpenMP's threads wait passively between operations (texvocab/__init__.py:
spinning threads would take a core from the UI and from whatever else runs), so every
parallel operation wakes them, tens of microseconds each. A render is thousands of small
operations. Measured on 2 cores (a 10-minute default-capture avatar, the guided marcher
at the ``fast`` knobs, best of 4 × 3 frames): a 256² frame took 0.112 s with torch on
one thread and 0.125 s on two, a 320² frame 0.173 and 0.171, 384² 0.246 and 0.220,
512² 0.397 and 0.336 s. A field call alone, on 16 points, 1.1 ms on one thread and
2.5 ms on two; on 2,048 points 6.2 and 9.0 ms; on 8,000 points 22.3 and 19.6 ms. Two
Python threads splitting one frame's rays were slower still (0.134 s): the render holds
the GIL between its operations. The projection onto the body and the other compiled
kernels keep their own threads either way."""

from __future__ import annotations

from contextlib import contextmanager

import torch


@contextmanager
def one_torch_thread(when: bool = True):
    """torch's intra-op threads set to 1 inside the block when ``when`` (and restored
    after); nothing changes otherwise or when torch already runs on one thread."""
    threads = torch.get_num_threads()
    if not when or threads == 1:
        yield
        return
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(threads)
