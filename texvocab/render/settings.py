"""The marchers' knobs, grouped by the part of the renderer they steer: the shell marcher
(:class:`ShellSettings`), the surface band (:class:`BandSettings`), the residual rays
(:class:`ResidualSettings`), the guided marcher's fallback march
(:class:`FallbackSettings`) and the batch sizes every path shares (:class:`ChunkSettings`).
Each knob trades speed (field evaluations) for accuracy.

Other code and stored settings name the knobs flat (``shell_width``, ``band_newton``, …,
:data:`FLAT_NAMES`): :meth:`MarchSettings.from_flat` builds from them,
:meth:`MarchSettings.replace` changes them, :meth:`MarchSettings.flat` lists them, and each
flat name reads and writes its group's field as an attribute (``settings.coarse_samples``).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field


@dataclass(frozen=True)
class ShellSettings:
    """The shell marcher (:mod:`texvocab.render.shell`).

    width: δ, metres. Only points within δ of the posed mesh are sampled. Smaller is faster
        but cuts off surface the field has moved away from the mesh (clothes, hair), and a
        ray entering the body keeps only ~δ of interior: its leftover transmittance is about
        exp(-δ/β) for a VolSDF density, so keep δ >= 7β. (The band and the residual rays
        read it too: the field's density is zero beyond the shell.)
    voxel: occupancy-grid voxel, metres. The sampled path reaches up to about δ + 0.9 voxel
        from the mesh: smaller wastes fewer samples next to the shell but costs a bigger
        grid per pose (cubic in 1/voxel).
    exact: settle the grid voxels near the shell's boundary with exact distances (a
        SurfaceIndex query per pose, ~0.1 s) instead of keeping them all (looser shell,
        about 20% more samples).
    skip_empty: True places samples only on the in-shell path (occupancy grid); False
        spreads them uniformly over [near, far] of the bounding balls (gaps included).
    coarse_samples: coarse samples per crossing of the shell: the coarse step along the
        in-shell path is 2δ / coarse_samples (stratified), so a ray crossing the shell along
        its normal gets this many and a ray grazing it fewer (18: 4.4 mm for δ = 4 cm,
        measured in bench/marcher.py for β of 2-4 mm). Keep the step within about 2β of the
        field: a coarser step may miss a sharp or thin surface, which the fine pass then
        never finds. Early termination stops most rays shortly after the first surface, so
        longer paths cost little more.
    max_coarse: cap on coarse samples per ray (long paths, e.g. a camera inside the body,
        get a larger step instead).
    fine_samples: importance samples per ray (inverse CDF of the coarse weights).
    dilate: spread the coarse weights to neighbouring bins before importance sampling
        (mip-NeRF's max-blur), so fine samples also cover a surface that fell between two
        coarse samples; costs nothing, and makes a coarser step usable.
    scout_threshold: coarse samples are first evaluated every other one ("scouts"); a
        sample between two scouts is evaluated only if one of them has sigma * step at
        least this (None: evaluate all). Empty shell then costs half; higher values save
        more but may step over faint or thin density.
    segment: coarse samples (scouts) per ray evaluated per step of the front-to-back march;
        a ray evaluates up to segment - 1 of them past the point where it became opaque,
        while a small segment means more, smaller field calls.
    early_stop_eps: a ray stops marching once its transmittance drops below this, and the
        leftover goes to its last evaluated sample: the colour error per ray is at most eps
        times the colour change behind that point; 0 disables the stop.
    empty_opacity: rays whose coarse opacity stays below this get no fine samples (they
        graze the shell but not the surface); their colour is off by at most this.
    """

    width: float = 0.04
    voxel: float = 0.01
    exact: bool = True
    skip_empty: bool = True
    coarse_samples: int = 18
    max_coarse: int = 512
    fine_samples: int = 8
    dilate: bool = True
    scout_threshold: float | None = 1e-3
    segment: int = 2
    early_stop_eps: float = 1e-3
    empty_opacity: float = 1e-3


#: How far from the mesh a missing ray can still meet the surface (BandSettings.miss_reach).
MISS_REACHES = ("shell", "margin")


@dataclass(frozen=True)
class BandSettings:
    """The surface band of the guided marcher (:mod:`texvocab.render.guided`): the mesh's
    rasterisation and the field's SDF place a few samples around each ray's surface,
    composited in closed form.

    samples: without ``newton``, the samples placed ``spacing`` β / cos apart around the
        Newton point t* (1 + samples evaluations per ray with the probe).
    spacing: the band's sample spacing, in β / cos.
    leftover: a band leaving more transmittance than this is not resolved (the ray falls
        back).
    min_cos: rays meeting faces at a cosine below this are not band rays (grazing hits).
    miss_margin: a passed surface farther than this many β from a ray shows nothing
        (density < e^-miss_margin / 2β): the ray is a band ray (a hit) or the background (a
        miss); nearer, it is a residual or a marched ray.
    newton: band rays take two evaluations after their probe (at t* and ``spacing`` β / cos
        behind it) and the SDF between is the hit face's plane plus the interpolated
        residual (:func:`texvocab.render.guided.band.newton_band`, 3 evaluations per ray);
        False: ``samples`` samples around t*.
    retries: a Newton band ray left unresolved whose SDF at its Newton point is more than
        ``retry_from`` β from 0 (the step missed the surface: clothing off the body) starts
        again from that point, up to this many times (two evaluations each; 0: it goes on
        to the residual rays or the marcher).
    retry_from: see ``retries`` (in β).
    miss_reach: which rays that miss the mesh are probed (:data:`MISS_REACHES`): "shell",
        every ray passing within δ of the mesh (exact: the avatar's surface may lie anywhere
        in the shell, as loose clothing does); "margin", only those within
        min(δ, ``miss_margin`` β), which assumes the surface lies on the mesh outside its
        silhouette (faster for avatars whose surface is the body's; cuts off clothing that
        stands off it).
    """

    samples: int = 4
    spacing: float = 2.0
    leftover: float = 0.1
    min_cos: float = 0.25
    miss_margin: float = 8.0
    newton: bool = True
    retries: int = 1
    retry_from: float = 2.0
    miss_reach: str = "shell"

    def __post_init__(self) -> None:
        if self.miss_reach not in MISS_REACHES:
            raise ValueError(f"miss_reach {self.miss_reach!r}: expected one of {', '.join(MISS_REACHES)}")


@dataclass(frozen=True)
class ResidualSettings:
    """The residual rays of the guided marcher (:mod:`texvocab.render.guided.residual`).

    enabled: the rays the band cannot take (close passing rays, grazing hits, hits behind a
        close edge, failed bands) are rendered from the mesh's distance sampled every
        ``step`` β along the ray plus the field's residual, interpolated between three
        evaluations at the ``spread``, 1/2 and 1 - ``spread`` quantiles of the ray's
        estimated weights; the rays it cannot resolve are marched: those whose residuals
        (with the probe's) differ by more than ``tolerance`` β, or whose final weights
        centre outside the three. False marches them all.
    step: a smaller step integrates the curved SDF more finely (more mesh queries; still
        three field evaluations per ray).
    spread: a smaller spread puts the outer evaluations farther out.
    tolerance: a smaller tolerance marches more rays (the Newton band's residuals obey it
        too).
    groups: speed only: the rays' quadrature runs in this many groups of similar sample
        counts, each as long as its longest ray (1: one array for all, padded to the
        longest; the counts vary several-fold). Training's quadrature only: a render's runs
        compiled, ray by ray.
    levels: speed: coarser passes (steps 4× apart) that narrow a ray's interval before
        the 4 ``step`` β pass, so a ray through the body is not sampled finely along the
        whole shell interval (0: the 4 ``step`` β pass over all of it, as before).
    retries: a ray left unresolved starts again, up to this many times, with its three
        evaluations as probes: the residual of the one nearest the surface stands for the
        ray's (clothing off the body, whose residual at the probe is not the residual at
        the surface; three evaluations each). 0: it is marched.
    """

    enabled: bool = True
    step: float = 1.5
    spread: float = 0.05
    tolerance: float = 2.0
    groups: int = 4
    levels: int = 2
    retries: int = 0


@dataclass(frozen=True)
class FallbackSettings:
    """The guided marcher's march of the rays neither the band nor the residual rays
    resolve: the shell marcher with ``segment`` scouts per step and ``scout_threshold`` as
    its scout threshold instead of the shell group's (few rays: fewer, larger calls). A field
    call has a fixed cost of a few ms: 64 scouts a step evaluate most of these rays' coarse
    samples in one call (3 calls a frame for the march instead of 7 with 8, for 0.02 % more
    evaluations and the same image to 2e-4 on a trained avatar). ``grid_rays``: up to this
    many rays march their whole shell interval [near, far] instead of the occupancy grid's
    in-shell path (the grid's build costs more than a handful of rays' empty stretches;
    0: always the grid)."""

    segment: int = 64
    scout_threshold: float | None = 1e-3
    grid_rays: int = 64


@dataclass(frozen=True)
class ChunkSettings:
    """Batch sizes (memory, not accuracy): ``rays`` per batch, ``points`` per field call."""

    rays: int = 4096
    points: int = 1 << 18


@dataclass
class MarchSettings:
    """Knobs of the render paths. ``guide`` names the path (:mod:`texvocab.render.paths`):
    "shell" marches every ray through the shell front to back, "raster" is the
    surface-guided marcher (band, residual rays, the rest marched). ``precision`` is the
    number format the field's MLPs are evaluated in when an image is rendered
    (``AvatarField.for_pose``; "float32", "bfloat16" or "auto"); the marchers themselves compute
    in float32. ``surface_reuse``: the guided marcher hands the field each point's closest
    face of the posed mesh where it knows it already — a probe at a rasterised hit lies on
    the hit face, a residual ray's three evaluations lie on its mesh samples — so the
    field's projection onto the body skips the search there (the same answers up to ties
    between equally near faces); False searches every point, as before."""

    guide: str = "shell"
    precision: str = "float32"
    surface_reuse: bool = True
    shell: ShellSettings = field(default_factory=ShellSettings)
    band: BandSettings = field(default_factory=BandSettings)
    residual: ResidualSettings = field(default_factory=ResidualSettings)
    fallback: FallbackSettings = field(default_factory=FallbackSettings)
    chunks: ChunkSettings = field(default_factory=ChunkSettings)

    @classmethod
    def from_flat(cls, **flat) -> MarchSettings:
        """From the flat knob names (:data:`FLAT_NAMES`); the others keep their defaults."""
        return cls().replace(**flat)

    def replace(self, **changes) -> MarchSettings:
        """A copy with knobs changed, by flat name (``coarse_samples=8``) or whole group
        (``band=BandSettings(...)``)."""
        groups = {f.name for f in dataclasses.fields(self)}
        top = {k: v for k, v in changes.items() if k in groups}
        per_group: dict[str, dict] = {}
        for key, value in changes.items():
            if key in top:
                continue
            if key not in FLAT_NAMES:
                raise TypeError(f"MarchSettings has no knob {key!r}; expected one of {', '.join(FLAT_NAMES)}")
            group, name = FLAT_NAMES[key]
            per_group.setdefault(group, {})[name] = value
        new = dataclasses.replace(self, **top)
        for group, values in per_group.items():
            setattr(new, group, dataclasses.replace(getattr(new, group), **values))
        return new

    def flat(self) -> dict:
        """The knobs by their flat names, in :data:`FLAT_NAMES` order."""
        return {key: getattr(self, key) for key in FLAT_NAMES}


#: flat knob name -> (group, field) of :class:`MarchSettings` (``guide`` is its own field)
FLAT_NAMES: dict[str, tuple[str, str]] = {
    "shell_width": ("shell", "width"),
    "shell_voxel": ("shell", "voxel"),
    "shell_exact": ("shell", "exact"),
    "skip_empty": ("shell", "skip_empty"),
    "coarse_samples": ("shell", "coarse_samples"),
    "max_coarse": ("shell", "max_coarse"),
    "fine_samples": ("shell", "fine_samples"),
    "dilate": ("shell", "dilate"),
    "scout_threshold": ("shell", "scout_threshold"),
    "segment": ("shell", "segment"),
    "early_stop_eps": ("shell", "early_stop_eps"),
    "empty_opacity": ("shell", "empty_opacity"),
    "chunk_rays": ("chunks", "rays"),
    "chunk_points": ("chunks", "points"),
    "guide": ("", "guide"),
    "precision": ("", "precision"),
    "surface_reuse": ("", "surface_reuse"),
    "band_samples": ("band", "samples"),
    "band_spacing": ("band", "spacing"),
    "band_leftover": ("band", "leftover"),
    "min_cos": ("band", "min_cos"),
    "miss_margin": ("band", "miss_margin"),
    "miss_reach": ("band", "miss_reach"),
    "band_retries": ("band", "retries"),
    "band_retry_from": ("band", "retry_from"),
    "fallback_segment": ("fallback", "segment"),
    "fallback_scout": ("fallback", "scout_threshold"),
    "fallback_grid_rays": ("fallback", "grid_rays"),
    "residual_rays": ("residual", "enabled"),
    "residual_step": ("residual", "step"),
    "residual_spread": ("residual", "spread"),
    "residual_tolerance": ("residual", "tolerance"),
    "residual_groups": ("residual", "groups"),
    "residual_levels": ("residual", "levels"),
    "residual_retries": ("residual", "retries"),
    "band_newton": ("band", "newton"),
}


def _flat_property(group: str, name: str) -> property:
    """The attribute of a flat knob name: reads the group's field; writing replaces the
    group (the groups are frozen, so copies of a MarchSettings never share a change)."""

    def get(self: MarchSettings):
        return getattr(getattr(self, group), name)

    def put(self: MarchSettings, value) -> None:
        setattr(self, group, dataclasses.replace(getattr(self, group), **{name: value}))

    return property(get, put, doc=f"``{group}.{name}`` by its flat name")


for _key, (_group, _name) in FLAT_NAMES.items():
    if _group:
        setattr(MarchSettings, _key, _flat_property(_group, _name))
