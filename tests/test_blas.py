"""texvocab/blas.py: numpy's BLAS pool is found and limited (in a fresh interpreter, so the
limit does not leak into other tests)."""
from __future__ import annotations

import os
import subprocess
import sys

CHILD = """
import numpy as np
from texvocab.blas import blas_threads, limit_blas_threads
before = blas_threads()
limit_blas_threads(1)
a = np.random.default_rng(0).random((300, 300))
assert np.allclose(a @ np.eye(300), a)  # products still right with one thread
print(before, blas_threads())
"""


def test_limit_blas_threads_limits_numpys_openblas():
    env = {k: v for k, v in os.environ.items()
           if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")}
    out = subprocess.run([sys.executable, "-c", CHILD], env=env, capture_output=True,
                         text=True, check=True).stdout.split()
    before, after = int(out[0]), int(out[1])
    assert before >= 1, "numpy's BLAS library was not found"
    assert after == 1
    if (os.cpu_count() or 1) > 1:  # OpenBLAS's default: a thread per core, so it changed
        assert before > 1
