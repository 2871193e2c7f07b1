"""``texvocab train``: fit the avatar to a capture (Sec. 3.5).

Each step picks a training frame and views, draws rays inside the shell around the posed
body (``train.fg_fraction`` of them inside the mask), renders them — with the surface band
where the posed mesh's rasterisation allows (``train.guide=raster``,
:func:`~texvocab.render.guided.triage.render_rays_banded`), else with the coarse-to-fine shell
marcher — and minimises λ_c·MSE(colour) + λ_m·MAE(opacity, mask) + λ_e·eikonal
+ λ_p·perceptual. For the perceptual term one ``train.patch_size``² patch of contiguous pixels,
placed at random inside the mask's bounding box of the first view, is rendered as part of
the batch (it replaces that many random rays, so a step renders the same number of rays)
and compared with the image by LPIPS-VGG when its weights are in the torch cache (the
paper's choice), else by the offline Inception perceptual distance
(:class:`~texvocab.metrics.inception_perceptual.InceptionPerceptual`); one log line
says which term is on (setting ``train.perceptual``; ``train.lambda_perceptual=0`` turns
it off).
Checkpoints are written atomically every ``train.checkpoint_every`` steps and at the end;
``--resume`` continues from the last one with the same random stream, so a killed run
ends with the same weights as an uninterrupted one.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from pathlib import Path

import torch
from tqdm import tqdm

from texvocab.capture.identity import IDENTITY_KEY, capture_identity, check_capture_identity
from texvocab.errors import TexvocabError
from texvocab.io.checkpoint import load_checkpoint, save_checkpoint
from texvocab.io.full_disk import disk_full_error, is_disk_full
from texvocab.method.pose_refinement import PoseRefinement
from texvocab.pipeline.girth_fit import CHECKPOINT_KEY as GIRTH_KEY
from texvocab.pipeline.girth_fit import apply_stored_girth, fit_girth
from texvocab.pipeline.lr_schedule import LearningRateSchedule
from texvocab.pipeline.model import build_model, load_stored_textures, load_textures, train_views
from texvocab.pipeline.param_groups import optimizer_groups
from texvocab.pipeline.perceptual_term import perceptual_term
from texvocab.pipeline.run_folder import RunLock
from texvocab.pipeline.settings import Settings, march_settings
from texvocab.pipeline.shell_fit import CHECKPOINT_KEY as SHELL_KEY
from texvocab.pipeline.shell_fit import apply_stored_shell, fit_shell
from texvocab.pipeline.train_log import TrainLog
from texvocab.pipeline.training_rays import FrameData, TrainingRays
from texvocab.pipeline.weight_average import TRAINED_KEY, WeightAverage
from texvocab.render import render_rays_banded

log = logging.getLogger("texvocab")
SCHEDULE = ("train.iterations", "train.max_minutes", "train.checkpoint_every")  # may change on --resume


class Trainer:
    """Owns the model, the optimiser, the random stream and the per-frame caches."""

    def __init__(self, capture, settings: Settings, out_dir: str | Path, progress: bool = True):
        self.capture, self.s, self.out = capture, settings, Path(out_dir)
        if capture.num_train < 1:
            raise TexvocabError(f"{capture.root}: no training frames")
        if settings.vocab.num_keys > capture.num_train:
            raise TexvocabError(
                f"setting vocab.num_keys={settings.vocab.num_keys}: "
                f"{capture.root} has only {capture.num_train} training frames "
                f"to take keys from (--set vocab.num_keys={capture.num_train} "
                "or fewer)"
            )
        if Path(out_dir).exists() and not Path(out_dir).is_dir():
            raise TexvocabError(f"--out {out_dir}: is a file; expected a run folder")
        self.views = train_views(capture, settings)
        capture.check_image_sizes(capture.train_frames, self.views)
        # the shell from the data (field.shell_coverage), before anything reads its width
        settings, self.shell_fit = fit_shell(capture, settings, self.views)
        self.s = settings
        # where the clothes stand off the body (data.body_girth), inside that shell
        self.girth_fit = fit_girth(capture, settings, self.views)
        self.textures = load_textures(capture, settings, progress)
        with torch.random.fork_rng():  # seeded initial weights; the global RNG is untouched
            torch.manual_seed(settings.train.seed)
            self.model = build_model(capture, settings, self.textures)
        if self.girth_fit is not None:
            self.model.set_girth(self.girth_fit.offsets)
        widths = getattr(self.shell_fit, "joint_widths", None)  # field.shell_shape=joints
        if widths is not None:
            self.model.set_shell_joints(widths)
        groups = optimizer_groups(self.model, settings.train)
        self.refine = None  # per-frame pose corrections (train.pose_refinement)
        if settings.train.pose_refinement != "off":
            self.refine = PoseRefinement(
                capture.num_train,
                capture.body.num_joints,
                settings.train.pose_refinement,
                settings.train.pose_refinement_span,
            )
            groups.append({"params": list(self.refine.parameters()), "lr": settings.train.pose_lr})
        self.optim = torch.optim.Adam(groups, lr=settings.train.lr)
        self.schedule = LearningRateSchedule(self.optim, settings.train.lr_decay)
        decay = settings.train.weight_average
        self.average = None if decay == 0 else WeightAverage(self.model, decay)
        self.gen = torch.Generator().manual_seed(settings.train.seed)
        self.step = 0
        self.saved_step: int | None = None  # the step the checkpoint on disk holds
        self.log_rows = TrainLog(self.out)  # RUN/train_log.csv, written with each checkpoint
        self.march = march_settings(settings, training=True)
        self.rays = TrainingRays(capture, settings, self.model, self.march)
        self.progress = progress
        self.perceptual = perceptual_term(settings)
        # data-parallel training (texvocab.pipeline.ddp): this process computes shard
        # `rank` of `world` of every step's batch; `sync` all-reduces the gradients and
        # `agree(x)` is the largest x over the processes (a time budget's stop, its clock)
        self.rank, self.world, self.sync, self.agree = 0, 1, None, None

    @property
    def frames(self) -> dict[int, FrameData]:
        """The per-frame caches built so far (:class:`TrainingRays`)."""
        return self.rays.frames

    @property
    def cache_seconds(self) -> float:
        return self.rays.cache_seconds

    @property
    def checkpoint_path(self) -> Path:
        return self.out / "checkpoint.pt"

    def _eikonal(self, fd: FrameData, ctx, n: int, evaluate: bool = True) -> torch.Tensor:
        verts = fd.ctx.vertices.detach()
        idx = torch.randint(len(verts), (n,), generator=self.gen)
        noise = torch.randn(n, 3, generator=self.gen) * (self.s.field.shell_width / 2)
        if not evaluate:  # the points are drawn (the stream stays shared), not used
            return torch.zeros(())
        pts = (verts[idx] + noise).requires_grad_(True)
        sdf, _, valid = self.model.sdf_and_color(ctx, pts, torch.nn.functional.normalize(noise, dim=-1))
        (grad,) = torch.autograd.grad(sdf.sum(), pts, create_graph=True)
        return ((grad[valid].norm(dim=-1) - 1) ** 2).mean() if valid.any() else sdf.sum() * 0

    def loss_terms(self) -> dict:
        """Draw one step's batch (frame, two training views, rays, the perceptual patch)
        from the run's random stream and return its loss terms as tensors (unweighted:
        ``color``, ``mask``, ``eikonal``, ``perceptual``), their weighted sum ``loss`` and
        ``field_evals`` and the step's ``frame`` (its :class:`FrameData`)."""
        s = self.s.train
        t = int(torch.randint(self.capture.num_train, (1,), generator=self.gen))
        fd = self.rays.frame(t)
        if getattr(self.model.pose_feature.encoder, "trainable", False):
            fd.ctx.features = self.model.pose_feature.feature_maps(fd.ctx.frames)
        ctx, prior = fd.ctx, torch.zeros(())
        if self.refine is not None:  # the frame's corrected pose, as a warp of the field's points
            cap = self.capture
            warp = self.refine.warp(t, cap.body, cap.poses[t], cap.trans[t], cap.shape())
            ctx, prior = dataclasses.replace(fd.ctx, warp=warp), self.refine.prior(t)
        vs = [self.views[int(i)] for i in torch.randint(len(self.views), (2,), generator=self.gen)]
        half = s.rays_per_batch // 2
        batch, p = [], 0
        if self.perceptual is not None:
            batch.append(self.rays.patch(fd, t, vs[0], s.patch_size, self.gen))
            p = int(round(len(batch[0][0]) ** 0.5))
        batch.append(self.rays.draw(fd, t, vs[0], max(1, half - p * p), self.gen))
        batch.append(self.rays.draw(fd, t, vs[1], s.rays_per_batch - half, self.gen))
        o, d, near, far, gt, m, t_band, cos, t_pass = (torch.cat(x) for x in zip(*batch, strict=True))
        # every process draws the whole batch from the shared stream and renders its shard:
        # the patch and the eikonal term on rank 0, the other rays dealt round; each term is
        # scaled so the mean over processes of the shards' gradients is the whole batch's
        total, gen, lead = len(o), self.gen, self.rank == 0
        if self.world > 1:
            rest = torch.arange(p * p, total)[self.rank :: self.world]
            mine = torch.cat([torch.arange(p * p), rest]) if lead else rest
            o, d, near, far, gt, m, t_band, cos, t_pass = (
                x[mine] for x in (o, d, near, far, gt, m, t_band, cos, t_pass)
            )
            gen = torch.Generator().manual_seed(s.seed * 1_000_003 + self.step * 64 + self.rank)
        share = self.world * len(o) / total
        out = render_rays_banded(
            self.model.for_pose(ctx),
            self.model.beta,
            o,
            d,
            near,
            far,
            t_band,
            cos,
            self.march,
            gen,
            fd.shell,
            t_passing=t_pass,
            index=fd.ctx.index,
            residual_misses=s.residual == "all",
        )
        eikonal = self._eikonal(fd, ctx, s.eikonal_points, evaluate=lead) if s.lambda_eikonal > 0 else None
        terms = {
            "color": ((out.rgb - gt) ** 2).mean(),
            "mask": (out.opacity - m).abs().mean(),
            "eikonal": torch.zeros(()) if eikonal is None else eikonal,
            "perceptual": torch.zeros(()),
        }
        if self.perceptual is not None and lead:
            patch, truth = (x[: p * p].T.reshape(1, 3, p, p) for x in (out.rgb, gt))
            terms["perceptual"] = self.perceptual(patch, truth).mean()
        terms["pose_prior"] = prior if lead else torch.zeros(())
        terms["loss"] = share * (
            s.lambda_color * terms["color"] + s.lambda_mask * terms["mask"]
        ) + self.world * (
            s.lambda_eikonal * terms["eikonal"]
            + s.lambda_perceptual * terms["perceptual"]
            + s.lambda_pose * terms["pose_prior"]
        )
        for name in ("loss", "color", "mask", "eikonal", "perceptual", "pose_prior"):
            if not torch.isfinite(terms[name]):
                ck = (
                    f"the last checkpoint {self.checkpoint_path} is intact"
                    if self.checkpoint_path.is_file()
                    else "no checkpoint was written"
                )
                raise TexvocabError(
                    f"training stopped at step {self.step + 1}: the {name} "
                    f"term is {float(terms[name].detach())}; {ck}"
                )
        terms["field_evals"], terms["banded"] = out.field_evals, out.banded
        terms["residual"] = out.residual
        terms["frame"] = fd
        return terms

    def train_step(self) -> dict:
        terms = self.loss_terms()
        self.optim.zero_grad(set_to_none=True)
        terms["loss"].backward()
        if self.sync is not None:
            self.sync()
        self.optim.step()
        if self.average is not None:
            self.average.update()
        if getattr(self.model.pose_feature.encoder, "trainable", False):
            # a trainable encoder's maps are recomputed whenever a frame is drawn again
            # (loss_terms), so the frame cache keeps none: kept for every training frame
            # they took ~9 GB with resnet34-scratch and the run was killed for memory
            terms["frame"].ctx.features = None
        self.step += 1
        psnr = float(-10 * torch.log10(terms["color"].detach().clamp(min=1e-10)))
        return {
            "loss": float(terms["loss"].detach()),
            "psnr": psnr,
            "eikonal": float(terms["eikonal"].detach()),
            "perceptual": float(terms["perceptual"].detach()),
            "beta": float(self.model.beta.detach()),
            "evals": terms["field_evals"],
            "banded": terms["banded"],
            "residual": terms["residual"],
        }

    def state(self) -> dict:
        weights, trained = self.model.state_dict(), None
        if self.average is not None:  # evaluation reads the average, --resume the raw weights
            weights, trained = self.average.checkpoint_weights(weights)
        return {
            "step": self.step,
            "settings": self.s.to_dict(),
            "capture": str(Path(self.capture.root).resolve()),
            "num_train": self.capture.num_train,
            IDENTITY_KEY: capture_identity(self.capture),
            "model": weights,
            **({} if trained is None else {TRAINED_KEY: trained}),
            "optimizer": self.optim.state_dict(),
            "vocab": self.model.pose_feature.vocab.to_dict(),
            "rng": {"torch": self.gen.get_state()},
            "lr_schedule": self.schedule.state(self.step),
            **({} if self.refine is None else {"pose_refinement": self.refine.state()}),
            **({GIRTH_KEY: self.model.girth.tolist()} if bool(self.model.girth.any()) else {}),
            **({SHELL_KEY: self.model.shell_joints.tolist()} if bool(self.model.shell_joints.any()) else {}),
        }

    def save(self) -> Path:
        """Write the checkpoint (rank 0). A full disk stops training with one line saying
        which step the intact checkpoint holds; the temporary file is removed."""
        if self.rank != 0:
            return self.checkpoint_path
        try:
            save_checkpoint(self.checkpoint_path, self.state())
        except (OSError, RuntimeError) as e:  # torch's writer: a RuntimeError from the OSError
            if not is_disk_full(e):
                raise
            raise disk_full_error(self.checkpoint_path, e, self._kept()) from None
        self.saved_step = self.step
        try:
            self.log_rows.write()
        except OSError as e:
            if not is_disk_full(e):
                raise
            raise disk_full_error(self.log_rows.path, e, self._kept()) from None
        return self.checkpoint_path

    def _kept(self) -> str:
        """What a failed save leaves: the last checkpoint's step, or that there is none."""
        if self.saved_step is not None:
            return f"the last checkpoint (step {self.saved_step}) is intact"
        if self.checkpoint_path.is_file():  # --overwrite: the run it was to replace
            return "no step of this run was saved; the checkpoint there is left as it was"
        return "no checkpoint was written"

    def resume(self, other_capture: bool = False) -> bool:
        """Load the last checkpoint in the output folder, if any; True when resumed. A
        checkpoint of another capture is refused unless ``other_capture``
        (:func:`~texvocab.capture.identity.check_capture_identity`)."""
        if not self.checkpoint_path.is_file():
            return False
        ck = load_checkpoint(self.checkpoint_path)
        check_capture_identity(ck, self.capture, self.checkpoint_path, other_capture)
        theirs, ours = Settings.from_dict(ck["settings"]).dotted(), self.s.dotted()
        differ = [k for k in ours if k not in SCHEDULE and theirs.get(k) != ours[k]]
        if differ:
            k = differ[0]
            raise TexvocabError(
                f"{self.checkpoint_path}: written with {k}={theirs.get(k)!r}, "
                f"this run asks for {k}={ours[k]!r}; resume with the same "
                "settings or choose another --out"
            )
        theirs = ck["vocab"].get("pose_condition", "global")  # absent: written before it
        ours = self.model.pose_feature.vocab.pose_condition  # existed, so global
        if theirs != ours:
            raise TexvocabError(
                f"{self.checkpoint_path}: written with pose_condition="
                f"{theirs!r} (the pose its vocabulary and field read), this "
                f"run builds pose_condition={ours!r}; choose another --out"
            )
        if int(ck["step"]) > self.s.train.iterations:
            raise TexvocabError(
                f"{self.checkpoint_path}: already at step {ck['step']}, past "
                f"train.iterations={self.s.train.iterations}; pass --iterations N > "
                f"{ck['step']} to extend it"
            )
        weights = load_stored_textures(self.model, ck["model"], self.checkpoint_path)
        self.model.load_state_dict(weights)
        if self.average is not None:
            self.average.load(weights, ck[TRAINED_KEY], self.model)
        apply_stored_girth(self.model, ck, self.checkpoint_path)
        apply_stored_shell(self.model, ck, self.checkpoint_path)
        if self.refine is not None:
            self.refine.load(ck["pose_refinement"])
        self.optim.load_state_dict(ck["optimizer"])
        self.schedule.load(ck.get("lr_schedule"))
        self.gen.set_state(ck["rng"]["torch"])
        self.step = self.saved_step = int(ck["step"])
        self.log_rows.resume(self.step)
        return True

    def run(self, until: int | None = None) -> list[dict]:
        """Train to ``settings.train.iterations`` (or ``until``) holding the run folder's lock
        (:class:`~texvocab.pipeline.run_folder.RunLock`); returns per-step logs."""
        if self.rank != 0:  # data-parallel: rank 0 holds the lock and writes checkpoints
            return self._run(until)
        with RunLock(self.out):
            return self._run(until)

    def _run(self, until: int | None) -> list[dict]:
        end = self.s.train.iterations if until is None else until
        logs = []
        bar = None
        budget = None if self.s.train.max_minutes is None else 60.0 * self.s.train.max_minutes
        if self.progress and budget is None:
            bar = tqdm(total=end, initial=self.step, desc="train", unit="step")
        elif self.progress:  # a time budget: the bar counts its seconds down, not steps
            bar = tqdm(
                total=round(budget),
                desc="train",
                unit="s",
                bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.0f}/{total:.0f} s of "
                "the time budget [{elapsed}<{remaining}{postfix}]",
            )
        t0, before = time.perf_counter(), self.log_rows.seconds
        self.schedule.begin(self.step, end, budget)
        try:  # the bar ends its line before any error line
            while self.step < end:
                elapsed = time.perf_counter() - t0
                if self.agree is not None and budget is not None:  # one clock for all
                    elapsed = self.agree(elapsed)
                over = budget is not None and elapsed > budget
                if over:
                    minutes = self.s.train.max_minutes
                    log.info("time budget of %.1f min reached at step %d", minutes, self.step)
                    break
                lr = self.schedule.update(self.step, elapsed)
                rec = self.train_step()
                logs.append({**rec, "lr": lr})
                self.log_rows.add(self.step, before + time.perf_counter() - t0, rec, lr)
                if bar is not None:
                    if budget is None:
                        bar.update(1)
                    else:
                        bar.update(min(time.perf_counter() - t0, bar.total) - bar.n)
                    bar.set_postfix(
                        step=self.step,
                        loss=f"{rec['loss']:.4f}",
                        psnr=f"{rec['psnr']:.2f}",
                        beta=f"{rec['beta']:.4f}",
                        lr=f"{lr:.2e}",
                    )
                if self.step % self.s.train.checkpoint_every == 0 or self.step == end:
                    self.save()
        finally:
            if bar is not None:
                bar.close()
        if logs and self.step % self.s.train.checkpoint_every:
            self.save()  # stopped by the time budget, or at an end between intervals
        if logs:
            log.info("trained %d steps in %.1f s", len(logs), time.perf_counter() - t0)
        return logs
