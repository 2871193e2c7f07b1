"""One settings object for every knob of a run, in the groups of the method's data flow:
``data`` (the view split and the texture maps, Eq. 2), ``vocab`` (the texture vocabulary
and its encoder, Eqs. 3-6), ``field`` (the network, Eq. 1), ``render`` (the marchers) and
``train`` (the optimisation, Eq. 10). Each field has a documented default and its check
beside it (:mod:`texvocab.knobs`); a bad value is refused with one line naming it, e.g.
``setting render.coarse_samples=0: expected >= 1``.

Names: ``group.field`` (``render.coarse_samples``) everywhere; ``--set`` also takes the
names of the flat settings checkpoints stored before the groups (:data:`FLAT_NAMES`:
``coarse_samples`` is ``render.coarse_samples``, ``train_coarse_samples`` is
``train.coarse_samples``). Checkpoints store :meth:`Settings.to_dict` (a dict per group);
:meth:`Settings.from_dict` reads that and the older flat dict.
"""

from __future__ import annotations

import dataclasses
import difflib
from dataclasses import asdict, dataclass, fields
from typing import ClassVar

from texvocab.errors import TexvocabError
from texvocab.knobs import check_group, parse_value, type_hints
from texvocab.method.field import FieldSettings
from texvocab.pipeline.setting_groups import (  # noqa: F401  re-exported: the groups live there
    DataSettings,
    Encoder,
    Guide,
    MissReach,
    Perceptual,
    PoseCondition,
    PoseRefinementMode,
    Precision,
    RenderSettings,
    Strategy,
    TrainResidual,
    TrainSettings,
    UnseenTexels,
    ViewWeighting,
    VocabSettings,
    Weighting,
)
from texvocab.render import MarchSettings


@dataclass
class Settings:
    """Every knob of a run, one group per stage of the method (module docstring).
    Speed/accuracy trade-offs are marked (S/A) in the fields' docs."""

    GROUP: ClassVar[str] = ""  # the groups are named by their own names

    data: DataSettings = dataclasses.field(default_factory=DataSettings)
    vocab: VocabSettings = dataclasses.field(default_factory=VocabSettings)
    field: FieldSettings = dataclasses.field(default_factory=FieldSettings)
    render: RenderSettings = dataclasses.field(default_factory=RenderSettings)
    train: TrainSettings = dataclasses.field(default_factory=TrainSettings)

    def __post_init__(self) -> None:
        check_group(self)

    def to_dict(self) -> dict[str, dict]:
        """``{group: {field: value}}`` of plain values (view tuples as lists)."""
        d = asdict(self)
        for key in ("train_views", "eval_views"):
            if d["data"][key] is not None:
                d["data"][key] = list(d["data"][key])
        return d

    def dotted(self) -> dict[str, object]:
        """``{"group.field": value}`` for every setting."""
        return {f"{g}.{k}": v for g, group in self.to_dict().items() for k, v in group.items()}

    @classmethod
    def from_dict(cls, d: dict) -> Settings:
        """Settings from :meth:`to_dict`'s form or a checkpoint's older flat one; settings a
        dict lacks take :data:`LEGACY`'s value (what they meant before they existed), else
        their default. TexvocabError naming the first unknown or bad setting."""
        if not isinstance(d, dict):
            raise TexvocabError(
                f"settings: expected a mapping of setting names to values, got {type(d).__name__}"
            )
        grouped = bool(set(d) & set(GROUPS) - {"field"})  # flat dicts hold a "field" group
        dotted = _from_groups(d) if grouped else _from_flat(d)
        return cls._from_dotted({**LEGACY, **dotted})

    @classmethod
    def _from_dotted(cls, d: dict[str, object]) -> Settings:
        groups: dict[str, dict] = {g: {} for g in GROUPS}
        for name, value in d.items():
            group, key = name.split(".", 1)
            if isinstance(value, list) and key.endswith("views"):
                value = tuple(value)
            groups[group][key] = value
        return cls(**{g: GROUPS[g](**kw) for g, kw in groups.items()})

    def with_overrides(self, items: list[str]) -> Settings:
        """Apply ``key=value`` strings; a key is ``group.field`` or a flat name
        (:func:`resolve_name`)."""
        d = self.dotted()
        for item in items:
            key, sep, raw = item.partition("=")
            if not sep:
                raise TexvocabError(f"--set {item!r}: expected key=value")
            name = resolve_name(key.strip(), item)
            group, attr = name.split(".", 1)
            d[name] = parse_value(raw.strip(), type_hints(GROUPS[group])[attr], item, name)
        return Settings._from_dotted(d)


