"""The 3D view over a headless OSMesa moderngl context: not blank, the silhouette equals the
CPU rasteriser's and pyrender's for the same camera (in this process, with pyrender on
PyOpenGL's OSMesa platform), five part colours, a novelty map that follows the pose, and
the orbit camera's GL matrices equal its OpenCV camera."""

import numpy as np
import pytest
import torch

from texvocab.body import default_body
from texvocab.body.parts import BODY_PARTS
from texvocab.capture import Camera
from texvocab.geometry.raster import rasterize_mesh
from texvocab.method.vocab import Vocabulary
from texvocab_viewer.gl.camera import OrbitCamera, gl_mvp
from texvocab_viewer.gl.colors import PART_COLORS
from texvocab_viewer.gl.headless import create_headless_context, make_current, release
from texvocab_viewer.gl.scene import SceneOptions, SceneRenderer, face_normals
from texvocab_viewer.state import ViewerData, ViewerState

W, H = 320, 200
LEFT_SHOULDER = 16


@pytest.fixture(scope="module")
def ctx():
    c = create_headless_context()
    yield c
    release(c)


@pytest.fixture(scope="module")
def body():
    return default_body()


def iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / max((a | b).sum(), 1))


def gl_mask(renderer: SceneRenderer) -> np.ndarray:
    return renderer.read_depth() < 1.0


def test_orbit_camera_gl_matrices_equal_its_opencv_camera():
    cam = OrbitCamera(yaw=35, pitch=-20, distance=2.5)
    cam.pan(0.1, -0.05)
    cam.orbit(10, 5)
    cv = cam.to_texvocab_camera(W, H)
    np.testing.assert_allclose(
        gl_mvp(cv, cam.near, cam.far), cam.projection(W / H) @ cam.view_matrix(), atol=1e-9
    )
    np.testing.assert_allclose(cv.center, cam.eye, atol=1e-12)
    back = OrbitCamera.from_capture_camera(cv, target=cam.target)
    np.testing.assert_allclose(back.to_texvocab_camera(W, H).K, cv.K, atol=1e-9)
    np.testing.assert_allclose(back.to_texvocab_camera(W, H).R, cv.R, atol=1e-9)
    np.testing.assert_allclose(back.eye, cam.eye, atol=1e-9)


def test_default_body_silhouette_matches_cpu_raster_and_pyrender(ctx, body):
    data = ViewerData(body)
    state = ViewerState(data)
    state.apply_preset("walk")
    renderer = SceneRenderer(ctx, data)
    verts = torch.as_tensor(state.posed()[0])
    # an orbit camera, and a capture-style camera with an off-centre principal point
    orbit = OrbitCamera(yaw=30, pitch=10).to_texvocab_camera(W, H)
    K = np.array([[300.0, 0, 0.42 * W], [0, 300.0, 0.55 * H], [0, 0, 1]])
    capture_cam = Camera(K, orbit.R, orbit.t, W, H, name="off-centre")
    for cam in (orbit, capture_cam):
        tex = renderer.render(state, cam, (W, H), SceneOptions())
        assert tex.size == (W, H)
        img = renderer.read((W, H))
        assert img.shape == (H, W, 3) and img.dtype == np.uint8
        mask = gl_mask(renderer)
        assert 0.03 < mask.mean() < 0.5  # not blank, not everything
        bg = np.asarray(SceneOptions().background) * 255
        assert np.abs(img[~mask] - bg).max() <= 1 and np.abs(img[mask] - bg).max(-1).mean() > 20
        cpu = rasterize_mesh(verts, body.faces, cam).mask.numpy()
        score = iou(mask, cpu)
        print(f"{cam.name}: IoU GL vs CPU raster {score:.4f}")
        assert score > 0.98
    # pyrender (PyOpenGL on OSMesa) in the same process, then moderngl again
    from texvocab.capture.mesh_renderer import MeshRenderer

    with MeshRenderer(W, H) as pr:
        _, depth = pr.render(
            verts.numpy(), body.faces.numpy(), capture_cam.K, capture_cam.R, capture_cam.t, flat=True
        )
    make_current(ctx)
    renderer.render(state, capture_cam, (W, H), SceneOptions())
    score = iou(gl_mask(renderer), depth > 0)
    print(f"IoU GL vs pyrender {score:.4f}")
    assert score > 0.98


