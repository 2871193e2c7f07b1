"""Camera: projection, pixel rays, scaling, undistortion."""

import numpy as np
import pytest

from texvocab.capture.calibration_checks import CameraFields, check_camera
from texvocab.capture.camera import Camera
from texvocab.capture.mesh_renderer import intrinsics, look_at
from texvocab.errors import AssetError


@pytest.fixture
def cam():
    R, t = look_at((1.0, 0.5, 3.0), (0.0, -0.2, 0.0))
    return Camera(intrinsics(160, 120, 40.0), R, t, 160, 120, name="c0")


def test_look_at_puts_world_up_at_image_top(cam):
    (top, bottom), _ = cam.project(np.array([[0.0, 0.3, 0.0], [0.0, -0.7, 0.0]]))[0:1][0], None
    assert top[1] < bottom[1]
    (left, right), _ = cam.project(np.array([[-0.5, -0.2, 0.0], [0.5, -0.2, 0.0]]))[0], None
    assert left[0] < right[0]  # camera in front (+z) sees world +x on the right


def test_rays_pass_through_projected_points(cam):
    pts = np.random.default_rng(0).uniform(-0.5, 0.5, (50, 3))
    pix, depth = cam.project(pts)
    o, d = cam.pixel_rays(pix, dtype=__import__("torch").float64)
    back = o.numpy() + d.numpy() * np.linalg.norm(pts - cam.center, axis=1)[:, None]
    np.testing.assert_allclose(back, pts, atol=1e-9)
    assert (depth > 0).all()


def test_scaled_camera_keeps_pixel_centres(cam):
    half = cam.scaled(0.5)
    pts = np.array([[0.1, 0.2, 0.0]])
    p_full, _ = cam.project(pts)
    p_half, _ = half.project(pts)
    np.testing.assert_allclose((p_full + 0.5) * 0.5 - 0.5, p_half, atol=1e-9)
    assert (half.width, half.height) == (80, 60)


