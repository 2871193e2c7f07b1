"""One settings object for every knob that trades speed for accuracy (and the rest of a
training run). Each field has a documented default; the CLI maps ``--set key=value``
onto it and checkpoints store it as a plain dict.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields

from texvocab.body.parts import STRATEGIES
from texvocab.errors import TexvocabError
from texvocab.method.encoder import ENCODER_NAMES
from texvocab.method.field import FieldSettings
from texvocab.method.texmap import VIEW_WEIGHTINGS
from texvocab.method.vocab import WEIGHTINGS
from texvocab.metrics.inception_perceptual import MIN_PATCH
from texvocab.render import GUIDES, MarchSettings

PERCEPTUAL_CHOICES = ("auto", "lpips-vgg", "inception", "off")
TRAIN_RESIDUAL = ("all", "hits", "off")
# What a setting absent from a stored settings dict (a checkpoint written before the
# setting existed) meant then; its default today may differ.
OPTIONAL_INTS = ("train_coarse_samples",)  # settings that are an integer or None
LEGACY = {"view_weighting": "mean", "perceptual": "off", "min_key_distance": 0.0,
          "train_guide": "shell", "train_coarse_samples": None, "train_residual": "off",
          "train_band_newton": False, "train_shell_voxel": 0.01}


@dataclass
class Settings:
    """Knobs, grouped. Speed/accuracy trade-offs are marked (S/A)."""

    # data
    texture_size: int = 256  # (S/A) texels per side of U_t; encoder cost grows with its square
    train_views: tuple[int, ...] | None = None  # None: every view not in eval_views
    eval_views: tuple[int, ...] = (1, 5)  # held-out views for evaluation
    view_weighting: str = "mean"  # texture maps: mean (Eq. 2) | cosine (by viewing angle;
    # +0.11 dB on novel poses but not resolved over 3 seeds, README)
    # vocabulary (Sec. 3.3-3.4)
    strategy: str = "part"  # part | joint | global (the paper's ablation) | none (no texture)
    num_keys: int = 20  # (S/A) M keys per part (the most, when min_key_distance > 0)
    min_key_distance: float = 0.0  # (S/A) adaptive M: stop sampling keys of a part once
    # every training pose of it is within this Eq. 4 distance of a key (0: always M)
    k: int = 3  # (S/A) K nearest keys blended per part
    weighting: str = "paper"  # paper (J_p - d) | inverse (1/d)
    encoder: str = "auto"  # (S/A) auto | resnet34 | resnet34-scratch | inception | small | pyramid
    # field
    field: FieldSettings = field(default_factory=FieldSettings)
    # rendering (S/A)
    coarse_samples: int = 18  # per 2δ of in-shell path (see MarchSettings)
    fine_samples: int = 8
    early_stop_eps: float = 1e-3
    image_scale: float = 1.0  # render at this fraction of the capture's resolution
    shell_width: float | None = None  # marcher δ (m); None: the field's shell_width
    guide: str = "raster"  # raster: surface-guided marcher (mesh raster + SDF band, README
    # "Rendering") | shell: every ray marched front to back through the shell
    residual_rays: bool = True  # guide raster: the rays the band cannot take from the mesh
    # distance + the field's residual at 3 evaluations (false: marched; MarchSettings)
    band_newton: bool = True  # guide raster: band rays from the probe, the Newton point and
    # one point behind it (false: band_samples samples; MarchSettings)
    # training
    iterations: int = 2000
    rays_per_batch: int = 1024
    fg_fraction: float = 0.8  # share of rays drawn inside the mask
    train_guide: str = "raster"  # raster: rays in the mask that hit the posed mesh are
    # rendered by the surface band (probe + band_samples, closed-form VolSDF opacity), the
    # rest by the shell marcher | shell: every ray by the shell marcher (README "Training")
    train_coarse_samples: int | None = 9  # coarse_samples of the rays training marches
    # (none: coarse_samples); with the band, only silhouette and occlusion-edge rays are
    # marched; 9 against 18: the same loss curve, +0.54 dB novel PSNR (README "Training")
    train_residual: str = "hits"  # train_guide raster: which rays the band leaves are
    # residual rays (3 evaluations; residual_* knobs) before the marcher: hits (failed
    # bands and hits behind a close edge, inside the mask) | all (also the close
    # silhouette misses: fastest, but -0.12 dB on novel poses) | off (README "Training")
    train_shell_voxel: float = 0.015  # (S/A) voxel of each training frame's shell grid
    # (metres; exact near its boundary): 0.01 builds 2.7x slower (135 against 50 ms a
    # frame) for an 11% tighter shell around the marched rays
    train_band_newton: bool = True  # train_guide raster: band rays from the probe, the
    # Newton point and one behind it (3 evaluations) | false: band_samples samples
    lr: float = 5e-4
    lambda_color: float = 1.0
    lambda_mask: float = 0.1
    lambda_eikonal: float = 0.05
    perceptual: str = "auto"  # auto (lpips-vgg if its weights exist, else inception) |
    # lpips-vgg | inception | off
    lambda_perceptual: float = 0.05  # 0: the perceptual term is off
    patch_size: int = 24  # (S/A) side of the square patch each step renders for it
    checkpoint_every: int = 250
    max_minutes: float | None = None  # stop (with a checkpoint) after this much training time
    seed: int = 0

    def __post_init__(self) -> None:
        """Refuse values the method cannot run with, naming the setting and the range."""
        self._check_types()
        f = self.field
        checks = [
            ("texture_size", self.texture_size >= 8, ">= 8"),
            ("num_keys", self.num_keys >= 1, ">= 1"),
            ("k", self.k >= 1, ">= 1"),
            ("strategy", self.strategy in STRATEGIES, "part, joint, global or none"),
            ("weighting", self.weighting in WEIGHTINGS, " or ".join(WEIGHTINGS)),
            ("min_key_distance", 0 <= self.min_key_distance, ">= 0"),
            ("view_weighting", self.view_weighting in VIEW_WEIGHTINGS,
             " or ".join(VIEW_WEIGHTINGS)),
            ("encoder", self.encoder in ENCODER_NAMES, ", ".join(ENCODER_NAMES)),
            ("perceptual", self.perceptual in PERCEPTUAL_CHOICES, ", ".join(PERCEPTUAL_CHOICES)),
            ("lambda_perceptual", self.lambda_perceptual >= 0, ">= 0"),
            ("patch_size", MIN_PATCH <= self.patch_size, f">= {MIN_PATCH}"),
            ("coarse_samples", self.coarse_samples >= 1, ">= 1"),
            ("train_coarse_samples", self.train_coarse_samples is None
             or self.train_coarse_samples >= 1, ">= 1 or none"),
            ("fine_samples", self.fine_samples >= 0, ">= 0"),
            ("early_stop_eps", 0 <= self.early_stop_eps < 1, "in [0, 1)"),
            ("image_scale", 0 < self.image_scale <= 4, "in (0, 4]"),
            ("shell_width", self.shell_width is None or 0 < self.shell_width <= 1, "in (0, 1] m"),
            ("train_shell_voxel", 0.002 <= self.train_shell_voxel <= 0.1, "in [0.002, 0.1] m"),
            ("guide", self.guide in GUIDES, " or ".join(GUIDES)),
            ("train_guide", self.train_guide in GUIDES, " or ".join(GUIDES)),
            ("train_residual", self.train_residual in TRAIN_RESIDUAL,
             " or ".join(TRAIN_RESIDUAL)),
            ("k", self.k <= self.num_keys, f"<= num_keys ({self.num_keys}): K of the M keys"),
            ("iterations", self.iterations >= 1, ">= 1"),
            ("checkpoint_every", self.checkpoint_every >= 1, ">= 1"),
            ("max_minutes", self.max_minutes is None or self.max_minutes > 0, "> 0 or none"),
            ("lr", 0 < self.lr <= 1, "in (0, 1]"),
            ("lambda_color", self.lambda_color >= 0, ">= 0"),
            ("lambda_mask", self.lambda_mask >= 0, ">= 0"),
            ("lambda_eikonal", self.lambda_eikonal >= 0, ">= 0"),
            ("eval_views", len(set(self.eval_views)) == len(self.eval_views)
             and all(v >= 0 for v in self.eval_views), "distinct view indices >= 0"),
            ("train_views", self.train_views is None or (
                len(self.train_views) > 0 and not set(self.train_views) & set(self.eval_views)
                and all(v >= 0 for v in self.train_views)),
             "view indices >= 0 not among eval_views (held-out views never train)"),
            ("field.pos_freqs", 0 <= f.pos_freqs <= 16, "in 0..16"),
            ("field.dir_freqs", 0 <= f.dir_freqs <= 16, "in 0..16"),
            ("field.feature_proj", 1 <= f.feature_proj, ">= 1"),
            ("field.hidden", 1 <= f.hidden, ">= 1"),
            ("field.sdf_layers", 1 <= f.sdf_layers, ">= 1"),
            ("field.color_layers", 0 <= f.color_layers, ">= 0"),
            ("rays_per_batch", self.rays_per_batch >= 1, ">= 1"),
            ("fg_fraction", 0 <= self.fg_fraction <= 1, "in [0, 1]"),
            # float32 VolSDF density and its gradients break down for beta below ~1e-17
            ("field.beta_min", self.field.beta_min >= 1e-8, ">= 1e-8"),
            ("field.beta_init", self.field.beta_init >= self.field.beta_min, ">= field.beta_min"),
            ("field.shell_width", 0 < self.field.shell_width <= 1, "in (0, 1] m"),
        ]
        for name, ok, expected in checks:
            if not ok:
                value = self.field.to_dict()[name[6:]] if name.startswith("field.") else getattr(
                    self, name)
                raise TexvocabError(f"setting {name}={value!r}: expected {expected}")

    def _check_types(self) -> None:
        """Every setting has its default's type (ints stay ints, floats are finite
        numbers, tuples of view indices are ints); raises naming the first that is not."""
        if not isinstance(self.field, FieldSettings):
            raise TexvocabError(f"setting field={self.field!r}: expected a group of field "
                                "settings (field.hidden=..., field.pos_freqs=...)")
        for group, prefix in ((self, ""), (self.field, "field.")):
            for f in fields(group):
                if f.name == "field":
                    continue
                value, default = getattr(group, f.name), f.default
                if f.name in ("train_views", "eval_views"):
                    ok = (value is None and f.name == "train_views") or (
                        isinstance(value, tuple) and all(type(v) is int for v in value))
                    what = "a list of view indices"
                elif f.name in ("max_minutes", "shell_width"):
                    ok = value is None or _finite(value)
                    what = "a finite number or none"
                elif f.name in OPTIONAL_INTS:
                    ok, what = value is None or type(value) is int, "an integer or none"
                elif isinstance(default, bool):
                    ok, what = isinstance(value, bool), "true or false"
                elif isinstance(default, int):
                    ok, what = type(value) is int, "an integer"
                elif isinstance(default, float):
                    ok, what = _finite(value), "a finite number"
                else:
                    ok, what = isinstance(value, str), "a name"
                if not ok:
                    raise TexvocabError(f"setting {prefix}{f.name}={value!r}: expected {what}")

    def to_dict(self) -> dict:
        d = asdict(self)
        d["train_views"] = None if self.train_views is None else list(self.train_views)
        d["eval_views"] = list(self.eval_views)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> Settings:
        """Settings from a plain dict (a checkpoint's or ``--set``'s); TexvocabError naming
        the first setting that is unknown or of the wrong kind."""
        if not isinstance(d, dict):
            raise TexvocabError(f"settings: expected a mapping of setting names to values, "
                                f"got {type(d).__name__}")
        d = {**LEGACY, **d}  # a checkpoint from before a setting existed: its behaviour then
        group = d.get("field", {})
        if not isinstance(group, dict):
            raise TexvocabError(f"setting field={group!r}: expected a group of field settings "
                                "(field.hidden=..., field.pos_freqs=...)")
        unknown = set(group) - {f.name for f in fields(FieldSettings)}
        if unknown:
            raise TexvocabError(f"unknown settings {sorted('field.' + k for k in unknown)}")
        d["field"] = FieldSettings(**group)
        for key in ("train_views", "eval_views"):
            if isinstance(d.get(key), list | tuple):
                d[key] = tuple(d[key])
        known = {f.name for f in fields(cls)}
        unknown = set(d) - known
        if unknown:
            raise TexvocabError(f"unknown settings {sorted(unknown)}")
        return cls(**d)

    def with_overrides(self, items: list[str]) -> Settings:
        """Apply ``key=value`` strings (``field.hidden=64`` reaches nested settings)."""
        d = self.to_dict()
        for item in items:
            key, sep, raw = item.partition("=")
            if not sep:
                raise TexvocabError(f"--set {item!r}: expected key=value")
            target, name = d, key
            if "." in key:
                head, name = key.split(".", 1)
                if head not in d or not isinstance(d[head], dict):
                    raise TexvocabError(f"--set {item!r}: no settings group {head!r}")
                target = d[head]
            if name not in target:
                raise TexvocabError(f"--set {item!r}: unknown setting {key!r}")
            target[name] = _parse(raw, target[name], key)
        return Settings.from_dict(d)


def _finite(value) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _parse(raw: str, current, key: str):
    if key in OPTIONAL_INTS and raw.lower() == "none":
        return None
    try:
        if isinstance(current, bool):
            if raw.lower() not in ("true", "false", "1", "0"):
                raise ValueError(raw)
            return raw.lower() in ("true", "1")
        if isinstance(current, int):
            return int(raw)
        if isinstance(current, float):
            return float(raw)
        if raw.lower() == "none" and (current is None or key.endswith("views")):
            return None
        if isinstance(current, list) or "views" in key:
            return [int(v) for v in raw.split(",") if v]
        if current is None:
            return int(raw) if key in OPTIONAL_INTS else float(raw)
    except ValueError:
        what = "an integer or none" if key in OPTIONAL_INTS else f"a {type(current).__name__}"
        raise TexvocabError(f"--set {key}={raw}: expected {what}") from None
    return raw


# Render knobs: a preset or ``--set`` may change these on a trained checkpoint (the rest
# is baked into the weights). See bench/tradeoff.py for what each costs and buys.
RENDER_KNOBS = ("image_scale", "coarse_samples", "fine_samples", "early_stop_eps", "shell_width",
                "guide", "residual_rays", "band_newton")

# Chosen from bench/tradeoff.py on the default synthetic capture (README, "Presets").
PRESETS: dict[str, dict] = {
    "fast": {"shell_width": 0.025, "coarse_samples": 6, "fine_samples": 2, "early_stop_eps": 1e-2},
    "balanced": {"shell_width": 0.025, "coarse_samples": 8, "fine_samples": 4},
    # quality also marches the guided marcher's hard rays and takes the 4-sample band:
    # 1.7x the default's time, 1 dB nearer the 64+32 reference (README, session 11)
    "quality": {"coarse_samples": 36, "fine_samples": 16, "early_stop_eps": 1e-4,
                "residual_rays": False, "band_newton": False},
}


def preset_overrides(name: str, render_only: bool = False) -> list[str]:
    """``key=value`` strings of preset ``name`` (only the render knobs if ``render_only``)."""
    if name not in PRESETS:
        raise TexvocabError(f"preset {name!r}: expected one of {', '.join(PRESETS)}")
    return [f"{k}={v}" for k, v in PRESETS[name].items() if not render_only or k in RENDER_KNOBS]


def render_overrides(settings: Settings, preset: str | None, items: list[str]) -> Settings:
    """A trained checkpoint's settings with a preset and ``--set`` items applied; only the
    render knobs may change (the rest is baked into the weights)."""
    bad = [i for i in items if i.partition("=")[0] not in RENDER_KNOBS]
    if bad:
        raise TexvocabError(f"--set {bad[0]!r}: only render knobs ({', '.join(RENDER_KNOBS)}) "
                            "can change on a trained checkpoint")
    pre = preset_overrides(preset, render_only=True) if preset else []
    return settings.with_overrides(pre + list(items))


def march_settings(s: Settings, training: bool = False) -> MarchSettings:
    """Marcher knobs from the settings. Training evaluates all coarse samples in one field
    call (no scouting, one segment): each call's backward through the texture-feature
    sampling costs a dense pass over the feature maps, so few large calls are far cheaper
    than the many small ones that early termination favours at render time."""
    width = s.field.shell_width if training or s.shell_width is None else s.shell_width
    m = MarchSettings.from_flat(shell_width=width, coarse_samples=s.coarse_samples,
                                fine_samples=s.fine_samples, early_stop_eps=s.early_stop_eps,
                                guide=s.guide, residual_rays=s.residual_rays,
                                band_newton=s.band_newton)
    if training:
        m.segment, m.scout_threshold, m.guide = m.max_coarse, None, "shell"
        m.coarse_samples = s.train_coarse_samples or s.coarse_samples
        m.residual_rays = s.train_residual != "off" and s.train_guide == "raster"
        m.band_newton = s.train_band_newton
        m.shell_voxel = s.train_shell_voxel
    elif m.guide == "raster":
        # the shell serves only the guided marcher's fallback rays: a coarser, inexact
        # grid builds 3-4x faster (0.15 -> 0.04 s) for slightly longer in-shell paths
        m.shell_voxel, m.shell_exact = 0.015, False
    return m
