"""The compiled rasteriser (texvocab.geometry.raster) against the vectorised torch
z-buffer it replaced (kept here as the reference): same faces, barycentrics and depths
on the default body seen from its cameras and on random triangle soups, and the
z-buffer's rules (nearest wins, faces behind the camera skipped, empty pixels)."""

import numpy as np
import torch

from texvocab.geometry.raster import rasterize, rasterize_mesh


def reference_rasterize(pix, depth, faces, width, height):
    """The torch rasteriser of the first texvocab versions: (face, bary, depth) (H·W, ...)."""
    pix, faces = pix.double(), faces.long()
    front = (depth[faces] > 1e-6).all(1)
    face_ids = torch.nonzero(front).squeeze(1)
    tri = pix[faces[face_ids]]
    inv_z = 1.0 / depth.double()[faces[face_ids]]
    lo, hi = torch.ceil(tri.amin(1)).long(), torch.floor(tri.amax(1)).long()
    lo[:, 0].clamp_(0, width - 1)
    lo[:, 1].clamp_(0, height - 1)
    hi[:, 0].clamp_(max=width - 1)
    hi[:, 1].clamp_(max=height - 1)
    bw, bh = (hi - lo + 1).clamp(min=0).unbind(1)
    n = bw * bh
    local = torch.repeat_interleave(torch.arange(len(tri)), n)
    k = torch.arange(len(local)) - torch.repeat_interleave(torch.cumsum(n, 0) - n, n)
    px, py = lo[local, 0] + k % bw[local], lo[local, 1] + k // bw[local]
    a, b, c = tri[local, 0], tri[local, 1], tri[local, 2]
    area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    x, y = px.double(), py.double()
    w0 = (b[:, 0] - x) * (c[:, 1] - y) - (b[:, 1] - y) * (c[:, 0] - x)
    w1 = (c[:, 0] - x) * (a[:, 1] - y) - (c[:, 1] - y) * (a[:, 0] - x)
    ok = area.abs() > 1e-12
    bary = torch.stack([w0, w1, area - w0 - w1], 1) / torch.where(ok, area, 1.0)[:, None]
    inside = ok & (bary >= -1e-9).all(1)
    local, bary, idx = local[inside], bary[inside], (py * width + px)[inside]
    z = 1.0 / (bary * inv_z[local]).sum(1)
    best = torch.full((height * width,), torch.inf, dtype=torch.float64)
    best.scatter_reduce_(0, idx, z, reduce="amin")
    face = torch.full((height * width,), -1, dtype=torch.long)
    out = torch.zeros(height * width, 3, dtype=torch.float64)
    win = z <= best[idx]
    face[idx[win]], out[idx[win]] = face_ids[local[win]], bary[win]
    return face, out.float(), best.float()


def assert_same(r, ref, width, height, max_tie_share=0.01):
    face, bary, depth = ref
    assert torch.equal(torch.isinf(r.depth.view(-1)), torch.isinf(depth))
    assert torch.allclose(r.depth.view(-1), depth, rtol=1e-6)
    same = r.face.view(-1) == face
    # pixels on a shared edge or vertex meet two faces at the same depth: either may win
    assert (~same).float().mean() <= max_tie_share
    assert torch.allclose(r.bary.view(-1, 3)[same], bary[same], atol=1e-6)


def test_compiled_rasteriser_matches_the_torch_reference_on_the_body(body):
    for cam in (body["camera"].scaled(4.0), body["camera"].scaled(2.0)):  # 256², 128²
        r = rasterize_mesh(body["v"], body["f"], cam)
        pix, z = cam.project(body["v"].numpy())
        ref = reference_rasterize(torch.as_tensor(pix), torch.as_tensor(z), body["f"], cam.width, cam.height)
        assert r.mask.sum() > 1000 * cam.width / 256
        assert_same(r, ref, cam.width, cam.height)


def test_compiled_rasteriser_matches_the_torch_reference_on_triangle_soups():
    rng = np.random.default_rng(0)
    for trial in range(5):
        n = 300
        pix = torch.as_tensor(rng.uniform(-20, 84, (3 * n, 2)))
        depth = torch.as_tensor(rng.uniform(-0.5, 3.0, 3 * n))  # some behind the camera
        faces = torch.arange(3 * n).view(n, 3)
        r = rasterize(pix, depth, faces, 64, 48)
        ref = reference_rasterize(pix, depth, faces, 64, 48)
        assert r.mask.sum() > 500
        assert_same(r, ref, 64, 48, max_tie_share=0.0)


def test_zbuffer_keeps_the_nearest_and_skips_faces_behind_the_camera():
    pix = torch.tensor([[0.0, 0.0], [20.0, 0.0], [0.0, 20.0]] * 3)
    depth = torch.tensor([2.0] * 3 + [1.0] * 3 + [-1.0] * 3)
    faces = torch.arange(9).view(3, 3)
    r = rasterize(pix, depth, faces, 32, 32)
    assert int(r.face[5, 5]) == 1 and float(r.depth[5, 5]) == 1.0  # nearer of two
    assert int(r.face[25, 25]) == -1 and torch.isinf(r.depth[25, 25])  # empty pixel
    assert torch.allclose(r.bary[0, 0], torch.tensor([1.0, 0.0, 0.0]))  # a vertex
    only_behind = rasterize(pix[6:], depth[6:], faces[:1], 32, 32)
    assert not only_behind.mask.any()
