"""bench/mask_registration.py: a mask shifted and drawn fatter than the person in the image
is read as that shift and that growth, and the bench runs on a HumanNeRF-layout capture."""

import sys
from pathlib import Path

import numpy as np
import pytest
from humannerf_cases import make_truth, write_standin

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench"))

import mask_registration  # noqa: E402


def test_a_shifted_fat_mask_is_read_as_its_shift_and_growth():
    size, k = 160, 8
    ys, xs = (np.mgrid[: size * k, : size * k] + 0.5) / k - 0.5
    person = ((((xs - 80) / 30) ** 2 + ((ys - 80) / 45) ** 2) < 1).reshape(size, k, size, k).mean((1, 3))
    yi, xi = np.mgrid[:size, :size]
    mask = (((xi - 80.5) / 31.5) ** 2 + ((yi - 79.25) / 46.5) ** 2) < 1  # 1.5 px fatter, moved (+0.5, -0.75)
    sides = mask_registration.side_offsets(person, mask)
    assert (sides["right"] - sides["left"]) / 2 == pytest.approx(-0.5, abs=0.15)
    assert (sides["bottom"] - sides["top"]) / 2 == pytest.approx(0.75, abs=0.15)
    for grow in ((sides["right"] + sides["left"]) / 2, (sides["bottom"] + sides["top"]) / 2):
        assert grow == pytest.approx(-1.5, abs=0.3)


def test_the_bench_runs_on_a_humannerf_capture(tmp_path, capsys):
    from texvocab.body import default_body

    body = default_body()
    root = write_standin(tmp_path / "subject", body, make_truth(body))
    for extra in ([], ["--body"]):
        assert mask_registration.main([str(root), "--frames", "2", *extra]) == 0
        last = capsys.readouterr().out.strip().splitlines()[-1]
        assert last.startswith("summary: shift_x=") and last.endswith("frames=2")
    readings = dict(kv.split("=") for kv in last.split()[1:])
    # the stand-in's masks are this body's own silhouettes: no shift, no growth
    assert all(abs(float(readings[k])) < 0.1 for k in ("shift_x", "shift_y", "grow_x", "grow_y"))
