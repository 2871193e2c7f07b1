"""The settings groups of a run but ``field`` (:class:`~texvocab.method.field.FieldSettings`):
``data``, ``vocab``, ``render`` and ``train``, each knob with its default, its check and its
doc (:mod:`texvocab.knobs`). :mod:`texvocab.pipeline.settings` joins them into one
:class:`~texvocab.pipeline.settings.Settings` and re-exports them."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Literal

from texvocab.knobs import Check, above, at_least, check_group, count_in, knob, within
from texvocab.metrics.inception_perceptual import MIN_PATCH

# choices (each the Literal of a tuple the method defines; tests/pipeline keep them equal)
ViewWeighting = Literal["mean", "cosine"]  # method.texmap.VIEW_WEIGHTINGS
UnseenTexels = Literal["mean", "nearest"]  # method.unseen_texels.UNSEEN_TEXELS
Strategy = Literal["part", "joint", "global", "none"]  # body.parts.STRATEGIES
Weighting = Literal["paper", "inverse"]  # method.vocab.WEIGHTINGS
Encoder = Literal["auto", "resnet34", "resnet34-scratch", "inception", "small", "pyramid"]
Guide = Literal["raster", "shell"]  # render.GUIDES
MissReach = Literal["shell", "margin"]  # render.MISS_REACHES
Precision = Literal["float32", "bfloat16", "auto"]  # method.field_precision.PRECISIONS
TrainResidual = Literal["hits", "all", "off"]
Perceptual = Literal["auto", "lpips-vgg", "inception", "off"]
PoseRefinementMode = Literal["off", "root", "joints"]  # method.pose_refinement.POSE_REFINEMENTS
BodyGirth = Literal["masks", "none"]  # pipeline.girth_fit
PoseCondition = Literal["root-relative", "global"]  # body.pose_condition.POSE_CONDITIONS


def _views_held_out(v, g) -> bool:
    return len(v) > 0 and not set(v) & set(g.eval_views) and all(i >= 0 for i in v)


@dataclass
class DataSettings:
    """What the avatar is built from: the training and held-out views of the capture and
    the texture maps U_t back-projected from the training views (Eq. 2)."""

    GROUP: ClassVar[str] = "data"

    texture_size: int = knob(
        256,
        count_in(8, 4096),
        doc="(S/A) texels per side of U_t; the encoder's cost grows with its square",
    )
    train_views: tuple[int, ...] | None = knob(
        None,
        Check(_views_held_out, "view indices >= 0 not among eval_views (held-out views never train)"),
        doc="views to train on; none: every view not in eval_views",
    )
    eval_views: tuple[int, ...] = knob(
        (1, 5),
        Check(lambda v, _: len(set(v)) == len(v) and all(i >= 0 for i in v), "distinct view indices >= 0"),
        doc="held-out views for evaluation",
    )
    view_weighting: ViewWeighting = knob(
        "mean",
        doc="texture maps: mean (Eq. 2) | cosine "
        "(by viewing angle; +0.11 dB on novel poses, not "
        "resolved over 3 seeds)",
    )
    unseen_texels: UnseenTexels = knob(
        "mean",
        doc="texels no view of a frame saw: mean (the training frames' coverage-weighted "
        "mean there) | nearest (the map's nearest seen texel)",
    )
    body_girth: BodyGirth = knob(
        "none",
        doc="(S/A) masks: the body's surface moved out along its normals by per-joint "
        "offsets fitted to the training masks (clothes off the body) | none: the body as fitted",
    )

    def __post_init__(self) -> None:
        check_group(self)


@dataclass
class VocabSettings:
    """The texture vocabulary (Sec. 3.3-3.4): which poses are keys, how many are blended
    (Eqs. 4-6), and the encoder that turns the keys' texture maps into features."""

    GROUP: ClassVar[str] = "vocab"

    strategy: Strategy = knob("part", doc="part | joint | global (the paper's ablation) | none (no texture)")
    num_keys: int = knob(
        20,
        at_least(0),
        doc="(S/A) M keys per part (the most, when min_key_distance > 0); 0: every training frame a key",
    )
    min_key_distance: float = knob(
        0.0,
        at_least(0),
        doc="(S/A) adaptive M: stop sampling "
        "keys of a part once every training pose of it is within "
        "this Eq. 4 distance of a key (0: always M)",
    )
    k: int = knob(
        3,
        at_least(1),
        Check(
            lambda v, g: g.num_keys == 0 or v <= g.num_keys,
            lambda g: f"<= num_keys ({g.num_keys}): K of the M keys",
        ),
        doc="(S/A) K nearest keys blended per part",
    )
    weighting: Weighting = knob("paper", doc="paper (J_p - d, Eq. 6) | inverse (1/d)")
    encoder: Encoder = knob(
        "auto",
        doc="(S/A) texture encoder: auto (resnet34 when its "
        "weights exist, else pyramid) | resnet34 | resnet34-scratch | "
        "inception | small | pyramid",
    )
    pose_condition: PoseCondition = knob(
        "root-relative",
        doc="the pose the vocabulary and "
        "the field read: root-relative (joint 0's rotation, "
        "the way the body faces, removed) | global",
    )

    def __post_init__(self) -> None:
        check_group(self)


