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
    env = {
        k: v
        for k, v in os.environ.items()
        if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
    }
    out = subprocess.run(
        [sys.executable, "-c", CHILD], env=env, capture_output=True, text=True, check=True
    ).stdout.split()
    before, after = int(out[0]), int(out[1])
    assert before >= 1, "numpy's BLAS library was not found"
    assert after == 1
    if (os.cpu_count() or 1) > 1:  # OpenBLAS's default: a thread per core, so it changed
        assert before > 1


BUDGET = """
import os, sys
import numpy as np
from texvocab.blas import blas_threads, budget_blas_threads
took = budget_blas_threads(1)
print(int(took), os.environ.get("OPENBLAS_NUM_THREADS"), blas_threads())
"""


def _clean_env(**extra) -> dict:
    env = {
        k: v
        for k, v in os.environ.items()
        if k not in ("OPENBLAS_NUM_THREADS", "GOTO_NUM_THREADS", "OMP_NUM_THREADS")
    }
    env.update(extra)
    return env


def test_budget_sets_one_thread_here_and_for_child_processes():
    out = subprocess.run(
        [sys.executable, "-c", BUDGET], env=_clean_env(), capture_output=True, text=True, check=True
    ).stdout.split()
    assert out == ["1", "1", "1"]


def test_a_users_blas_setting_wins():
    out = subprocess.run(
        [sys.executable, "-c", BUDGET],
        env=_clean_env(OPENBLAS_NUM_THREADS="2"),
        capture_output=True,
        text=True,
        check=True,
    ).stdout.split()
    assert out == ["0", "2", "2"]


def test_the_texvocab_command_budgets_blas_before_its_work(monkeypatch, tmp_path, capsys):
    """Every subcommand (here one that fails at once) runs after the budget is set."""
    import texvocab.blas
    from texvocab.cli.main import main

    calls = []
    monkeypatch.setattr(texvocab.blas, "budget_blas_threads", lambda n=1: calls.append(n))
    assert main(["check-assets", str(tmp_path / "missing")]) == 2
    assert calls == [1]
    assert "error:" in capsys.readouterr().err
