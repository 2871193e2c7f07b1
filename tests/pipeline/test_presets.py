"""Speed/accuracy presets and render-knob overrides on trained checkpoints."""

from dataclasses import fields

import pytest
from train_cases import flat_dict

from texvocab.errors import TexvocabError
from texvocab.pipeline.settings import (
    PRESETS,
    RENDER_KNOBS,
    RenderSettings,
    Settings,
    VocabSettings,
    march_settings,
    preset_overrides,
    render_overrides,
)


def _with(name: str) -> Settings:
    return Settings().with_overrides(preset_overrides(name))


def test_presets_are_valid_settings_and_ordered_by_cost():
    fast, balanced, quality = _with("fast"), _with("balanced"), _with("quality")
    # presets change only render knobs: a checkpoint trained with any of them is the same
    default = Settings().dotted()
    for p in (fast, balanced, quality):
        changed = {k for k, v in p.dotted().items() if v != default[k]}
        assert changed and changed <= {f"render.{k}" for k in RENDER_KNOBS}
    # every knob moves monotonically from fast to quality
    for knob in ("image_scale", "coarse_samples", "fine_samples"):
        assert (
            getattr(fast.render, knob) <= getattr(balanced.render, knob) <= getattr(quality.render, knob)
        ), knob
    assert fast.render.early_stop_eps >= balanced.render.early_stop_eps >= quality.render.early_stop_eps
    assert len({repr(p) for p in (fast, balanced, quality)}) == 3  # pairwise distinct


def test_unknown_preset_names_the_choices():
    with pytest.raises(TexvocabError, match="expected one of fast, balanced, quality"):
        preset_overrides("ultra")


@pytest.mark.parametrize("knob", ["coarse_samples", "render.coarse_samples"])
def test_render_overrides_touch_only_render_knobs(knob):
    trained = Settings(vocab=VocabSettings(num_keys=7, k=2))
    s = render_overrides(trained, "fast", [f"{knob}=10"])
    assert s.render.coarse_samples == 10  # --set wins over the preset
    assert (s.render.fine_samples, s.render.precision) == (
        PRESETS["fast"]["fine_samples"],
        PRESETS["fast"]["precision"],
    )
    assert (s.vocab.num_keys, s.vocab.k) == (7, 2)
    assert s.train == trained.train  # train.coarse_samples is training's own
    for item in ("num_keys=3", "vocab.num_keys=3", "train.coarse_samples=3"):
        with pytest.raises(TexvocabError, match="only render knobs"):
            render_overrides(trained, None, [item])
    assert RENDER_KNOBS == tuple(f.name for f in fields(RenderSettings))
    in_presets = {k for p in PRESETS.values() for k in p}
    # knobs no preset sets: the resolution, the path and the shell (presets keep all of it),
    # and the residual rays' mesh step
    assert set(RENDER_KNOBS) == in_presets | {
        "image_scale",
        "guide",
        "shell_width",
        "shell_scale",
        "miss_reach",
        "residual_step",
    }


def test_marcher_shell_width_is_a_render_knob_but_training_keeps_the_fields():
    s = Settings().with_overrides(["shell_width=0.025"])
    assert s.render.shell_width == 0.025 and s.field.shell_width == 0.04
    assert march_settings(s).shell_width == 0.025
    assert march_settings(s, training=True).shell_width == s.field.shell_width
    assert march_settings(Settings()).shell_width == Settings().field.shell_width


@pytest.mark.parametrize(
    "item, message",
    [
        ("field.beta_min=0", "setting field.beta_min=0.0: expected >= 1e-8"),
        ("image_scale=0", "setting render.image_scale=0.0: expected in (0, 4]"),
        ("render.image_scale=5", "setting render.image_scale=5.0: expected in (0, 4]"),
        ("k=0", "setting vocab.k=0: expected >= 1"),
        ("strategy=parts", "setting vocab.strategy='parts': expected part, joint, global or none"),
        ("early_stop_eps=1", "setting render.early_stop_eps=1.0: expected in [0, 1)"),
        ("train.coarse_samples=0", "setting train.coarse_samples=0: expected >= 1 or none"),
        ("render.shell_width=2", "setting render.shell_width=2.0: expected in (0, 1] m or none"),
    ],
)
def test_out_of_range_settings_name_the_setting_and_the_range(item, message):
    with pytest.raises(TexvocabError) as e:
        Settings().with_overrides([item])
    assert str(e.value) == message


def test_quality_takes_the_guided_marchers_exact_paths_and_the_knobs_reach_the_marcher():
    """The presets' sample knobs act only on marched rays; with the guided marcher
    `quality` also marches its hard rays and takes the 4-sample band, and `--set` reaches
    both on a trained checkpoint."""
    assert (march_settings(_with("quality")).residual_rays, march_settings(_with("quality")).band_newton) == (
        False,
        False,
    )
    for name in ("fast", "balanced"):
        m = march_settings(_with(name))
        assert m.residual_rays and m.band_newton
    s = render_overrides(Settings(), "fast", ["residual_rays=false", "render.band_newton=0"])
    assert (march_settings(s).residual_rays, march_settings(s).band_newton) == (False, False)
    old = flat_dict(Settings())  # a checkpoint from before the knobs: today's defaults
    del old["residual_rays"], old["band_newton"]
    assert Settings.from_dict(old).render.residual_rays
    assert Settings.from_dict(old).render.band_newton
    with pytest.raises(TexvocabError, match="residual_rays=maybe"):
        Settings().with_overrides(["residual_rays=maybe"])


def test_presets_keep_the_fields_shell():
    """Every preset marches the field's whole shell (loose clothing stands up to its edge):
    4 cm on the default, 6 cm on an avatar trained with a 6 cm shell; render.shell_scale
    narrows it as a share, and an explicit render.shell_width wins."""
    for name in PRESETS:
        assert march_settings(_with(name)).shell_width == Settings().field.shell_width
        wide = Settings().with_overrides(["field.shell_width=0.06", *preset_overrides(name)])
        assert march_settings(wide).shell_width == 0.06
        assert march_settings(wide.with_overrides(["render.shell_scale=0.5"])).shell_width == pytest.approx(
            0.03
        )
        pinned = wide.with_overrides(["render.shell_width=0.02"])
        assert march_settings(pinned).shell_width == 0.02
