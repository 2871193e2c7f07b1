"""The surface band shared by the guided renderer and training
(texvocab.render.render_rays_banded): the same colours as the shell marcher for far
fewer evaluations, gradients that reach the field and β, passing rays that cost two probes,
and the trainer's use of it (``train_guide``)."""

import pytest
import torch
from render_cases import MARCH, psnr, rays_of
from train_cases import flat_dict, tiny_settings

from texvocab.capture import open as open_capture
from texvocab.pipeline.settings import Settings, TrainSettings
from texvocab.pipeline.train import Trainer
from texvocab.render import render_rays, render_rays_banded


def test_banded_rays_match_the_shell_marcher_for_far_fewer_evaluations(body):
    o, d, near, far, t_band, cos, t_pass = rays_of(body, body["camera"])
    field = body["field"]
    with torch.no_grad():
        ref = render_rays(field, o, d, near, far, MARCH, None, body["shell"])
        out = render_rays_banded(
            field, field.beta, o, d, near, far, t_band, cos, MARCH, None, body["shell"], t_passing=t_pass
        )
    assert out.banded > 0.5 * int(torch.isfinite(t_band).sum()) > 0
    assert psnr(out.rgb, ref.rgb) > 40
    assert (out.opacity - ref.opacity).abs().max() < 0.05
    assert out.field_evals < 0.5 * ref.field_evals
    shell_only = render_rays_banded(
        field,
        field.beta,
        o,
        d,
        near,
        far,
        torch.full_like(t_band, torch.inf),
        cos,
        MARCH,
        None,
        body["shell"],
    )
    assert shell_only.banded == 0 and shell_only.field_evals == ref.field_evals


@pytest.mark.parametrize("newton", [True, False])
def test_banded_gradients_reach_the_colour_and_beta_like_the_marcher(body, newton):
    """Both band kinds: the probe and the Newton point, or band_samples samples."""
    march = MARCH.replace(band_newton=newton)
    o, d, near, far, t_band, cos, t_pass = rays_of(body, body["camera"])
    band = torch.isfinite(t_band)
    o, d, near, far, t_band, cos = (x[band] for x in (o, d, near, far, t_band, cos))
    grads = {}
    for name in ("band", "shell"):
        field = body["field"]
        field.albedo = field.albedo.detach().clone().requires_grad_(True)
        field.beta = field.beta.detach().clone().requires_grad_(True)
        t = t_band if name == "band" else torch.full_like(t_band, torch.inf)
        out = render_rays_banded(field, field.beta, o, d, near, far, t, cos, march, None, body["shell"])
        (out.rgb.sum() + out.rgb[:, 0].pow(2).sum()).backward()
        grads[name] = (field.albedo.grad.clone(), field.beta.grad.clone())
    field.albedo, field.beta = field.albedo.detach(), field.beta.detach()
    (ga, gb), (sa, _) = grads["band"], grads["shell"]
    assert torch.isfinite(ga).all() and float(ga.abs().min()) > 0
    assert torch.allclose(ga, sa, rtol=0.02)  # band rays: the colour's gradient is the same
    assert torch.isfinite(gb) and float(gb) != 0.0


def test_passing_rays_cost_two_probes_and_show_the_background(body):
    """Rays that pass the body farther than miss_margin β read the background for two
    evaluations each; rays that pass close are marched."""
    cam = body["camera"]
    o, d, near, far, t_band, cos, t_pass = rays_of(body, cam)
    field = body["field"]
    passing = torch.isfinite(t_pass[:, 0])
    assert passing.sum() > 10
    idx = torch.nonzero(passing).squeeze(1)
    bg = (0.1, 0.2, 0.3)
    with torch.no_grad():
        out = render_rays_banded(
            field,
            field.beta,
            o[idx],
            d[idx],
            near[idx],
            far[idx],
            t_band[idx],
            cos[idx],
            MARCH,
            None,
            body["shell"],
            bg,
            t_pass[idx],
        )
        probe = field.sdf((o[idx, None] + t_pass[idx, :, None] * d[idx, None]).reshape(-1, 3))
    far_away = probe.view(-1, 2).min(1).values > MARCH.miss_margin * float(field.beta)
    assert 0 < int(far_away.sum()) < len(idx)  # both kinds occur on this view
    assert torch.allclose(out.rgb[far_away], torch.tensor(bg).expand(int(far_away.sum()), 3))
    assert (out.opacity[far_away] == 0).all()
    marched = render_rays(
        field,
        o[idx][~far_away],
        d[idx][~far_away],
        near[idx][~far_away],
        far[idx][~far_away],
        MARCH,
        None,
        body["shell"],
        bg,
    )
    assert out.field_evals == 2 * len(idx) + marched.field_evals
    assert torch.allclose(out.rgb[~far_away], marched.rgb, atol=1e-6)


