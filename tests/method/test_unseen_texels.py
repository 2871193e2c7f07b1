"""Unseen texels (one camera sees a third of the body per frame): the coverage-weighted mean
of the training frames replaces them, seen texels are kept, and ``nearest`` is the maps as
stored."""

import numpy as np
import pytest
import torch

from texvocab.method.unseen_texels import fill_unseen_texels, mean_texture, seen_share


def two_halves():
    """Frame 0 sees the left half red, frame 1 the right half and the middle column blue
    (twice: two views); the bottom-right texel is seen by neither."""
    tex = torch.zeros(2, 3, 4, 4)
    cov = torch.zeros(2, 4, 4)
    tex[0, 0, :, :2] = 1.0
    cov[0, :, :2] = 1
    tex[1, 2, :, 1:] = 1.0
    cov[1, :, 1:] = 2
    cov[:, 3, 3] = 0
    return tex, cov


def test_mean_is_coverage_weighted_and_unseen_everywhere_takes_the_nearest():
    tex, cov = two_halves()
    mean = mean_texture(tex, cov)
    assert torch.allclose(mean[:, 0, 0], torch.tensor([1.0, 0, 0]))  # frame 0 only
    assert torch.allclose(mean[:, 0, 3], torch.tensor([0.0, 0, 1]))  # frame 1 only
    # column 1: red once, blue twice
    assert torch.allclose(mean[:, 0, 1], torch.tensor([1 / 3, 0, 2 / 3]))
    assert torch.allclose(mean[:, 3, 3], mean[:, 2, 3])  # seen by no frame: its neighbour


def test_fill_keeps_seen_texels_and_nearest_is_the_stored_maps():
    tex, cov = two_halves()
    filled = fill_unseen_texels(tex, cov, "mean")
    seen = (cov > 0)[:, None].expand_as(tex)
    assert torch.equal(filled[seen], tex[seen])
    mean = mean_texture(tex, cov)
    assert torch.allclose(filled[0, :, :, 3], mean[:, :, 3])  # frame 0 never saw column 3
    assert fill_unseen_texels(tex, cov, "nearest") is tex
    with pytest.raises(ValueError, match="unseen_texels must be one of"):
        fill_unseen_texels(tex, cov, "zeros")
    assert np.allclose(seen_share(cov), [8 / 15, 11 / 15])
