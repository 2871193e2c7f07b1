"""The rays training does not band (texvocab.render.render_rays_banded with an
``index``): close silhouette rays and failed bands as residual rays (three evaluations,
differentiable), band rays from the probe and the Newton point, both with per-ray origins
(a training batch mixes two views), and the trainer's knobs for them (``train_residual``,
``train_band_newton``; runs written before them marched and used the 5-sample band)."""

import pytest
import torch
from render_cases import MARCH, psnr, rays_of
from train_cases import flat_dict, flat_settings, tiny_settings

from texvocab.capture import open as open_capture
from texvocab.errors import TexvocabError
from texvocab.geometry.surface import SurfaceIndex
from texvocab.pipeline.settings import Settings, TrainSettings, march_settings
from texvocab.pipeline.train import Trainer
from texvocab.render import render_rays, render_rays_banded
from texvocab.render.guided.band import newton_band, sample_band
from texvocab.render.guided.residual import render_residual

OLD_BAND = MARCH.replace(band_newton=False)


def _index(body):
    return SurfaceIndex(body["v"], body["f"])


def test_residual_rays_match_the_marcher_for_fewer_evaluations(body):
    o, d, near, far, t_band, cos, t_pass = rays_of(body, body["camera"])
    field = body["field"]
    with torch.no_grad():
        ref = render_rays(field, o, d, near, far, MARCH, None, body["shell"])
        marched = render_rays_banded(
            field, field.beta, o, d, near, far, t_band, cos, MARCH, None, body["shell"], t_passing=t_pass
        )
        resid = render_rays_banded(
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
            t_passing=t_pass,
            index=_index(body),
        )
        off = render_rays_banded(
            field,
            field.beta,
            o,
            d,
            near,
            far,
            t_band,
            cos,
            MARCH.replace(residual_rays=False),
            None,
            body["shell"],
            t_passing=t_pass,
            index=_index(body),
        )
        hits = render_rays_banded(
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
            t_passing=t_pass,
            index=_index(body),
            residual_misses=False,
        )
    assert 0 < hits.residual < resid.residual  # misses are marched, the hits are not
    assert resid.field_evals < hits.field_evals < marched.field_evals
    assert marched.residual == 0 and off.residual == 0
    assert torch.equal(off.rgb, marched.rgb) and off.field_evals == marched.field_evals
    assert resid.residual > 20 and resid.banded == marched.banded
    assert resid.field_evals < 0.6 * marched.field_evals
    assert psnr(resid.rgb, ref.rgb) > 38
    assert (resid.opacity - ref.opacity).abs().max() < 0.15


def test_residual_rays_carry_gradients_to_the_colour_and_beta(body):
    """Only the rays that are not band rays (passing close, grazing, failed bands): the
    colour's gradient matches the marcher's, and β gets one."""
    o, d, near, far, t_band, cos, t_pass = rays_of(body, body["camera"])
    keep = torch.isfinite(t_pass[:, 0])
    o, d, near, far, t_band, cos, t_pass = (x[keep] for x in (o, d, near, far, t_band, cos, t_pass))
    field = body["field"]
    grads = {}
    for name, index in (("residual", _index(body)), ("marched", None)):
        field.albedo = field.albedo.detach().clone().requires_grad_(True)
        field.beta = field.beta.detach().clone().requires_grad_(True)
        out = render_rays_banded(
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
            t_passing=t_pass,
            index=index,
        )
        out.rgb.sum().backward()
        grads[name] = (field.albedo.grad.clone(), field.beta.grad.clone(), out.residual)
    field.albedo, field.beta = field.albedo.detach(), field.beta.detach()
    (ga, gb, n), (ma, mb, _) = grads["residual"], grads["marched"]
    assert n > 10
    assert torch.isfinite(ga).all() and torch.isfinite(gb) and float(gb) != 0.0
    assert torch.allclose(ga, ma, rtol=0.03)
    assert abs(float(gb) - float(mb)) < 0.1 * abs(float(mb))


