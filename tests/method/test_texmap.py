"""Texture maps (Sec. 3.2): the back-projected U_t of a synthetic capture reproduces the
generator's known appearance where views saw the surface; occluded surface gets nothing."""

import numpy as np
import pytest
import torch

from texvocab.body import default_body
from texvocab.capture import open as open_capture
from texvocab.capture.garment import Garment
from texvocab.capture.synth import SynthSettings, synthesize
from texvocab.geometry.uv import texel_map
from texvocab.method.texmap import (
    TexmapSettings,
    build_texture_map,
    load_texture_map,
    prepare_texture_maps,
)

SIZE = 128


@pytest.fixture(scope="module")
def unlit_capture(tmp_path_factory):
    body = default_body()
    poses = np.zeros((2, 24, 3), np.float32)
    poses[:, 16, 2] = -np.radians(60)  # arms lowered a little
    poses[:, 17, 2] = np.radians(60)
    poses[1, 18, 1] = -np.radians(70)
    settings = SynthSettings(ring_views=6, raised_views=2, size=256, texture_size=512, lighting=False)
    root = synthesize(
        tmp_path_factory.mktemp("cap") / "unlit", poses, np.zeros((2, 3)), 2, body, settings, progress=False
    )
    return open_capture(root, body=body)


def _psnr(a, b):
    return float(10 * np.log10(1.0 / np.mean((a - b) ** 2)))


def test_texture_map_matches_known_appearance(unlit_capture):
    cap = unlit_capture
    truth_full = Garment(cap.body, 512).texture(cap.poses[0])
    truth = truth_full.reshape(SIZE, 4, SIZE, 4, 3).mean((1, 3))  # box-filter to 128²
    texture, coverage = build_texture_map(cap, 0, TexmapSettings(size=SIZE))
    seen = coverage > 0
    covered = texel_map(cap.body, SIZE).covered
    assert seen.sum() > 0.6 * covered.sum()  # most of the surface is seen by 8 views
    psnr = _psnr(texture[seen], truth[seen])
    print(
        f"UV-space PSNR of U_0 vs the generator's albedo over seen texels: {psnr:.2f} dB "
        f"({seen.mean():.1%} of the atlas seen)"
    )
    assert psnr > 20.0
    # a texture map from a different pose's truth would not match as well: folds differ
    assert np.isfinite(texture).all() and texture.min() >= 0 and texture.max() <= 1


def test_occluded_surface_receives_nothing(unlit_capture):
    cap = unlit_capture
    # Only the front camera: texels on the back of the body must stay unseen.
    _, coverage = build_texture_map(cap, 0, TexmapSettings(size=SIZE), views=[0])
    tmap = texel_map(cap.body, SIZE)
    verts = cap.posed_body(0).vertices[0].double().numpy()
    pts = tmap.points(verts, cap.body.faces.numpy())
    cov = coverage[tmap.covered]
    front_cam_z = cap.cameras[0].center[2]
    assert front_cam_z > 0
    back = pts[:, 2] < np.percentile(pts[:, 2], 15)  # the rearmost surface
    assert cov[back].max() == 0
    assert (cov > 0).mean() < 0.6


def test_prepare_caches_and_resumes(unlit_capture, monkeypatch):
    cap = unlit_capture
    s = TexmapSettings(size=64)
    paths = prepare_texture_maps(cap, s, progress=False)
    assert len(paths) == 2 and all(p.is_file() for p in paths)
    tex, cov = load_texture_map(paths[1])
    assert tex.shape == (64, 64, 3) and cov.max() >= 1
    stamp = paths[0].stat().st_mtime_ns
    paths[1].unlink()  # simulate a run killed before frame 1 was written

    calls = []
    import texvocab.method.texmap as tm

    real = tm.build_texture_map
    monkeypatch.setattr(tm, "build_texture_map", lambda c, t, st: calls.append(t) or real(c, t, st))
    prepare_texture_maps(cap, s, progress=False)
    assert calls == [1] and paths[0].stat().st_mtime_ns == stamp and paths[1].is_file()
    assert not list(paths[0].parent.glob(".*"))  # no temporary leftovers