@dataclass
class RenderSettings:
    """The marchers' knobs at render time (S/A); a preset or ``--set`` may change them on a
    trained checkpoint. See :class:`~texvocab.render.MarchSettings` for what each does."""

    GROUP: ClassVar[str] = "render"

    image_scale: float = knob(
        1.0, within(0, 4, open_low=True), doc="render at this fraction of the capture's resolution"
    )
    coarse_samples: int = knob(18, at_least(1), doc="coarse samples per 2δ of in-shell path")
    fine_samples: int = knob(8, at_least(0), doc="importance samples per ray")
    early_stop_eps: float = knob(
        1e-3, within(0, 1, open_high=True), doc="a ray stops once its transmittance is below this"
    )
    shell_width: float | None = knob(
        None,
        within(0, 1, open_low=True, unit=" m"),
        doc="the marcher's δ (m); none: render.shell_scale × field.shell_width",
    )
    shell_scale: float = knob(
        1.0,
        within(0, 1, open_low=True),
        doc="where render.shell_width is none, the marcher's δ as a fraction of the field's "
        "shell: narrower is faster and cuts off surface the field grew farther from the "
        "body than δ (an avatar trained with a wider shell keeps its share)",
    )
    guide: Guide = knob(
        "raster",
        doc="raster: the surface-guided marcher (mesh raster + SDF "
        "band) | shell: every ray marched front to back through the shell",
    )
    residual_rays: bool = knob(
        True,
        doc="guide raster: the rays the band cannot take from the "
        "mesh distance + the field's residual at 3 evaluations "
        "(false: marched)",
    )
    residual_step: float = knob(
        1.5,
        within(0, 100, open_low=True),
        doc="guide raster: the residual rays sample the mesh's distance every this many β; "
        "3 renders a 512² frame of a ZJU-MoCap 387 avatar 1.21x as fast at the same PSNR, "
        "and a sharp synthetic avatar's at -0.06 to +0.02 dB (docs/results.md)",
    )
    band_newton: bool = knob(
        True,
        doc="guide raster: band rays from the probe, the Newton "
        "point and one point behind it (false: band_samples samples)",
    )
    miss_reach: MissReach = knob(
        "shell",
        doc="guide raster: the rays that miss the posed mesh which are probed for surface: "
        "shell, every ray passing within δ of it (exact: clothing may stand off the body "
        "anywhere in the shell) | margin, only those within miss_margin β (faster; cuts "
        "off surface the field grew outside the body's silhouette)",
    )
    precision: Precision = knob(
        "float32",
        doc="the number format of the field's MLPs at render time: bfloat16 runs their "
        "products on the CPU's bf16 units (AMX), auto takes bfloat16 where the CPU has them "
        "(else float32); the marchers and training compute in float32",
    )

    def __post_init__(self) -> None:
        check_group(self)


