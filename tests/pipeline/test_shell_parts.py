"""A shell fitted part by part (field.shell_shape=joints): each body part gets the narrowest
width that reaches field.shell_coverage of the mask pixels whose rays come closest to it,
the field is empty beyond its part's width outside the body, and the widths live in the
checkpoint. The stand-in for clothes off one part: the tiny capture's masks dilated in the
lower half of each image only (the legs: wide trousers)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy import ndimage
from train_cases import tiny_settings

from texvocab.body.parts import JOINT_NAMES
from texvocab.capture import open as open_capture
from texvocab.capture.silhouette import posed_vertices, ray_surface_distances, ray_surface_reach
from texvocab.errors import TexvocabError
from texvocab.geometry.raster import rasterize_mesh
from texvocab.pipeline.model import train_views
from texvocab.pipeline.settings import Settings
from texvocab.pipeline.shell_fit import CHECKPOINT_KEY, apply_stored_shell, fit_shell

LEGS = [JOINT_NAMES.index(n) for n in JOINT_NAMES if n.split("_")[-1] in ("hip", "knee", "ankle", "foot")]
#: the parts above the body's middle in the tiny capture's walk (its hands hang below it)
UPPER = [
    JOINT_NAMES.index(n) for n in ("head", "left_shoulder", "right_shoulder", "left_elbow", "right_elbow")
]
HEAD = [JOINT_NAMES.index(n) for n in ("head", "neck")]
PARTS = Settings().with_overrides(["field.shell_shape=joints"])


@pytest.fixture(autouse=True)
def every_pixel(monkeypatch):
    """The fit reads every mask pixel: the tiny capture's 64² masks hold a few hundred."""
    import texvocab.pipeline.shell_fit as shell_fit

    monkeypatch.setattr(shell_fit, "PIXEL_STRIDE", 1)


def wide_trousers(root, pixels: int = 2):
    """The capture at ``root`` with its masks dilated by ``pixels`` below the body's
    middle row only (64² images: ~3 cm a pixel)."""
    cap = open_capture(root)
    mask = cap.mask

    def grown(v, t):
        m = np.asarray(mask(v, t), bool)
        rows = np.nonzero(m.any(1))[0]
        middle = (rows.min() + rows.max()) // 2
        out = m.copy()
        out[middle:] = ndimage.binary_dilation(m, iterations=pixels)[middle:]
        return out

    cap.mask = grown
    return cap


def test_each_ray_reaches_the_part_it_comes_closest_to(capture):
    cap = open_capture(capture)
    body, cam = cap.body, cap.cameras[0]
    verts = next(posed_vertices(body, cap.poses[[0]], cap.trans[[0]]))
    ys, xs = np.mgrid[0 : cam.height : 2, 0 : cam.width : 2]
    pix = np.stack([xs.ravel(), ys.ravel()], 1)
    dist, joint = ray_surface_reach(verts, body.faces, body.weights, cam, pix, max_distance=0.1)
    assert np.array_equal(dist, ray_surface_distances(verts, body.faces, cam, pix, max_distance=0.1))
    raster = rasterize_mesh(verts, body.faces, cam)
    inside = raster.mask.numpy()[pix[:, 1], pix[:, 0]]
    assert inside.sum() > 50 and (dist[inside] == 0).all() and (joint[inside] >= 0).all()
    near = ~inside & np.isfinite(dist)
    assert near.sum() > 50 and (joint[near] >= 0).all() and (joint[~np.isfinite(dist)] == -1).all()
    # below the body's middle the rays come closest to the legs, at the top to the head
    top, bottom = pix[:, 1].min(), pix[:, 1].max()
    rows = np.nonzero(inside)[0]
    low = rows[pix[rows, 1] > np.percentile(pix[rows, 1], 90)]
    high = rows[pix[rows, 1] < np.percentile(pix[rows, 1], 5)]
    assert top < bottom and np.isin(joint[low], LEGS).mean() > 0.9
    assert np.isin(joint[high], HEAD).mean() > 0.9


def test_clothes_off_the_legs_widen_the_legs_shell_only(capture):
    cap = wide_trousers(capture)
    fitted, fit = fit_shell(cap, PARTS, train_views(cap, PARTS))
    widths = fit.joint_widths
    assert widths.shape == (len(JOINT_NAMES),) and fitted.field.shell_width == pytest.approx(widths.max())
    assert widths[LEGS].max() > 0.04 and np.allclose(widths[UPPER], 0.04)
    for name in ("knee", "ankle"):  # mirror twins share a width
        assert widths[JOINT_NAMES.index("left_" + name)] == widths[JOINT_NAMES.index("right_" + name)]
    assert "per part 4-" in fit.line(0.97)
    # the one width for the whole body reaches at most as far as the widest part
    uniform, one = fit_shell(cap, Settings(), train_views(cap, PARTS))
    assert not hasattr(one, "joint_widths") and 0.04 < uniform.field.shell_width <= fitted.field.shell_width


