"""Settings (one object for every knob) and checkpoint I/O (atomic, weights-only)."""

import os
from dataclasses import fields
from typing import get_args

import pytest
import torch
from train_cases import flat_dict, flat_settings

from texvocab.body.parts import STRATEGIES
from texvocab.errors import AssetError, TexvocabError
from texvocab.io.checkpoint import load_checkpoint, save_checkpoint
from texvocab.method.encoder import ENCODER_NAMES
from texvocab.method.field import PRECISIONS, FieldSettings
from texvocab.method.pose_refinement import POSE_REFINEMENTS
from texvocab.method.texmap import VIEW_WEIGHTINGS
from texvocab.method.unseen_texels import UNSEEN_TEXELS
from texvocab.method.vocab import WEIGHTINGS
from texvocab.pipeline.settings import (
    FLAT_NAMES,
    GROUPS,
    DataSettings,
    Encoder,
    Guide,
    MissReach,
    PoseRefinementMode,
    Precision,
    RenderSettings,
    Settings,
    Strategy,
    TrainSettings,
    UnseenTexels,
    ViewWeighting,
    VocabSettings,
    Weighting,
    resolve_name,
)
from texvocab.render import GUIDES, MISS_REACHES


def test_settings_round_trip_and_overrides():
    s = Settings().with_overrides(
        [
            "k=5",
            "field.hidden=64",
            "data.eval_views=0,3",
            "max_minutes=2.5",
            "vocab.encoder=small",
            "train_views=none",
            "train.coarse_samples=none",
        ]
    )
    assert (
        s.vocab.k,
        s.field.hidden,
        s.data.eval_views,
        s.train.max_minutes,
        s.vocab.encoder,
        s.train.coarse_samples,
    ) == (5, 64, (0, 3), 2.5, "small", None)
    assert Settings.from_dict(s.to_dict()) == s
    assert list(s.to_dict()) == ["data", "vocab", "field", "render", "train"]
    for bad, msg in (
        (["nope=1"], "unknown setting 'nope'"),
        (["k=three"], "--set k=three: setting vocab.k expects an integer"),
        (["field.nope=1"], "unknown setting 'field.nope'"),
        (["render.nope=1"], "unknown setting 'render.nope'"),
        (["k"], "expected key=value"),
        (["render=3"], "render is a group of settings"),
    ):
        with pytest.raises(TexvocabError, match=msg):
            Settings().with_overrides(bad)


def test_flat_names_map_to_the_groups():
    """Every setting outside ``field`` has one flat name (its name before the groups), and
    the five training twins of render knobs are ``train_*``."""
    dotted = set(Settings().dotted())
    assert sorted(FLAT_NAMES.values()) == sorted(n for n in dotted if not n.startswith("field."))
    assert {k: v for k, v in FLAT_NAMES.items() if k.startswith("train_") and k != "train_views"} == {
        f"train_{t}": f"train.{t}" for t in TrainSettings.TWINS
    }
    assert (FLAT_NAMES["coarse_samples"], FLAT_NAMES["guide"], FLAT_NAMES["shell_width"]) == (
        "render.coarse_samples",
        "render.guide",
        "render.shell_width",
    )
    for flat, name in FLAT_NAMES.items():  # --set takes either name for the same setting
        assert resolve_name(flat) == resolve_name(name) == name
    s = Settings().with_overrides(["train_coarse_samples=12", "coarse_samples=20"])
    assert (s.train.coarse_samples, s.render.coarse_samples) == (12, 20)
    assert s == Settings().with_overrides(["train.coarse_samples=12", "render.coarse_samples=20"])


def test_flat_checkpoint_settings_read_as_the_groups():
    s = flat_settings(
        texture_size=64,
        num_keys=4,
        train_guide="shell",
        shell_width=0.03,
        train_residual="all",
        field=FieldSettings(hidden=32),
    )
    assert Settings.from_dict(flat_dict(s)) == s
    assert (
        s.data.texture_size,
        s.vocab.num_keys,
        s.train.guide,
        s.render.shell_width,
        s.train.residual,
        s.field.hidden,
    ) == (64, 4, "shell", 0.03, "all", 32)
    with pytest.raises(TexvocabError, match="unknown setting 'nope'"):
        Settings.from_dict({**flat_dict(s), "nope": 1})
    with pytest.raises(TexvocabError, match="unknown settings \\['field.nope'\\]"):
        Settings.from_dict({**flat_dict(s), "field": {"nope": 1}})
    with pytest.raises(TexvocabError, match="unknown settings group 'nope'"):
        Settings.from_dict({**s.to_dict(), "nope": {}})
    with pytest.raises(TexvocabError, match="setting render=3: expected a group of settings"):
        Settings.from_dict({**s.to_dict(), "render": 3})


