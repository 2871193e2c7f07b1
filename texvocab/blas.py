"""numpy's BLAS thread pool (OpenBLAS in numpy's wheels), kept to the threads a program
budgets for it.

OpenBLAS starts one worker thread per core and, after each call, lets them spin for a
while before they sleep. A program that calls a numpy matrix product every few
milliseconds (the viewer's frame: posed mesh, normals, vocabulary weights) therefore keeps
one core busy with threads that do nothing, on a machine where every core is budgeted:
torch's threads, the render process, Mesa's raster threads. Measured in the viewer while a
slider is dragged (2 cores, llvmpipe): an OpenBLAS thread took 35% of the machine's CPU
samples; with one BLAS thread the window process's CPU per frame fell from 148-154 to
90-99 ms and the frame from 91-95 to 65-70 ms (bench/viewer_ui.py, dragging row).
"""
from __future__ import annotations

from threadpoolctl import threadpool_info, threadpool_limits


def limit_blas_threads(threads: int = 1) -> None:
    """Limit every BLAS library loaded in this process (numpy's, scipy's) to ``threads``
    threads from now on. torch's own pool is separate (``torch.set_num_threads``)."""
    threadpool_limits(limits=max(1, int(threads)), user_api="blas")


def blas_threads() -> int:
    """The largest thread count of the BLAS libraries loaded in this process (0: none)."""
    return max((int(p.get("num_threads", 0)) for p in threadpool_info()
                if p.get("user_api") == "blas"), default=0)