def test_texel_map_inverts_the_uv_layout():
    """Each covered texel's face and barycentrics map back to that texel's UV centre."""
    from texvocab.geometry.uv import pixel_to_uv

    body = default_body()
    tmap = texel_map(body, 64)
    uv = tmap.interpolate(body.vt.double().numpy(), body.ft.numpy())
    rows, cols = np.nonzero(tmap.covered)
    centres = pixel_to_uv(torch.as_tensor(np.stack([cols, rows], 1), dtype=torch.float64), 64, 64)
    np.testing.assert_allclose(uv, centres.numpy(), atol=1e-9)
    assert np.all(tmap.bary >= -1e-9) and np.allclose(tmap.bary.sum(1), 1)


def test_texel_fill_is_the_nearest_covered_texel():
    """to_image's fill (one gather) equals scattering the covered texels and copying
    each texel's nearest covered one, for vector and scalar values, dtype kept."""
    tmap = texel_map(default_body(), 64)
    rng = np.random.default_rng(0)
    n = int(tmap.covered.sum())
    for values in (rng.random((n, 3)).astype(np.float32), rng.random(n)):
        ref = np.zeros((64, 64) + values.shape[1:], values.dtype)
        ref[tmap.covered] = values
        out = tmap.to_image(values, fill=True)
        assert out.dtype == values.dtype and np.array_equal(out, ref[tmap.nearest])
        assert np.array_equal(tmap.to_image(values, fill=False), ref)
    assert (~tmap.covered).any()  # the fill is exercised


def _maps_of(root, body, **settings):
    from texvocab.pipeline.model import load_textures
    from texvocab.pipeline.settings import DataSettings, Settings

    cap = open_capture(root, body=body)
    s = Settings(data=DataSettings(texture_size=64, **settings))
    return load_textures(cap, s, progress=False).numpy()


def _scramble(paths, seed):
    from PIL import Image

    rng = np.random.default_rng(seed)
    for path in paths:
        with Image.open(path) as im:
            size, mode = im.size, im.mode
        noise = rng.integers(0, 256, (size[1], size[0], len(mode)), dtype=np.uint8)
        Image.fromarray(noise.squeeze(-1) if len(mode) == 1 else noise, mode).save(path)


def test_held_out_views_never_enter_a_texture_map(unlit_capture, tmp_path):
    """Honest evaluation: scrambling every pixel of the evaluation views (eval_views, the
    same views training never samples) leaves every texture map bit-identical; scrambling a
    training view changes them (so the comparison can fail)."""
    import shutil

    body, root = unlit_capture.body, unlit_capture.root
    ref = _maps_of(root, body, eval_views=(1, 5))
    for name, views, same in (("held_out", (1, 5), True), ("training", (0,), False)):
        copy = tmp_path / name
        shutil.copytree(root, copy, ignore=shutil.ignore_patterns("texvocab_cache"))
        cap = open_capture(copy, body=body)
        _scramble([cap.image_paths[t][v] for t in range(cap.num_frames) for v in views], seed=3)
        got = _maps_of(copy, body, eval_views=(1, 5))
        assert np.array_equal(got, ref) == same, name