GROUPS: dict[str, type] = {f.name: type_hints(Settings)[f.name] for f in fields(Settings)}
#: the flat names of the settings before the groups -> ``group.field``
FLAT_NAMES: dict[str, str] = {
    (f"train_{f.name}" if g == "train" and f.name in TrainSettings.TWINS else f.name): f"{g}.{f.name}"
    for g, cls in GROUPS.items()
    if g != "field"
    for f in fields(cls)
}
# What a setting absent from a stored settings dict (a checkpoint written before the
# setting existed) meant then; its default today may differ.
LEGACY: dict[str, object] = {
    "data.view_weighting": "mean",
    "data.unseen_texels": "nearest",
    "train.perceptual": "off",
    "vocab.min_key_distance": 0.0,
    "train.guide": "shell",
    "train.coarse_samples": None,
    "train.residual": "off",
    "train.band_newton": False,
    "train.shell_voxel": 0.01,
    "vocab.pose_condition": "global",
    "field.shell_coverage": None,
    "field.shell_shape": "uniform",
    "train.lr_decay": 1.0,
    "data.body_girth": "none",
    "field.position_encoding": "frequencies",
}


def resolve_name(key: str, item: str | None = None) -> str:
    """``group.field`` for a setting named ``key`` (itself, or a flat name of
    :data:`FLAT_NAMES`); TexvocabError naming ``item`` (the ``--set`` string) and the
    closest known names when there is no such setting."""
    group, dot, attr = key.partition(".")
    if dot and group in GROUPS and attr in {f.name for f in fields(GROUPS[group])}:
        return key
    if not dot and key in FLAT_NAMES:
        return FLAT_NAMES[key]
    if not dot and key in GROUPS:
        raise TexvocabError(
            f"--set {item or key!r}: {key} is a group of settings ({key}.{fields(GROUPS[key])[0].name}=...)"
        )
    known = [f"{g}.{f.name}" for g, cls in GROUPS.items() for f in fields(cls)]
    close = difflib.get_close_matches(key, known + list(FLAT_NAMES), n=4, cutoff=0.6)
    close = list(dict.fromkeys(FLAT_NAMES.get(c, c) for c in close))[:3]
    hint = f" (did you mean {' or '.join(close)}?)" if close else ""
    raise TexvocabError(f"--set {item or key!r}: unknown setting {key!r}{hint}")


def _from_groups(d: dict) -> dict[str, object]:
    """Dotted names of a ``{group: {field: value}}`` dict; unknown names are refused."""
    out = {}
    for group, values in d.items():
        if group not in GROUPS:
            raise TexvocabError(f"unknown settings group {group!r}; expected {', '.join(GROUPS)}")
        if not isinstance(values, dict):
            raise TexvocabError(
                f"setting {group}={values!r}: expected a group of settings "
                f"({group}.{fields(GROUPS[group])[0].name}=...)"
            )
        out.update(_group_items(group, values))
    return out


def _from_flat(d: dict) -> dict[str, object]:
    """Dotted names of a checkpoint's flat settings dict (its ``field`` a dict)."""
    out = {}
    for key, value in d.items():
        if key == "field":
            if not isinstance(value, dict):
                raise TexvocabError(
                    f"setting field={value!r}: expected a group of field "
                    "settings (field.hidden=..., field.pos_freqs=...)"
                )
            out.update(_group_items("field", value))
        elif key in FLAT_NAMES:
            out[FLAT_NAMES[key]] = value
        else:
            raise TexvocabError(f"unknown setting {key!r}")
    return out


def _group_items(group: str, values: dict) -> dict[str, object]:
    known = {f.name for f in fields(GROUPS[group])}
    unknown = sorted(f"{group}.{k}" for k in set(values) - known)
    if unknown:
        raise TexvocabError(f"unknown settings {unknown}")
    return {f"{group}.{k}": v for k, v in values.items()}


# Render knobs: a preset or ``--set`` may change these on a trained checkpoint (the rest
# is baked into the weights). See bench/tradeoff.py for what each costs and buys.
RENDER_KNOBS = tuple(f.name for f in fields(RenderSettings))