def test_per_ray_origins_give_what_one_origin_gives(body):
    o, d, near, far, t_band, cos, t_pass = rays_of(body, body["camera"])
    field = body["field"]
    band = torch.nonzero(torch.isfinite(t_band)).squeeze(1)[:100]
    with torch.no_grad():
        t_hit = t_band[band]
        sdf0, rgb0 = field.sdf_rgb(o[band] + t_hit[:, None] * d[band], d[band])
        one = newton_band(field, o[0], d[band], t_hit, cos[band], sdf0, rgb0, field.beta, MARCH)
        each = newton_band(field, o[band], d[band], t_hit, cos[band], sdf0, rgb0, field.beta, MARCH)
        probes = torch.cat([t_hit[:, None], torch.full_like(t_hit, torch.inf)[:, None]], 1)
        sdfs = torch.cat([sdf0[:, None], torch.full_like(sdf0, torch.inf)[:, None]], 1)
        r_one = render_residual(
            field, _index(body), o[0], d[band], near[band], far[band], probes, sdfs, float(field.beta), MARCH
        )
        r_each = render_residual(
            field, _index(body), o[band], d[band], near[band], far[band], probes, sdfs, field.beta, MARCH
        )
    assert torch.equal(o[band], o[0].expand(len(band), 3))  # one camera
    for a, b in zip(one[:4] + r_one[:4], each[:4] + r_each[:4], strict=True):
        assert torch.allclose(a.float(), b.float(), atol=1e-6)
    assert one[3].any() and r_one[3].any()


def test_newton_band_rays_take_three_evaluations_the_old_band_five(body):
    o, d, near, far, t_band, cos, _ = rays_of(body, body["camera"])
    keep = torch.isfinite(t_band)
    o, d, near, far, t_band, cos = (x[keep] for x in (o, d, near, far, t_band, cos))
    field = body["field"]
    with torch.no_grad():
        ref = render_rays(field, o, d, near, far, MARCH, None, body["shell"])
        sdf0, rgb0 = field.sdf_rgb(o + t_band[:, None] * d, d)
        runs = {}
        for m in (MARCH, OLD_BAND):
            out = render_rays_banded(field, field.beta, o, d, near, far, t_band, cos, m, None, body["shell"])
            ok = (
                newton_band(field, o, d, t_band, cos, sdf0, rgb0, field.beta, m)
                if m.band_newton
                else sample_band(field, o, d, t_band, cos, sdf0, rgb0, field.beta, m)
            )[3]
            rest = render_rays(field, o[~ok], d[~ok], near[~ok], far[~ok], m, None, body["shell"])
            per_ray = 3 if m.band_newton else 1 + m.band_samples
            assert out.banded == int(ok.sum()) > 0.8 * len(o)
            assert out.field_evals == per_ray * len(o) + rest.field_evals
            assert psnr(out.rgb, ref.rgb) > 40
            runs[m.band_newton] = out
    assert not torch.equal(runs[True].rgb, runs[False].rgb)


@pytest.mark.parametrize(
    "knobs",
    [
        {},
        {"train_residual": "hits"},
        {"train_residual": "off"},
        {"train_residual": "off", "train_band_newton": False},
    ],
)
def test_training_uses_residual_and_newton_rays_by_their_knobs(capture, tmp_path, knobs):
    cap = open_capture(capture)
    trainer = Trainer(cap, tiny_settings(iterations=3, **knobs), tmp_path / "run", progress=False)
    m = trainer.march
    assert m.residual_rays == (knobs.get("train_residual", "all") != "off")
    assert m.band_newton == knobs.get("train_band_newton", True)
    before = [p.detach().clone() for p in trainer.model.parameters() if p.requires_grad]
    logs = trainer.run()
    assert (sum(r["residual"] for r in logs) > 0) == m.residual_rays
    assert sum(r["banded"] for r in logs) > 0
    after = [p for p in trainer.model.parameters() if p.requires_grad]
    assert any(not torch.equal(a, b) for a, b in zip(before, after, strict=True))