@dataclass
class TrainSettings:
    """The optimisation (Sec. 3.5, loss Eq. 10) and how training renders its rays.

    Five knobs are training's own counterparts of render knobs, separate because training
    renders small ray batches with gradients where rendering renders images: ``guide``,
    ``coarse_samples`` (none: ``render.coarse_samples``), ``residual``, ``shell_voxel`` and
    ``band_newton``. Checkpoints before the groups named them ``train_guide``,
    ``train_coarse_samples``, ``train_residual``, ``train_shell_voxel`` and
    ``train_band_newton`` (:data:`FLAT_NAMES`). The other render knobs are not used by
    training (it marches with ``field.shell_width`` and every coarse sample in one call).
    """

    GROUP: ClassVar[str] = "train"
    TWINS: ClassVar[tuple[str, ...]] = ("guide", "coarse_samples", "residual", "shell_voxel", "band_newton")

    iterations: int = knob(2000, at_least(1), doc="optimisation steps")
    rays_per_batch: int = knob(1024, at_least(1), doc="rays rendered per step")
    fg_fraction: float = knob(0.8, within(0, 1), doc="share of rays drawn inside the mask")
    guide: Guide = knob(
        "raster",
        doc="raster: rays in the mask that hit the posed mesh are "
        "rendered by the surface band (closed-form VolSDF opacity), the rest "
        "by the shell marcher | shell: every ray by the shell marcher",
    )
    coarse_samples: int | None = knob(
        9,
        at_least(1),
        doc="coarse samples of the rays "
        "training marches (none: render.coarse_samples); 9 "
        "against 18: the same loss curve, +0.54 dB novel PSNR",
    )
    residual: TrainResidual = knob(
        "hits",
        doc="guide raster: which rays the band leaves are "
        "residual rays (3 evaluations) before the marcher: hits "
        "(failed bands and hits behind a close edge, inside the "
        "mask) | all (also the close silhouette misses: fastest, "
        "-0.12 dB on novel poses) | off",
    )
    shell_voxel: float = knob(
        0.015,
        within(0.002, 0.1, unit=" m"),
        doc="(S/A) voxel of each "
        "training frame's shell grid (m): 0.01 builds 2.7x slower for "
        "an 11% tighter shell",
    )
    band_newton: bool = knob(
        True,
        doc="guide raster: band rays from the probe, the Newton "
        "point and one behind it (3 evaluations) | false: band_samples",
    )
    lr: float = knob(5e-4, within(0, 1, open_low=True), doc="Adam's learning rate")
    beta_lr_scale: float = knob(
        1.0,
        above(0),
        doc="VolSDF's β learns at this multiple of train.lr (its own optimiser group when not 1): "
        "how fast the surface sharpens",
    )
    triplane_lr_scale: float = knob(
        20.0,
        above(0),
        doc="the tri-plane's features (field.position_encoding=triplane) learn at this multiple of train.lr",
    )
    lr_decay: float = knob(
        1.0,
        within(0, 1, open_low=True),
        doc="learning rate at the run's end as a share of train.lr, reached exponentially "
        "over the run (its steps, or its time budget when that ends it first; VolSDF "
        "decays to 0.1); 1: constant",
    )
    lambda_color: float = knob(1.0, at_least(0), doc="λ_c of the colour term (Eq. 10)")
    lambda_mask: float = knob(0.1, at_least(0), doc="λ_m of the mask term (Eq. 10)")
    lambda_eikonal: float = knob(0.05, at_least(0), doc="λ_e of the eikonal term (Eq. 10)")
    eikonal_points: int = knob(
        512,
        at_least(1),
        doc="points near the body (within half the shell) whose SDF gradient the eikonal term "
        "reads each step; its second-order backward pass is a share of every step's time",
    )
    perceptual: Perceptual = knob(
        "auto", doc="auto (lpips-vgg if its weights exist, else inception) | lpips-vgg | inception | off"
    )
    lambda_perceptual: float = knob(0.05, at_least(0), doc="λ_p of the perceptual term (Eq. 10; 0: off)")
    patch_size: int = knob(
        24,
        at_least(MIN_PATCH),
        doc="(S/A) side of the square patch each step renders for the perceptual term",
    )
    pose_refinement: PoseRefinementMode = knob(
        "off",
        doc="per-frame corrections of the recorded poses, trained with the avatar: off | root "
        "(root rotation and translation) | joints (every joint and the translation)",
    )
    pose_refinement_span: int = knob(
        1,
        at_least(1),
        doc="training frames that share a pose correction: 1 = one per frame; s = corrections on "
        "every s-th frame, blended linearly between (each drawn s times as often)",
    )
    pose_lr: float = knob(
        5e-3, within(0, 1, open_low=True), doc="Adam's learning rate of the pose corrections"
    )
    lambda_pose: float = knob(
        0.01, at_least(0), doc="weight of the corrections' prior Σδθ² + (δT / 10 cm)² (per step, its frame's)"
    )
    weight_average: float = knob(
        0.0,
        within(0, 1, open_high=True),
        doc="decay of a moving average of the weights, which checkpoints hold for evaluation "
        "and rendering (training steps the raw weights; 0: off, 0.995: about the last 200 steps)",
    )
    checkpoint_every: int = knob(250, at_least(1), doc="steps between checkpoints")
    max_minutes: float | None = knob(
        None, above(0), doc="stop (with a checkpoint) after this much training time"
    )
    seed: int = knob(0, doc="seeds the initial weights and the run's random stream")

    def __post_init__(self) -> None:
        check_group(self)