# Render knob -> value, chosen from bench/tradeoff.py on the default synthetic capture. The
# presets keep the field's shell: narrowing the marcher's (0.625 of it, as they once did)
# saved 2 % of a frame on the painted garment's avatar and cut 1.7 dB off the loose
# garment's, whose cloth stands up to 10 cm off the body (render.shell_scale still does it).
PRESETS: dict[str, dict] = {
    "fast": {
        "coarse_samples": 6,
        "fine_samples": 2,
        "early_stop_eps": 1e-2,
        "precision": "auto",
    },
    "balanced": {"coarse_samples": 8, "fine_samples": 4},
    # quality also marches the guided marcher's hard rays and takes the 4-sample band:
    # 1.7x the default's time, 1 dB nearer the 64+32 reference
    "quality": {
        "coarse_samples": 36,
        "fine_samples": 16,
        "early_stop_eps": 1e-4,
        "residual_rays": False,
        "band_newton": False,
    },
}


def preset_overrides(name: str, render_only: bool = False) -> list[str]:
    """``render.knob=value`` strings of preset ``name`` (every preset is render knobs
    only; ``render_only`` is kept for callers that say so)."""
    if name not in PRESETS:
        raise TexvocabError(f"preset {name!r}: expected one of {', '.join(PRESETS)}")
    return [f"render.{k}={v}" for k, v in PRESETS[name].items() if not render_only or k in RENDER_KNOBS]


def render_overrides(settings: Settings, preset: str | None, items: list[str]) -> Settings:
    """A trained checkpoint's settings with a preset and ``--set`` items applied; only the
    render knobs may change (the rest is baked into the weights)."""
    for item in items:
        if not resolve_name(item.partition("=")[0].strip(), item).startswith("render."):
            raise TexvocabError(
                f"--set {item!r}: only render knobs ("
                f"{', '.join('render.' + k for k in RENDER_KNOBS)}) can "
                "change on a trained checkpoint"
            )
    pre = preset_overrides(preset, render_only=True) if preset else []
    return settings.with_overrides(pre + list(items))


# Training marches every coarse sample of a ray (at most this many) in one field call.
TRAIN_MAX_COARSE = 512
# Training's residual rays sample the mesh every this many β (render.residual_step, which a
# trained checkpoint may change, does not reach them)
TRAIN_RESIDUAL_STEP = 1.5


def march_settings(s: Settings, training: bool = False) -> MarchSettings:
    """Marcher knobs from the settings. Training evaluates all coarse samples in one field
    call (no scouting, one segment): each call's backward through the texture-feature
    sampling costs a dense pass over the feature maps, so few large calls are far cheaper
    than the many small ones that early termination favours at render time."""
    r, t = s.render, s.train
    knobs = dict(
        shell_width=s.field.shell_width
        if training
        else r.shell_scale * s.field.shell_width
        if r.shell_width is None
        else r.shell_width,
        coarse_samples=r.coarse_samples,
        fine_samples=r.fine_samples,
        early_stop_eps=r.early_stop_eps,
        guide=r.guide,
        precision=r.precision,
        residual_rays=r.residual_rays,
        residual_step=r.residual_step,
        band_newton=r.band_newton,
        miss_reach=r.miss_reach,
    )
    if training:
        knobs.update(
            segment=TRAIN_MAX_COARSE,
            max_coarse=TRAIN_MAX_COARSE,
            scout_threshold=None,
            guide="shell",
            precision="float32",
            coarse_samples=t.coarse_samples or r.coarse_samples,
            residual_rays=t.residual != "off" and t.guide == "raster",
            band_newton=t.band_newton,
            shell_voxel=t.shell_voxel,
            band_retries=0,  # measured for rendering only; training's rays as before
            residual_step=TRAIN_RESIDUAL_STEP,  # render.residual_step is a render knob only
        )
    elif r.guide == "raster":
        # the shell serves only the guided marcher's fallback rays: a coarser, inexact
        # grid builds 3-4x faster (0.15 -> 0.04 s) for slightly longer in-shell paths
        knobs.update(shell_voxel=0.015, shell_exact=False)
    return _march(knobs)


def _march(knobs: dict) -> MarchSettings:
    """The marcher's settings from flat knob names (MarchSettings' own field names): the
    one place the run's settings build them."""
    return MarchSettings.from_flat(**knobs)
