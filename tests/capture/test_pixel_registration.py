"""Pixel conventions that a real capture's registration rests on: OpenCV pixel centres at
integer coordinates in the rays, the rasteriser and the synthetic renders alike, and
OpenCV's lens model."""

import numpy as np
import torch

from texvocab.capture.camera import Camera
from texvocab.capture.mesh_renderer import look_at


def test_the_ray_through_the_principal_point_is_the_optical_axis():
    R, t = look_at((0.4, 0.3, 2.5), (0.0, 0.0, 0.0))
    cam = Camera([[500.0, 0, 31.0], [0, 510.0, 17.0], [0, 0, 1]], R, t, 64, 48)
    _, d = cam.pixel_rays(np.array([[31.0, 17.0], [32.0, 17.0]]), dtype=torch.float64)
    np.testing.assert_allclose(d[0].numpy(), R[2], atol=1e-12)  # pixel (31, 17)'s centre
    assert abs(float(d[0] @ d[1]) - np.cos(np.arctan(1 / 500.0))) < 1e-9  # one pixel over


def test_distortion_is_opencvs_model():
    """k1, k2, k3 radial; p1 on y's r² + 2y² term and x's 2xy, p2 the other way round
    (OpenCV's ``projectPoints``), written out for one point."""
    k1, k2, p1, p2, k3 = -0.22, 0.031, -0.0053, 0.0022, 0.064
    cam = Camera(np.eye(3), np.eye(3), np.zeros(3), 8, 8, [k1, k2, p1, p2, k3])
    x, y = 0.3, -0.2
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2 * r2 + k3 * r2**3
    expected = [
        x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
        y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y,
    ]
    np.testing.assert_allclose(cam.distort_normalized(np.array([[x, y]]))[0], expected, atol=1e-15)


def test_synthetic_renders_and_the_rasteriser_share_pixel_centres():
    """pyrender (GL: pixel centres at i + 0.5) renders a synthetic capture's masks through
    the OpenCV camera; they match the rasteriser's silhouette pixel for pixel. Half a pixel
    off in x and y (the principal point taken as it is) leaves an IoU of 0.74 at 64²."""
    from texvocab.body import default_body
    from texvocab.capture.motion import make_sequence
    from texvocab.capture.synth import SynthRenderer, SynthSettings, default_cameras
    from texvocab.geometry.raster import rasterize_mesh

    body = default_body()
    settings = SynthSettings(ring_views=2, raised_views=0, size=64, texture_size=64)
    poses, trans = make_sequence([("walk", 1)], seed=4)
    cams = default_cameras(settings)
    renderer = SynthRenderer(body, settings)
    try:
        renders = renderer.render(poses[0], trans[0], cams)
    finally:
        renderer.close()
    verts = body.forward(torch.as_tensor(poses[0])[None], torch.as_tensor(trans[0])[None]).vertices[0]
    for cam, (_, mask) in zip(cams, renders):
        sil = rasterize_mesh(verts, body.faces, cam).mask.numpy()
        assert (sil & mask).sum() / (sil | mask).sum() > 0.99, cam.name