def test_part_colors_give_five_colours(ctx, body):
    data = ViewerData(body)
    state = ViewerState(data)
    renderer = SceneRenderer(ctx, data)
    renderer.render(state, OrbitCamera(), (W, H), SceneOptions(part_colors=True, lighting=False))
    img = renderer.read().astype(np.float64)
    body_px = img[gl_mask(renderer)]
    palette = np.array(list(PART_COLORS.values())) * 255
    dist = np.linalg.norm(body_px[:, None] - palette[None], axis=-1)  # (N, 5)
    near = dist.min(1) < 8
    assert near.mean() > 0.9  # (the rest: triangles straddling two parts, blended)
    counts = np.bincount(dist.argmin(1)[near], minlength=5)
    print(dict(zip(BODY_PARTS, counts.tolist(), strict=True)))
    assert np.all(counts > 0.01 * len(body_px))


def test_novelty_overlay_follows_the_pose(ctx, body):
    rng = np.random.default_rng(0)
    poses = rng.normal(0, 0.05, (10, 24, 3))
    poses[:, 0] = 0
    vocab = Vocabulary.build(poses, "part", num_keys=5, k=2)
    data = ViewerData(body, vocab)
    state = ViewerState(data)
    for part in BODY_PARTS:
        state.set_part_to_key(part, 0)
    renderer = SceneRenderer(ctx, data)
    opts = SceneOptions(novelty=True, lighting=False, novelty_scale=0.1)
    cam = OrbitCamera()
    renderer.render(state, cam, (W, H), opts)
    seen = renderer.read().astype(np.int32)
    seen_mask = gl_mask(renderer)
    assert np.all(state.novelty() < 1e-9)
    state.set_joint(LEFT_SHOULDER, (0.0, 0.0, 80.0))  # the left arm far from every key
    renderer.render(state, cam, (W, H), opts)
    novel = renderer.read().astype(np.int32)
    arm = list(BODY_PARTS).index("left_arm")
    assert state.novelty()[arm] > 0.1 and np.all(np.delete(state.novelty(), arm) < 1e-9)

    def red(img):  # hot pixels of the heat scale
        return (img[..., 0] > 180) & (img[..., 2] < 80)

    def blue(img):  # cold pixels: a pose the vocabulary has
        return (img[..., 2] > 150) & (img[..., 0] < 60)

    mask = gl_mask(renderer)
    assert red(seen).sum() == 0 and blue(seen)[seen_mask].mean() > 0.95
    assert red(novel).sum() > 0.05 * mask.sum()  # the arm turned red
    assert blue(novel)[mask].mean() > 0.6  # the rest stays cold


@pytest.mark.parametrize(
    "options",
    [SceneOptions(), SceneOptions(part_colors=True), SceneOptions(novelty=True), SceneOptions(skeleton=True)],
    ids=["textured", "parts", "novelty", "skeleton"],
)
def test_indexed_mesh_draws_the_unrolled_pixels_with_fewer_vertices(ctx, body, options):
    """Without the wireframe the body is drawn indexed, one GL vertex per (vertex, uv)
    pair: the same pixels as one vertex per triangle corner, and far fewer vertices."""
    rng = np.random.default_rng(1)
    poses = rng.normal(0, 0.1, (8, 24, 3))
    poses[:, 0] = 0
    data = ViewerData(body, Vocabulary.build(poses, "part", num_keys=4, k=2))
    state = ViewerState(data)
    state.set_joint(LEFT_SHOULDER, (0.0, 0.0, 50.0))
    renderer = SceneRenderer(ctx, data)
    assert renderer._layout(options) == "indexed"
    assert renderer.num_indexed < 0.3 * renderer.num_corners
    images = []
    for unrolled in (False, True):
        renderer.force_unrolled = unrolled
        renderer.render(state, OrbitCamera(), (W, H), options)
        images.append(renderer.read())
    assert gl_mask(renderer).mean() > 0.02
    assert np.array_equal(images[0], images[1])
    assert renderer._layout(SceneOptions(wireframe=True)) == "unrolled"


def test_wireframe_and_skeleton_draw_over_the_body(ctx, body):
    data = ViewerData(body)
    state = ViewerState(data)
    renderer = SceneRenderer(ctx, data)

    def darker_share(cam):
        renderer.render(state, cam, (W, H), SceneOptions())
        plain = renderer.read().astype(int).sum(-1)
        renderer.render(state, cam, (W, H), SceneOptions(wireframe=True))
        wire = renderer.read().astype(int).sum(-1)
        mask = gl_mask(renderer)
        return ((wire < plain - 30) & mask).sum() / mask.sum()

    close = darker_share(OrbitCamera(target=(0.0, 0.2, 0.0), distance=0.9))
    far = darker_share(OrbitCamera(distance=8.0))
    print(f"wireframe pixels: close-up {close:.1%} of the body, far away {far:.1%}")
    assert close > 0.1  # edges drawn across the body
    assert far < 0.02  # triangles of a pixel or two: lines fade out instead of covering all
    cam = OrbitCamera(distance=2.0)
    renderer.render(state, cam, (W, H), SceneOptions(skeleton=True))
    skel = renderer.read().astype(int)
    yellow = (skel[..., 0] > 200) & (skel[..., 1] > 170) & (skel[..., 2] < 80)
    assert yellow.sum() > 100  # bones
    # a joint (right wrist) drawn in red on top, where the camera projects it
    px, _ = cam.to_texvocab_camera(W, H).project(state.posed()[1][21:22])
    x, y = np.rint(px[0]).astype(int)
    assert skel[y, x, 0] > 200 and skel[y, x, 1] < 80


