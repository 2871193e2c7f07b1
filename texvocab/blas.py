"""numpy's BLAS thread pool (OpenBLAS in numpy's wheels), kept to the threads a program
budgets for it.

OpenBLAS starts one worker thread per core and, after each call, lets them spin for a
while before they sleep. A program that calls a numpy matrix product every few
milliseconds (the viewer's frame: posed mesh, normals, vocabulary weights) therefore keeps
one core busy with threads that do nothing, on a machine where every core is budgeted:
torch's threads, the render process, Mesa's raster threads. Measured in the viewer while a
slider is dragged (2 cores, llvmpipe): an OpenBLAS thread took 35% of the machine's CPU
samples; with one BLAS thread the window process's CPU per frame fell from 130-154 to
83-99 ms and the frame from 72-95 to 56-78 ms (bench/viewer_ui.py, dragging row). In
training (torch on 2 threads) a step took 13-23% less time (bench/train_speed.py).
"""

from __future__ import annotations

import os

from threadpoolctl import threadpool_info, threadpool_limits

#: the variables OpenBLAS reads for its thread count, in its order of precedence
_USER_SETTINGS = ("OPENBLAS_NUM_THREADS", "GOTO_NUM_THREADS", "OMP_NUM_THREADS")


def limit_blas_threads(threads: int = 1) -> None:
    """Limit every BLAS library loaded in this process (numpy's, scipy's) to ``threads``
    threads from now on. torch's own pool is separate (``torch.set_num_threads``)."""
    threadpool_limits(limits=max(1, int(threads)), user_api="blas")


def budget_blas_threads(threads: int = 1) -> bool:
    """What texvocab's commands, the viewer and the benchmarks do first: unless the user
    set a BLAS thread count (``OPENBLAS_NUM_THREADS`` and the like), keep BLAS to
    ``threads`` in this process and, through ``OPENBLAS_NUM_THREADS``, in the processes
    it starts. Returns False (and changes nothing) when the user's setting stands."""
    if any(name in os.environ for name in _USER_SETTINGS):
        return False
    os.environ["OPENBLAS_NUM_THREADS"] = str(max(1, int(threads)))
    limit_blas_threads(threads)
    return True


def blas_threads() -> int:
    """The largest thread count of the BLAS libraries loaded in this process (0: none)."""
    return max(
        (int(p.get("num_threads", 0)) for p in threadpool_info() if p.get("user_api") == "blas"), default=0
    )