def test_texture_map_cache_is_keyed_by_view_set(unlit_capture, tmp_path):
    """A cache built from other views (e.g. every view, as before held-out views were
    excluded) is never reused: another view set gets its own folder."""
    from texvocab.method.texmap import cache_dir
    from texvocab.pipeline.model import texmap_settings
    from texvocab.pipeline.settings import DataSettings, Settings

    cap = unlit_capture
    all_views = cache_dir(cap, TexmapSettings(size=64))
    train = cache_dir(
        cap, texmap_settings(cap, Settings(data=DataSettings(texture_size=64, eval_views=(1, 5))))
    )
    other = cache_dir(
        cap, texmap_settings(cap, Settings(data=DataSettings(texture_size=64, eval_views=(2,))))
    )
    assert len({all_views, train, other}) == 3
    assert train.name == "texmaps_64_views_0-2-3-4-6-7"
    maps = prepare_texture_maps(cap, TexmapSettings(size=64), progress=False)  # all views
    assert all(p.parent == all_views for p in maps)
    honest = _maps_of(cap.root, cap.body, eval_views=(1, 5))
    leaky = np.stack([load_texture_map(p)[0] for p in maps]).transpose(0, 3, 1, 2)
    assert not np.array_equal(honest, leaky)  # the all-view maps were not reused


def test_texture_map_cache_follows_its_inputs(tmp_path, monkeypatch):
    """The cache is keyed by what a map was built from: an image rewritten in place (same
    name, same size) rebuilds that frame only, a changed calibration every frame, and an
    unchanged capture nothing."""
    import shutil

    from PIL import Image

    import texvocab.method.texmap as tm

    body = default_body()
    poses = np.zeros((3, 24, 3), np.float32)
    settings = SynthSettings(ring_views=2, raised_views=0, size=64, texture_size=64, lighting=False)
    root = synthesize(tmp_path / "cap", poses, np.zeros((3, 3)), 3, body, settings, progress=False)
    s = TexmapSettings(size=32)
    calls = []
    real = tm.build_texture_map
    monkeypatch.setattr(tm, "build_texture_map", lambda c, t, st: calls.append(t) or real(c, t, st))

    def prepare():
        calls.clear()
        prepare_texture_maps(open_capture(root, body=body), s, progress=False)
        return list(calls)

    assert prepare() == [0, 1, 2]
    assert prepare() == []
    cap = open_capture(root, body=body)
    img = cap.image_paths[1][0]
    pixels = np.asarray(Image.open(img)).copy()
    pixels[10:20, 10:20] = 255 - pixels[10:20, 10:20]
    Image.fromarray(pixels).save(img)  # same file name, same size, new content
    assert prepare() == [1]
    root = tmp_path / "copy"
    shutil.copytree(cap.root, root)
    assert prepare() == []  # a copied capture (its cache inside) is the same content
    annots = np.load(root / "annots.npy", allow_pickle=True).item()
    annots["cams"]["T"][0] = np.asarray(annots["cams"]["T"][0]) + 1.0  # camera 0 moved 1 mm
    np.save(root / "annots.npy", annots, allow_pickle=True)
    assert prepare() == [0, 1, 2]


def test_coverage_is_reported_and_a_frame_that_saw_little_is_named(unlit_capture, caplog):
    from texvocab.method.texmap import coverage_note, seen_texel_share
    from texvocab.pipeline.model import load_textures
    from texvocab.pipeline.settings import DataSettings, Settings

    cap = unlit_capture
    paths = prepare_texture_maps(cap, TexmapSettings(size=64), progress=False)
    cov = np.stack([load_texture_map(p)[1] for p in paths])
    share = seen_texel_share(cov, cap.body)
    assert share.shape == (2,) and (share > 0.8).all()  # 8 views see nearly all of the body
    line, warning = coverage_note(share, cap.frame_ids)
    assert line.startswith("coverage: ") and warning is None
    cov[1] = np.where(np.cumsum(cov[1] > 0).reshape(cov[1].shape) > 20, 0, cov[1])  # 20 texels left
    _, warning = coverage_note(seen_texel_share(cov, cap.body), cap.frame_ids)
    assert warning.startswith("1 of 2 texture maps saw under 10 %")
    assert f"frames {cap.frame_ids[1]}" in warning
    with caplog.at_level("WARNING", logger="texvocab"):
        load_textures(cap, Settings(data=DataSettings(texture_size=64, eval_views=())), progress=False)
    assert not any("texture maps saw under" in r.getMessage() for r in caplog.records)  # a sound capture