def test_msaa_resolves_into_the_same_image_with_smoother_edges(ctx, body):
    data = ViewerData(body)
    state = ViewerState(data)
    plain, msaa = SceneRenderer(ctx, data), SceneRenderer(ctx, data, samples=4)
    assert msaa.samples == min(4, ctx.max_samples) > 0
    opts = SceneOptions(part_colors=True, lighting=False)
    images = []
    for r in (plain, msaa):
        r.render(state, OrbitCamera(), (W, H), opts)
        images.append(r.read().astype(int))
    diff = np.abs(images[0] - images[1]).max(-1)
    assert 0 < (diff > 0).mean() < 0.05  # only edge pixels change
    palette = np.array(list(PART_COLORS.values()) + [SceneOptions().background]) * 255

    def off_palette(img):  # pixels that are a blend of two colours
        return (np.linalg.norm(img[:, :, None] - palette, axis=-1).min(-1) > 8).sum()

    assert off_palette(images[1]) > 1.5 * off_palette(images[0])


def test_missing_osmesa_is_one_clear_error(monkeypatch):
    import ctypes.util

    import texvocab_viewer.gl.headless as gh
    from texvocab.errors import TexvocabError

    monkeypatch.setattr(gh, "LIBRARY_NAMES", ("libOSMesa-not-here.so.99",))
    monkeypatch.setattr(ctypes.util, "find_library", lambda name: None)
    with pytest.raises(
        TexvocabError,
        match="libOSMesa not found .*libOSMesa-not-here.so.99.*install the Debian package libosmesa6",
    ):
        gh.create_headless_context()


def test_back_faces_are_culled_without_changing_the_image(ctx, body):
    """The closed body's back faces are culled (the winding GL keeps is the body's own):
    seen from outside, the image is pixel for pixel the one drawn with both sides, for
    several poses, cameras and modes; from inside the hips the view sees out."""
    data = ViewerData(body)
    state = ViewerState(data)
    renderer = SceneRenderer(ctx, data)
    assert renderer.front_face == "ccw"
    views = (
        ("walk", 30.0, SceneOptions()),
        ("squat", 160.0, SceneOptions(part_colors=True)),
        ("kick", -70.0, SceneOptions(wireframe=True, skeleton=True)),
    )

    def both_ways(cam, options):
        images = []
        for front in ("ccw", None):
            renderer.front_face = front
            renderer.render(state, cam, (W, H), options)
            images.append((renderer.read((W, H)), gl_mask(renderer)))
        renderer.front_face = "ccw"
        return images

    for preset, yaw, options in views:
        state.reset_all()
        state.apply_preset(preset)
        cam = OrbitCamera(target=state.posed()[1][0], yaw=yaw, pitch=10).to_texvocab_camera(W, H)
        (culled, _), (drawn, _) = both_ways(cam, options)
        np.testing.assert_array_equal(culled, drawn)
    state.reset_all()
    pelvis = state.posed()[1][0]
    inside = OrbitCamera(target=pelvis, yaw=0.0, pitch=0.0, distance=0.04)
    (_, culled), (_, drawn) = both_ways(inside.to_texvocab_camera(W, H), SceneOptions())
    print(f"inside the hips: body covers {drawn.mean():.3f} drawn both ways, {culled.mean():.3f} culled")
    assert drawn.mean() > 0.99 and culled.mean() < 0.5


def test_face_normals_are_the_cross_product(body):
    """The written-out float32 cross product equals np.cross in float64 (to float32's
    precision), so the 3D view's shading normals are unchanged."""
    state = ViewerState(ViewerData(body))
    state.apply_preset("kick")
    verts = state.posed()[0]
    faces = body.faces.numpy()
    tri = verts.astype(np.float64)[faces]
    want = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    got = face_normals(verts.astype(np.float32), faces)
    assert got.dtype == np.float32
    scale = np.linalg.norm(want, axis=1).max()
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-5 * scale)
    assert np.all(np.einsum("ij,ij->i", got, want) >= 0)  # no flipped face