def test_choices_are_the_methods_own_and_every_knob_says_what_it_does():
    for hint, names in (
        (ViewWeighting, VIEW_WEIGHTINGS),
        (UnseenTexels, UNSEEN_TEXELS),
        (PoseRefinementMode, POSE_REFINEMENTS),
        (Strategy, STRATEGIES),
        (Weighting, WEIGHTINGS),
        (Encoder, ENCODER_NAMES),
        (Guide, GUIDES),
        (MissReach, MISS_REACHES),
        (Precision, PRECISIONS),
    ):
        assert set(get_args(hint)) == set(names)
    for group in GROUPS.values():
        for f in fields(group):
            assert f.metadata.get("doc"), f"{group.GROUP}.{f.name} has no doc"


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda: RenderSettings(coarse_samples=0), "setting render.coarse_samples=0: expected >= 1"),
        (
            lambda: RenderSettings(coarse_samples=2.0),
            "setting render.coarse_samples=2.0: expected an integer",
        ),
        (lambda: RenderSettings(guide="mesh"), "setting render.guide='mesh': expected raster or shell"),
        (
            lambda: TrainSettings(coarse_samples=None, residual="some"),
            "setting train.residual='some': expected hits, all or off",
        ),
        (lambda: TrainSettings(max_minutes=0), "setting train.max_minutes=0: expected > 0 or none"),
        (lambda: TrainSettings(lr=float("nan")), "setting train.lr=nan: expected a finite number"),
        (lambda: TrainSettings(band_newton=1), "setting train.band_newton=1: expected true or false"),
        (
            lambda: DataSettings(eval_views=(1, 1)),
            "setting data.eval_views=(1, 1): expected distinct view indices >= 0",
        ),
        (
            lambda: DataSettings(eval_views=[1]),
            "setting data.eval_views=[1]: expected a list of view indices",
        ),
        (
            lambda: DataSettings(train_views=(0, 1), eval_views=(1,)),
            "setting data.train_views=(0, 1): "
            "expected view indices >= 0 not among eval_views (held-out views never train) or none",
        ),
        (
            lambda: VocabSettings(num_keys=2, k=3),
            "setting vocab.k=3: expected <= num_keys (2): K of the M keys",
        ),
        (lambda: FieldSettings(beta_init=1e-5), "setting field.beta_init=1e-05: expected >= field.beta_min"),
        (
            lambda: Settings(render=3),
            "setting render=3: expected a group of settings "
            "(render.image_scale=..., render.coarse_samples=...)",
        ),
    ],
)
def test_each_check_sits_with_its_field_and_names_it(make, message):
    with pytest.raises(TexvocabError) as e:
        make()
    assert str(e.value) == message


def test_checkpoint_round_trip_is_atomic(tmp_path):
    path = tmp_path / "run" / "checkpoint.pt"
    save_checkpoint(path, {"step": 3, "settings": Settings().to_dict(), "model": {"w": torch.ones(2)}})
    ck = load_checkpoint(path)
    assert ck["step"] == 3 and torch.equal(ck["model"]["w"], torch.ones(2))
    assert [p.name for p in path.parent.iterdir()] == ["checkpoint.pt"]  # no temp files left

    def explode(tmp):
        open(tmp, "wb").write(b"partial")
        raise OSError("disk full")

    from texvocab.io.images import atomic_write_bytes

    with pytest.raises(OSError):
        atomic_write_bytes(path, explode)
    assert load_checkpoint(path)["step"] == 3  # the old checkpoint survives intact
    assert [p.name for p in path.parent.iterdir()] == ["checkpoint.pt"]


class _Evil:
    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


def test_malicious_checkpoint_is_refused(tmp_path):
    marker = tmp_path / "pwned"
    path = tmp_path / "checkpoint.pt"
    torch.save({"format": "texvocab-checkpoint", "model": _Evil(marker)}, path)
    with pytest.raises(AssetError, match="not a loadable texvocab checkpoint"):
        load_checkpoint(path)
    assert not marker.exists()


def test_foreign_or_newer_checkpoints(tmp_path):
    path = tmp_path / "x.pt"
    torch.save({"state_dict": {}}, path)
    with pytest.raises(AssetError, match="not a texvocab checkpoint"):
        load_checkpoint(path)
    torch.save({"format": "texvocab-checkpoint", "version": 99, "step": 0, "settings": {}, "model": {}}, path)
    with pytest.raises(AssetError, match="version 99 is newer"):
        load_checkpoint(path)
    with pytest.raises(AssetError, match="checkpoint not found"):
        load_checkpoint(tmp_path / "missing.pt")


def test_the_residual_step_is_a_render_knob_that_training_does_not_follow():
    from texvocab.pipeline.settings import TRAIN_RESIDUAL_STEP, march_settings, render_overrides

    s = Settings().with_overrides(["render.residual_step=3"])
    assert march_settings(s).residual.step == 3.0
    assert march_settings(Settings()).residual.step == 1.5
    assert march_settings(s, training=True).residual.step == TRAIN_RESIDUAL_STEP == 1.5
    # a trained checkpoint's render may change it; written before the knob, it reads 1.5
    assert render_overrides(Settings(), None, ["render.residual_step=3"]).render.residual_step == 3.0
    d = Settings().to_dict()
    del d["render"]["residual_step"]
    assert Settings.from_dict(d).render.residual_step == 1.5
    with pytest.raises(TexvocabError, match="render.residual_step=0.0: expected in"):
        Settings().with_overrides(["render.residual_step=0"])