@pytest.mark.parametrize("step", [3, 8])
def test_every_nth_pixel_camera_has_the_same_rays(cam, step):
    """Camera.every(step): pixel (x, y) is the full camera's pixel (step x, step y) (a
    progressive render's preview level), ceil(W / step) x ceil(H / step) pixels."""
    import torch

    sub = cam.every(step)
    assert (sub.width, sub.height) == (-(-160 // step), -(-120 // step))
    o_full, d_full = cam.pixel_rays(dtype=torch.float64)
    o_sub, d_sub = sub.pixel_rays(dtype=torch.float64)
    pick = d_full.view(120, 160, 3)[::step, ::step].reshape(-1, 3)
    np.testing.assert_allclose(d_sub.numpy(), pick.numpy(), atol=1e-12)
    np.testing.assert_allclose(o_sub.numpy(), o_full[: len(o_sub)].numpy())


def test_undistort_recovers_the_ideal_image(cam):
    cam.dist = np.array([-0.25, 0.08, 0.001, -0.002, 0.0])
    ys, xs = np.mgrid[0 : cam.height, 0 : cam.width].astype(float)

    def pattern(x, y):  # smooth analytic image in ideal normalised coordinates
        return 0.5 + 0.5 * np.sin(9 * x) * np.cos(7 * y)

    # distorted image: the pixel at distorted position shows the ideal pattern
    ideal_xy = np.stack(
        [(xs.ravel() - cam.K[0, 2]) / cam.K[0, 0], (ys.ravel() - cam.K[1, 2]) / cam.K[1, 1]], -1
    )
    # sample the distorted image densely by inverting with fixed-point iterations
    und = ideal_xy.copy()
    for _ in range(30):
        und = und + (ideal_xy - cam.distort_normalized(und))
    distorted = pattern(und[:, 0], und[:, 1]).reshape(cam.height, cam.width).astype(np.float32)
    restored = cam.undistort_image(distorted)
    truth = pattern(ideal_xy[:, 0], ideal_xy[:, 1]).reshape(cam.height, cam.width)
    inner = np.s_[10:-10, 10:-10]
    err_restored = np.abs(restored[inner] - truth[inner]).mean()
    err_distorted = np.abs(distorted[inner] - truth[inner]).mean()
    assert err_restored < 0.005 and err_distorted > 4 * err_restored


@pytest.mark.parametrize("field", ["K", "R", "t"])
def test_non_finite_calibration_is_named(cam, field):
    getattr(cam, field).flat[0] = np.nan
    fields = CameraFields.keyed("", "K", "R", "t", "dist", "size")
    with pytest.raises(AssetError, match=rf"calib\.json: camera 'c0' {field}: holds NaN or inf"):
        check_camera(cam, "calib.json", fields)


@pytest.mark.parametrize("dtype", [np.float32, np.uint8])
def test_pixel_taps_sample_as_zero_padded_bilinear_interpolation(dtype):
    """The taps a camera keeps for its undistortion read what bilinear interpolation of
    the image padded with zeros gives (scipy's), at positions inside, on and past the
    border; integer images are rounded."""
    from scipy import ndimage

    from texvocab.capture.camera import PixelTaps

    rng = np.random.default_rng(3)
    image = (rng.random((9, 13, 3)) * 255).astype(dtype)
    x = np.concatenate([rng.uniform(-2, 15, 400), [-1.0, -0.5, 0.0, 12.0, 12.5, 13.0]])
    y = np.concatenate([rng.uniform(-2, 11, 400), [0.0, 4.0, -0.5, 8.0, 8.5, 9.0]])
    taps = PixelTaps.at(image.shape, x, y)
    got = taps.apply(image)
    want = np.stack(
        [
            ndimage.map_coordinates(image[..., c].astype(np.float64), [y, x], order=1, mode="grid-constant")
            for c in range(3)
        ],
        -1,
    )
    if dtype == np.uint8:
        np.testing.assert_array_less(np.abs(got.astype(np.float64) - want), 0.5 + 1e-3)
    else:
        np.testing.assert_allclose(got, want, atol=1e-4)
    # one set of taps serves every image of the size; nearest reads the rounded pixel or 0
    np.testing.assert_allclose(taps.apply(image[..., :1] * 0 + 1).ravel()[:400].max(), 1.0, atol=1e-6)
    near = PixelTaps.at(image.shape, x, y, nearest=True).apply(image)
    xi, yi = np.rint(x).astype(int), np.rint(y).astype(int)
    inside = (xi >= 0) & (xi < 13) & (yi >= 0) & (yi < 9)
    np.testing.assert_array_equal(near[inside], image[yi[inside], xi[inside]])
    assert not near[~inside].any()


def test_every_pixels_rays_are_kept_per_camera_and_handed_out_as_copies():
    """pixel_rays() of every pixel is kept for the last few cameras: the same rays as the
    pixels asked for one by one, a caller's change to them is not seen by the next caller,
    and a camera that moves gets its own rays."""
    import torch

    K = np.array([[80.0, 0, 31.5], [0, 80.0, 23.5], [0, 0, 1]])
    cam = Camera(K, np.eye(3), np.array([0.0, 0.0, 3.0]), 64, 48)
    ys, xs = np.mgrid[0:48, 0:64]
    listed = cam.pixel_rays(np.stack([xs.ravel(), ys.ravel()], -1))
    first = cam.pixel_rays()
    assert all(torch.equal(a, b) for a, b in zip(first, listed, strict=True))
    first[1][0] = 99.0
    again = cam.pixel_rays()
    assert torch.equal(again[1], listed[1]) and again[1].data_ptr() != first[1].data_ptr()
    moved = Camera(K, np.eye(3), np.array([0.1, 0.0, 3.0]), 64, 48)
    assert not torch.equal(moved.pixel_rays()[0], again[0])
    assert torch.equal(moved.pixel_rays()[1], again[1])  # a shift keeps the directions
    assert cam.pixel_rays(dtype=torch.float64)[1].dtype == torch.float64