def test_band_rays_behind_a_passed_surface_take_the_band_only_when_it_reads_far(body):
    """A band ray that also passes a surface (behind an occlusion edge) is banded when both
    passing probes read beyond miss_margin β, and marched as the shell marcher does when
    one of them reads close."""
    o, d, near, far, t_band, cos, _ = rays_of(body, body["camera"])
    idx = torch.nonzero(torch.isfinite(t_band)).squeeze(1)[:200]
    o, d, near, far, t_band, cos = (x[idx] for x in (o, d, near, far, t_band, cos))
    field = body["field"]
    with torch.no_grad():
        alone = render_rays_banded(
            field, field.beta, o, d, near, far, t_band, cos, MARCH, None, body["shell"]
        )
        # passed surface far away: probes in front of the body (the ray's shell entry)
        far_probes = torch.stack([near, near], 1)
        far_away = render_rays_banded(
            field, field.beta, o, d, near, far, t_band, cos, MARCH, None, body["shell"], t_passing=far_probes
        )
        # a close passed surface: probes on the surface itself
        close = render_rays_banded(
            field,
            field.beta,
            o,
            d,
            near,
            far,
            t_band,
            cos,
            MARCH,
            None,
            body["shell"],
            t_passing=torch.stack([t_band, t_band], 1),
        )
        marched = render_rays(field, o, d, near, far, MARCH, None, body["shell"])
        entry = field.sdf(o + near[:, None] * d)
    assert (entry > MARCH.miss_margin * float(field.beta)).all()
    assert far_away.banded == alone.banded > 0.5 * len(idx)
    assert torch.equal(far_away.rgb, alone.rgb)
    assert far_away.field_evals == alone.field_evals + 2 * len(idx)
    assert close.banded == 0
    assert torch.allclose(close.rgb, marched.rgb, atol=1e-6)
    assert close.field_evals == marched.field_evals + 2 * len(idx)


@pytest.mark.parametrize("guide", ["raster", "shell"])
def test_training_takes_the_band_only_with_train_guide_raster(capture, tmp_path, guide):
    cap = open_capture(capture)
    trainer = Trainer(cap, tiny_settings(train_guide=guide, iterations=3), tmp_path / "run", progress=False)
    before = [p.detach().clone() for p in trainer.model.parameters() if p.requires_grad]
    logs = trainer.run()
    banded = sum(r["banded"] for r in logs)
    assert trainer.cache_seconds > 0  # cache builds are timed (bench/train_speed.py)
    assert (banded > 0) == (guide == "raster")
    after = [p for p in trainer.model.parameters() if p.requires_grad]
    assert any(not torch.equal(a, b) for a, b in zip(before, after, strict=True))
    for fd in trainer.frames.values():
        for vd in fd.views.values():  # rays outside the mask never take the band
            _, _, t_band, _, t_passing = vd.rays(torch.arange(len(vd.mask)))
            assert not (torch.isfinite(t_band) & ~vd.mask).any()
            # inside the mask only band rays (behind an occlusion edge) get passing probes
            assert not (torch.isfinite(t_passing[:, 0]) & vd.mask & ~torch.isfinite(t_band)).any()
            if guide == "shell":
                assert not torch.isfinite(t_band).any()


def test_train_guide_is_checked_and_old_checkpoints_trained_with_the_shell():
    from texvocab.errors import TexvocabError

    with pytest.raises(TexvocabError, match="train.guide"):
        TrainSettings(guide="mesh")
    old = flat_dict(Settings())
    del old["train_guide"]
    assert Settings.from_dict(old).train.guide == "shell"
    from texvocab.pipeline.settings import march_settings

    def train(**kw):
        return Settings(train=TrainSettings(**kw))

    assert march_settings(Settings(), training=True).coarse_samples == 9  # the default
    assert (
        march_settings(train(coarse_samples=None), training=True).coarse_samples
        == Settings().render.coarse_samples
        == 18
    )  # none: the render's coarse_samples
    assert march_settings(train(coarse_samples=9), training=True).coarse_samples == 9
    assert march_settings(train(coarse_samples=9)).coarse_samples == 18  # rendering
    del old["train_coarse_samples"]  # written before the setting: trained at coarse_samples
    assert Settings.from_dict(old).train.coarse_samples is None
    with pytest.raises(TexvocabError, match="train.coarse_samples"):
        Settings().with_overrides(["train_coarse_samples=2.5"])
    assert Settings().with_overrides(["train_coarse_samples=none"]).train.coarse_samples is None
    assert Settings().with_overrides(["train_coarse_samples=12"]).train.coarse_samples == 12
