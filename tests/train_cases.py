"""Shared training-test cases: a tiny model's settings, and settings from the flat names."""

import sys
from pathlib import Path

from texvocab.method.field import FieldSettings
from texvocab.pipeline.settings import FLAT_NAMES, GROUPS, Settings

TEXVOCAB = str(Path(sys.executable).parent / "texvocab")


def flat_settings(**kw) -> Settings:
    """Settings from flat names (``FLAT_NAMES``: ``texture_size=64`` sets
    ``data.texture_size``, ``train_guide="shell"`` sets ``train.guide``) and ``field``, a
    FieldSettings; the rest at their defaults."""
    groups: dict[str, dict] = {}
    for key, value in kw.items():
        if key == "field":
            continue
        group, name = FLAT_NAMES[key].split(".")
        groups.setdefault(group, {})[name] = value
    built = {g: GROUPS[g](**values) for g, values in groups.items()}
    return Settings(**built, **({"field": kw["field"]} if "field" in kw else {}))


def flat_dict(s: Settings) -> dict:
    """``s`` as checkpoints stored settings before the groups: one flat dict of
    ``FLAT_NAMES`` (view tuples as lists) and ``field``, a dict."""
    dotted = s.dotted()
    return {**{flat: dotted[name] for flat, name in FLAT_NAMES.items()}, "field": s.to_dict()["field"]}


def set_arguments(s: Settings) -> list[str]:
    """``--set KEY=VALUE`` arguments reproducing ``s`` on the command line (the defaults aside)."""
    ours, default = s.dotted(), Settings().dotted()
    return sum((["--set", f"{k}={v}"] for k, v in ours.items() if default[k] != v), [])


def tiny_settings(**kw) -> Settings:
    """A tiny model's settings, ``kw`` (flat names, as :func:`flat_settings`) applied."""
    base = dict(
        texture_size=64,
        num_keys=3,
        k=2,
        encoder="small",
        rays_per_batch=256,
        coarse_samples=8,
        fine_samples=8,
        iterations=40,
        checkpoint_every=10,
        field=FieldSettings(hidden=48, sdf_layers=2, color_layers=1, pos_freqs=4),
        lr=2e-3,
    )
    base.update(kw)
    return flat_settings(**base)


#: ``--set`` items of a smallest run: a few seconds of training on a tiny capture.
SMALLEST_SET = [
    "texture_size=32",
    "num_keys=1",
    "k=1",
    "rays_per_batch=64",
    "coarse_samples=8",
    "fine_samples=4",
]