def test_beyond_its_parts_width_the_field_is_empty_outside_the_body(capture, tmp_path):
    from texvocab.pipeline.train import Trainer

    cap = wide_trousers(capture)
    s = tiny_settings(iterations=1).with_overrides(["field.shell_shape=joints"])
    trainer = Trainer(cap, s, tmp_path / "run", progress=False)
    model = trainer.model
    fitted = torch.as_tensor(trainer.shell_fit.joint_widths, dtype=torch.float32)
    assert torch.allclose(model.shell_joints, fitted)
    width = model.settings.shell_width
    assert width > 0.05
    widths = torch.full_like(fitted, 0.04)
    widths[LEGS] = width
    model.set_shell_joints(widths)
    ctx = model.pose_feature.context(torch.as_tensor(cap.poses[0]), torch.as_tensor(cap.trans[0]))
    verts = cap.posed_body(0).vertices[0]
    normals = _normals(verts, cap.body.faces)
    w = cap.body.weights
    legs, upper = (torch.nonzero(w[:, group].sum(1) > 0.99).squeeze(1)[::20] for group in (LEGS, UPPER))
    out = 0.5 * (0.04 + width)  # beyond 4 cm, within the legs' width

    def clear(idx):  # vertices whose point ``out`` along the normal is that far from the body
        d = ctx.index.project((verts[idx] + out * normals[idx]).double().numpy()).distance
        return idx[torch.as_tensor(d > out - 0.002)]

    legs, upper = clear(legs), clear(upper)
    pts = torch.cat([verts[legs] + out * normals[legs], verts[upper] + out * normals[upper]])
    inner = verts[upper] - 0.01 * normals[upper]
    dirs = torch.nn.functional.normalize(torch.ones_like(pts), dim=-1)
    field = model.for_pose(ctx)
    with torch.no_grad():
        sdf, _ = field.sdf_rgb(pts, dirs)
        _, _, valid_in = model.sdf_and_color(ctx, inner, dirs[: len(inner)])
        _, _, valid = model.sdf_and_color(ctx, pts, dirs)
        model.set_shell_joints(torch.zeros_like(widths))  # one width: all of them in
        _, _, valid_one = model.sdf_and_color(ctx, pts, dirs)
    n = len(legs)
    assert n > 10 and len(upper) > 10
    assert valid[:n].float().mean() > 0.9 and valid[n:].float().mean() < 0.1
    assert (sdf[n:][~valid[n:]] == width).all() and (sdf[:n][valid[:n]] < width).all()
    assert valid_one.float().mean() > 0.9 and valid_in.all()  # the body's inside stays
    with pytest.raises(ValueError, match="at most field.shell_width"):
        model.set_shell_joints(torch.full_like(widths, width + 0.01))


def test_the_widths_go_with_the_checkpoint(capture, tmp_path):
    from texvocab.io.checkpoint import load_checkpoint
    from texvocab.pipeline.avatar import load_avatar
    from texvocab.pipeline.train import Trainer

    cap = wide_trousers(capture)
    s = tiny_settings(iterations=1).with_overrides(["field.shell_shape=joints"])
    trainer = Trainer(cap, s, tmp_path / "run", progress=False)
    trainer.run()
    ck = load_checkpoint(trainer.checkpoint_path)
    assert np.allclose(ck[CHECKPOINT_KEY], trainer.shell_fit.joint_widths, atol=1e-6)
    avatar = load_avatar(trainer.checkpoint_path, open_capture(capture))
    assert torch.allclose(avatar.model.shell_joints, trainer.model.shell_joints)
    more = tiny_settings(iterations=2).with_overrides(["field.shell_shape=joints"])
    again = Trainer(cap, more, tmp_path / "run", progress=False)
    assert again.resume() and torch.allclose(again.model.shell_joints, trainer.model.shell_joints)
    with pytest.raises(TexvocabError, match=CHECKPOINT_KEY):
        apply_stored_shell(avatar.model, {CHECKPOINT_KEY: [0.04] * 23}, "ck.pt")
    plain = Trainer(open_capture(capture), tiny_settings(iterations=1), tmp_path / "plain", progress=False)
    plain.run()
    assert CHECKPOINT_KEY not in load_checkpoint(plain.checkpoint_path)
    assert not plain.model.shell_joints.any()


def test_checkpoints_before_the_knob_read_as_one_width():
    d = Settings().to_dict()
    del d["field"]["shell_shape"]
    assert Settings.from_dict(d).field.shell_shape == "uniform"


def _normals(verts: torch.Tensor, faces: torch.Tensor) -> torch.Tensor:
    from texvocab.body.girth import vertex_normals

    return vertex_normals(verts, faces).float()