def test_old_runs_marched_and_used_the_five_sample_band():
    old = flat_dict(Settings())
    for key in ("train_residual", "train_band_newton"):
        del old[key]
    s = Settings.from_dict(old)
    assert s.train.residual == "off" and s.train.band_newton is False
    m = march_settings(s, training=True)
    assert not m.residual_rays and not m.band_newton
    assert march_settings(Settings(), training=True).residual_rays
    # the shell guide bands nothing, so it has no residual rays either
    assert not march_settings(flat_settings(train_guide="shell"), training=True).residual_rays
    # render knobs do not follow the training ones
    assert march_settings(flat_settings(train_residual="off", train_band_newton=False)).residual_rays
    with pytest.raises(TexvocabError, match="train.residual"):
        TrainSettings(residual="some")


def test_train_shell_voxel_sets_the_training_shells_grid(capture, tmp_path):
    cap = open_capture(capture)
    shells = {}
    for voxel in (0.01, 0.015):
        trainer = Trainer(
            cap,
            tiny_settings(iterations=1, train_shell_voxel=voxel),
            tmp_path / f"run{voxel}",
            progress=False,
        )
        trainer.run()
        (fd,) = trainer.frames.values()
        shells[voxel] = fd.shell
        assert fd.shell.voxel == voxel and fd.shell.has_grid
    fine, coarse = shells[0.01], shells[0.015]
    # the coarser grid holds the finer one's shell (both keep every point within δ)
    idx = torch.nonzero(fine.occupied)
    centres = torch.from_numpy(fine.origin) + (idx + 0.5) * 0.01
    assert coarse.contains(centres.float()).float().mean() > 0.99
    assert coarse.occupied.sum() * 0.015**3 > fine.occupied.sum() * 0.01**3
    old = flat_dict(Settings())
    del old["train_shell_voxel"]
    assert Settings.from_dict(old).train.shell_voxel == 0.01  # runs before the setting
    with pytest.raises(TexvocabError, match="train.shell_voxel"):
        TrainSettings(shell_voxel=0.0)


def test_views_keep_per_hit_arrays_and_give_every_pixels_rays(capture, tmp_path):
    """A view's cache stores its ray bounds and band per shell hit only, yet every pixel's
    rays are what the per-pixel arrays gave: the misses an empty interval, no band, no
    passing places; colours to 8-bit precision (the images are 8-bit PNGs)."""
    from texvocab.render import plan_surface

    cap = open_capture(capture)
    trainer = Trainer(cap, tiny_settings(), tmp_path / "run", progress=False)
    fd = trainer.rays.frame(0)
    vd = trainer.rays.view(fd, 0, 0)
    n = len(vd.mask)
    assert 0 < len(vd.near) == int(vd.hit.sum()) < n
    near, far, t_band, cos, t_passing = vd.rays(torch.arange(n))
    b = fd.shell.image_bounds(cap.cameras[0])
    miss = ~b.hit.view(-1)
    assert torch.equal(near, b.near.view(-1)) and (far[miss] == 0).all()
    assert torch.isinf(t_band[miss]).all() and torch.isinf(t_passing[miss]).all()
    _, dirs = trainer.rays.rays_of(0)
    delta = trainer.s.field.shell_width
    plan = plan_surface(
        fd.ctx.vertices.detach(), cap.body.faces, cap.cameras[0], dirs, delta, delta, trainer.march.min_cos
    )
    hit = b.hit.view(-1)
    assert torch.equal(cos[hit], plan.cos.half().float()[hit])
    truth = torch.from_numpy(cap.image(0, 0)).view(-1, 3)
    assert (vd.colours(torch.arange(n)) - truth).abs().max() < 0.5 / 255 + 1e-6
