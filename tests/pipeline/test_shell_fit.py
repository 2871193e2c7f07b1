"""The field's shell from the data (texvocab.pipeline.shell_fit): a capture whose person
stays on the body keeps the given width; one whose masks reach beyond it (here the tiny
capture's masks dilated, a stand-in for clothing off the body) gets the narrowest wider
shell that reaches field.shell_coverage of their pixels, and the run keeps it."""

from __future__ import annotations

import numpy as np
import pytest
from grown_masks import grown
from train_cases import tiny_settings

from texvocab.capture import open as open_capture
from texvocab.pipeline.model import train_views
from texvocab.pipeline.settings import Settings
from texvocab.pipeline.shell_fit import SHELL_MAX, SHELL_STEP, candidate_widths, fit_shell, measure_shell


def test_candidate_widths_step_from_the_given_width_to_the_widest():
    w = candidate_widths(0.04)
    assert w[0] == pytest.approx(0.04) and w[-1] == pytest.approx(SHELL_MAX)
    assert np.allclose(np.diff(w), SHELL_STEP)
    assert len(candidate_widths(SHELL_MAX)) == 1


def test_a_person_on_the_body_keeps_the_given_shell(capture):
    cap = open_capture(capture)
    s = Settings()
    fitted, fit = fit_shell(cap, s, train_views(cap, s))
    assert fitted.field.shell_width == s.field.shell_width == 0.04
    assert fit.coverage[0] >= 0.99 and fit.images == 4  # every training frame of the 4
    assert fitted.render == s.render and fitted.vocab == s.vocab


def test_masks_beyond_the_shell_widen_it_to_the_narrowest_that_reaches_them(capture):
    cap = grown(capture, 2)
    s = Settings()
    widths, cov, _ = measure_shell(cap, train_views(cap, s), 0.04)
    assert cov[0] < 0.97 and np.all(np.diff(cov) >= 0)  # wider reaches at least as much
    fitted, fit = fit_shell(cap, s, train_views(cap, s))
    i = int(np.argmin(np.abs(widths - fitted.field.shell_width)))
    assert fitted.field.shell_width > 0.04 and cov[i] >= 0.97 and cov[i - 1] < 0.97
    assert "field shell: " in fit.line(0.97) and f"{fitted.field.shell_width * 100:.0f} cm" in fit.line(0.97)
    # a lower target is met by a narrower shell; none keeps the width as given
    lower, _ = fit_shell(cap, s.with_overrides([f"field.shell_coverage={cov[0]:.6f}"]), [0, 2])
    assert lower.field.shell_width <= fitted.field.shell_width
    off, none = fit_shell(cap, s.with_overrides(["field.shell_coverage=none"]), [0])
    assert none is None and off.field.shell_width == 0.04


def test_the_run_trains_and_stores_the_fitted_shell(capture, tmp_path):
    from texvocab.io.checkpoint import load_checkpoint
    from texvocab.pipeline.train import Trainer

    cap = grown(capture, 2)
    trainer = Trainer(cap, tiny_settings(iterations=1), tmp_path / "run", progress=False)
    width = trainer.s.field.shell_width
    assert width > 0.04 and trainer.model.settings.shell_width == width
    assert trainer.march.shell_width == width  # training rays reach as far
    trainer.run()
    stored = Settings.from_dict(load_checkpoint(trainer.checkpoint_path)["settings"])
    assert stored.field.shell_width == width and stored.field.shell_coverage == 0.97
    # resuming measures the same width, so the run's settings agree with the checkpoint
    again = Trainer(cap, tiny_settings(iterations=2), tmp_path / "run", progress=False)
    assert again.resume() and again.s.field.shell_width == width


def test_checkpoints_before_the_knob_read_as_a_fixed_shell():
    d = Settings().to_dict()
    del d["field"]["shell_coverage"]
    assert Settings.from_dict(d).field.shell_coverage is None
