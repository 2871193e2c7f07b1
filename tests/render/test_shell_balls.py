"""The shell's bounding balls: the compiled build (texvocab.render.shell.balls) against
binning the surface samples in numpy, and the balls-only shell the guided marcher uses."""

import numpy as np
import pytest
import torch

from texvocab.render import ShellGeometry
from texvocab.render.shell import balls
from texvocab.render.shell.balls import bounding_balls, surface_balls, surface_samples


def reference(v, f, spacing, width):
    samples, r0 = surface_samples(v, f, spacing)
    return (*bounding_balls(samples, r0, width), r0)


@pytest.mark.parametrize("spacing,width", [(0.0075, 0.025), (0.005, 0.04), (0.02, 0.01)])
def test_compiled_balls_are_the_binned_samples_balls(body, spacing, width):
    v, f = body["v"].double().numpy(), body["f"].numpy()
    got, want = surface_balls(v, f, spacing, width), reference(v, f, spacing, width)
    assert got[0].shape == want[0].shape
    assert np.allclose(got[0], want[0], rtol=0, atol=1e-12)
    assert np.allclose(got[1], want[1], rtol=0, atol=1e-12) and got[2] == want[2]


def test_compiled_balls_on_a_random_mesh_with_large_and_degenerate_faces():
    rng = np.random.default_rng(0)
    v = rng.normal(size=(40, 3)) * 0.3
    v[5] = v[4]  # a repeated vertex: zero-area faces
    f = rng.integers(0, 40, size=(120, 3))
    f[:10, 1] = 4
    f[:10, 2] = 5
    for spacing, width in ((0.01, 0.05), (0.05, 0.02)):  # n up to the cap of 32 per side
        got, want = surface_balls(v, f, spacing, width), reference(v, f, spacing, width)
        assert np.allclose(got[0], want[0], atol=1e-12) and np.allclose(got[1], want[1], atol=1e-12)


def test_too_many_cells_bins_sparsely(body, monkeypatch):
    v, f = body["v"].double().numpy(), body["f"].numpy()
    monkeypatch.setattr(balls, "_MAX_CELLS", 10)
    got, want = surface_balls(v, f, 0.01, 0.03), reference(v, f, 0.01, 0.03)
    assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])


def test_a_balls_only_shell_bounds_the_image_as_the_full_one(body):
    v, f, cam = body["v"], body["f"], body["camera"]
    full = ShellGeometry.build(v, f, 0.025, 0.015, exact=False)
    balls = ShellGeometry.build(v, f, 0.025, 0.015, exact=False, grid=False)
    assert full.has_grid and not balls.has_grid
    a, b = full.image_bounds(cam), balls.image_bounds(cam)
    assert torch.equal(a.hit, b.hit) and torch.equal(a.near, b.near) and torch.equal(a.far, b.far)
    assert a.hit.any()
    with pytest.raises(ValueError, match="grid"):
        balls.contains(v[:3])
