"""Speed/accuracy presets and render-knob overrides on trained checkpoints."""
import pytest

from texvocab.errors import TexvocabError
from texvocab.pipeline.settings import (
    PRESETS,
    RENDER_KNOBS,
    Settings,
    march_settings,
    preset_overrides,
    render_overrides,
)


def _with(name: str) -> Settings:
    return Settings().with_overrides(preset_overrides(name))


def test_presets_are_valid_settings_and_ordered_by_cost():
    fast, balanced, quality = _with("fast"), _with("balanced"), _with("quality")
    # presets change only render knobs: a checkpoint trained with any of them is the same
    for p in (fast, balanced, quality):
        assert {k for k, v in p.to_dict().items() if v != Settings().to_dict()[k]} <= set(RENDER_KNOBS)
    # every knob moves monotonically from fast to quality
    for knob in ("image_scale", "coarse_samples", "fine_samples"):
        assert getattr(fast, knob) <= getattr(balanced, knob) <= getattr(quality, knob), knob
    assert fast.early_stop_eps >= balanced.early_stop_eps >= quality.early_stop_eps
    assert len({repr(p) for p in (fast, balanced, quality)}) == 3  # pairwise distinct


def test_unknown_preset_names_the_choices():
    with pytest.raises(TexvocabError, match="expected one of fast, balanced, quality"):
        preset_overrides("ultra")


def test_render_overrides_touch_only_render_knobs():
    trained = Settings(num_keys=7, k=2)
    s = render_overrides(trained, "fast", ["coarse_samples=10"])
    assert s.coarse_samples == 10  # --set wins over the preset
    assert (s.fine_samples, s.shell_width) == (PRESETS["fast"]["fine_samples"],
                                               PRESETS["fast"]["shell_width"])
    assert (s.num_keys, s.k) == (7, 2)
    with pytest.raises(TexvocabError, match="only render knobs"):
        render_overrides(trained, None, ["num_keys=3"])
    assert set(RENDER_KNOBS) <= set(Settings().to_dict())


def test_marcher_shell_width_is_a_render_knob_but_training_keeps_the_fields():
    s = Settings().with_overrides(["shell_width=0.025"])
    assert march_settings(s).shell_width == 0.025
    assert march_settings(s, training=True).shell_width == s.field.shell_width
    assert march_settings(Settings()).shell_width == Settings().field.shell_width


@pytest.mark.parametrize("item, message", [
    ("field.beta_min=0", "field.beta_min=0.0: expected >= 1e-8"),
    ("image_scale=0", "image_scale=0.0: expected in (0, 4]"),
    ("k=0", "k=0: expected >= 1"),
    ("strategy=parts", "strategy='parts': expected part, joint, global or none"),
    ("early_stop_eps=1", "early_stop_eps=1.0: expected in [0, 1)"),
])
def test_out_of_range_settings_name_the_setting_and_the_range(item, message):
    with pytest.raises(TexvocabError, match=message.replace("(", r"\(").replace(")", r"\)")
                       .replace("[", r"\[")):
        Settings().with_overrides([item])


def test_quality_takes_the_guided_marchers_exact_paths_and_the_knobs_reach_the_marcher():
    """The presets' sample knobs act only on marched rays; with the guided marcher
    `quality` also marches its hard rays and takes the 4-sample band (README,
    session 11), and `--set` reaches both on a trained checkpoint."""
    assert (march_settings(_with("quality")).residual_rays,
            march_settings(_with("quality")).band_newton) == (False, False)
    for name in ("fast", "balanced"):
        m = march_settings(_with(name))
        assert m.residual_rays and m.band_newton
    s = render_overrides(Settings(), "fast", ["residual_rays=false", "band_newton=0"])
    assert (march_settings(s).residual_rays, march_settings(s).band_newton) == (False, False)
    old = Settings().to_dict()  # a checkpoint from before the knobs: today's defaults
    del old["residual_rays"], old["band_newton"]
    assert Settings.from_dict(old).residual_rays and Settings.from_dict(old).band_newton
    with pytest.raises(TexvocabError, match="residual_rays=maybe"):
        Settings().with_overrides(["residual_rays=maybe"])
