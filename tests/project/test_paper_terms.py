"""The paper's perceptual term runs (and changes the field's gradient), the offline frozen
Inception encoder, cosine view weighting of texture maps, adaptive keys per part and the
channels-last feature sampling."""

import dataclasses
import logging

import numpy as np
import pytest
import torch
import torch.nn.functional as F
from train_cases import tiny_settings
from weights_cases import torch_home_with

from texvocab.capture import open as open_capture
from texvocab.errors import AssetError, TexvocabError
from texvocab.geometry.rotations import rotvec_to_quat
from texvocab.geometry.uv import uv_to_grid
from texvocab.method.encoder import AUTO_FALLBACK, build_encoder
from texvocab.method.feature import FeatureMaps, sample_maps
from texvocab.method.texmap import TexmapSettings, build_texture_map, cache_dir
from texvocab.method.vocab import Vocabulary, farthest_point_sampling, part_distance
from texvocab.metrics import perceptual as lpips_module
from texvocab.metrics.inception_perceptual import InceptionPerceptual
from texvocab.pipeline.settings import DataSettings, Settings
from texvocab.pipeline.train import Trainer


def _field_grads(trainer, loss):
    params = [p for p in trainer.model.parameters() if p.requires_grad]
    grads = torch.autograd.grad(loss, params, retain_graph=True, allow_unused=True)
    return torch.cat(
        [(torch.zeros_like(p) if g is None else g).reshape(-1) for p, g in zip(params, grads, strict=True)]
    )


def test_perceptual_term_changes_the_field_gradient_only_when_weighted(capture, tmp_path, empty_torch_home):
    cap = open_capture(capture)
    s = tiny_settings(perceptual="inception", lambda_perceptual=1.0, patch_size=16)
    trainer = Trainer(cap, s, tmp_path / "run", progress=False)
    assert isinstance(trainer.perceptual, InceptionPerceptual)
    state = trainer.gen.get_state()
    on = trainer.loss_terms()
    assert float(on["perceptual"].detach()) > 0
    g_perc = _field_grads(trainer, on["perceptual"])
    assert g_perc.abs().max() > 0  # the term reaches the field's parameters
    g_on = _field_grads(trainer, on["loss"])
    trainer.gen.set_state(state)  # the same frame, views, patch and rays
    trainer.s = dataclasses.replace(s, train=dataclasses.replace(s.train, lambda_perceptual=0.0))
    off = trainer.loss_terms()
    assert torch.allclose(off["color"], on["color"]) and torch.allclose(off["perceptual"], on["perceptual"])
    g_off = _field_grads(trainer, off["loss"])
    assert torch.allclose(g_on - g_off, g_perc, atol=1e-5 * float(g_perc.abs().max()) + 1e-9)
    assert (g_on - g_off).abs().max() > 0.1 * g_perc.abs().max()


def test_perceptual_choice_is_logged_and_zero_weight_turns_it_off(
    capture, tmp_path, empty_torch_home, caplog
):
    cap = open_capture(capture)
    with caplog.at_level(logging.INFO, logger="texvocab"):
        t = Trainer(cap, tiny_settings(), tmp_path / "a", progress=False)  # auto, no VGG
        assert isinstance(t.perceptual, InceptionPerceptual)
        t0 = Trainer(cap, tiny_settings(lambda_perceptual=0.0), tmp_path / "b", progress=False)
        assert t0.perceptual is None and float(t0.loss_terms()["perceptual"].detach()) == 0.0
    lines = [r.getMessage() for r in caplog.records if "perceptual term" in r.getMessage()]
    assert "inception-perceptual" in lines[0] and "LPIPS-VGG weights absent" in lines[0]
    assert lines[1] == "perceptual term: off"
    with pytest.raises(AssetError, match="VGG16"):
        Trainer(cap, tiny_settings(perceptual="lpips-vgg"), tmp_path / "c", progress=False)


def test_auto_perceptual_is_lpips_vgg_when_its_weights_are_present(capture, tmp_path, monkeypatch, caplog):
    from texvocab.metrics.perceptual import LPIPS, _heads_layout, _vgg16_layout

    g = torch.Generator().manual_seed(0)
    vgg = {k: torch.randn(shape, generator=g) * 0.05 for k, shape in _vgg16_layout().items()}
    home = torch_home_with(tmp_path / "home", {"vgg16-397923af.pth": vgg})
    pkg = tmp_path / "lpips"
    (pkg / "weights" / "v0.1").mkdir(parents=True)
    torch.save(
        {k: torch.rand(shape, generator=g) for k, shape in _heads_layout().items()},
        pkg / "weights" / "v0.1" / "vgg.pth",
    )
    monkeypatch.setenv("TORCH_HOME", str(home))
    monkeypatch.setattr(lpips_module, "package_dir", lambda name: pkg if name == "lpips" else None)
    with caplog.at_level(logging.INFO, logger="texvocab"):
        t = Trainer(open_capture(capture), tiny_settings(patch_size=16), tmp_path / "run", progress=False)
    assert isinstance(t.perceptual, LPIPS)
    assert any("LPIPS-VGG (the paper's)" in r.getMessage() for r in caplog.records)
    assert float(t.loss_terms()["perceptual"].detach()) > 0


def test_inception_perceptual_is_zero_for_equal_images_and_grows_with_noise():
    net = InceptionPerceptual()
    g = torch.Generator().manual_seed(0)
    x = torch.rand(2, 3, 24, 24, generator=g)
    assert torch.allclose(net(x, x), torch.zeros(2), atol=1e-6)
    d = [
        float(net((x + a * torch.randn(x.shape, generator=g)).clamp(0, 1), x).mean())
        for a in (0.02, 0.1, 0.3)
    ]
    assert 0 < d[0] < d[1] < d[2] <= 4
    with pytest.raises(ValueError, match="at least"):
        net(x[..., :10, :10], x[..., :10, :10])


def test_inception_encoder_is_frozen_offline_and_spatially_aligned(empty_torch_home):
    enc = build_encoder("inception")
    assert enc.name == "inception" and not enc.trainable and enc.feature_dim == 64 + 192 + 288
    assert len(enc.state_dict()) == 0  # the shared network never enters a checkpoint
    black = torch.zeros(1, 3, 256, 256)
    blob = black.clone()
    blob[:, :, 32:48, 192:208] = 1.0  # centre at texel (row 40, col 200)
    with torch.no_grad():
        fa, fb = enc(black), enc(blob)
    assert fa.shape == (1, 544, 128, 128) and not fa.requires_grad
    change = (fb - fa)[0, :64].abs().sum(0)  # the finest tap (conv_2)
    r, c = divmod(int(change.argmax()), 128)
    assert abs(2 * r - 40) <= 10 and abs(2 * c - 200) <= 10, (r, c)


def test_auto_still_falls_back_to_the_documented_encoder(empty_torch_home):
    assert build_encoder("auto").name == AUTO_FALLBACK


def test_sample_maps_equals_grid_sample_for_channels_last_and_plain_maps():
    g = torch.Generator().manual_seed(0)
    maps = torch.randn(2, 7, 9, 13, generator=g, dtype=torch.float64, requires_grad=True)
    uv = torch.rand(300, 2, generator=g, dtype=torch.float64) * 1.4 - 0.2  # incl. outside
    ref = F.grid_sample(
        maps[:1],
        uv_to_grid(uv).view(1, 1, -1, 2),
        mode="bilinear",
        padding_mode="border",
        align_corners=False,
    )[0, :, 0].T
    for m in (maps[0], FeatureMaps.from_stack(maps).map(0)):
        got = sample_maps(m, uv)
        assert torch.allclose(got, ref, atol=1e-12)
        (ga,) = torch.autograd.grad(got.square().sum(), maps)
        (gb,) = torch.autograd.grad(ref.square().sum(), maps, retain_graph=True)
        assert torch.allclose(ga, gb, atol=1e-10)


def test_cosine_view_weighting_favours_head_on_views(capture, tmp_path):
    cap = open_capture(capture)
    mean = build_texture_map(cap, 0, TexmapSettings(size=64))
    cos = build_texture_map(cap, 0, TexmapSettings(size=64, view_weighting="cosine"))
    assert np.array_equal(mean[1], cos[1])  # the same views see the same texels
    many = mean[1] >= 2  # texels seen by several views get a different blend
    diff = np.abs(mean[0] - cos[0]).max(-1)
    assert diff[many].max() > 1e-3 and diff[mean[1] == 1].max() < 1e-6
    s = DataSettings(view_weighting="cosine")
    assert cache_dir(cap, TexmapSettings(view_weighting="cosine")) != cache_dir(cap, TexmapSettings())
    with pytest.raises(TexvocabError, match="view_weighting"):
        dataclasses.replace(s, view_weighting="max")


def test_adaptive_keys_stop_when_every_pose_is_within_d_min():
    g = torch.Generator().manual_seed(0)
    poses = torch.zeros(40, 24, 3, dtype=torch.float64)
    poses[:, 18] = torch.randn(40, 3, generator=g, dtype=torch.float64)  # an arm swings
    poses[:, 4] = 0.01 * torch.randn(40, 3, generator=g, dtype=torch.float64)  # a knee barely
    fixed = Vocabulary.build(poses, "part", 20, 3)
    adaptive = Vocabulary.build(poses, "part", 20, 3, min_distance=0.05)
    sizes = dict(zip(adaptive.part_names, [len(f) for f in adaptive.key_frames], strict=True))
    assert all(len(f) == 20 for f in fixed.key_frames)
    assert sizes["right_arm"] == 1 and sizes["left_leg"] < 5 < sizes["left_arm"] <= 20, sizes
    for joints, keys in zip(adaptive.part_joints, adaptive.key_quats, strict=True):
        q = rotvec_to_quat(poses[:, list(joints)])
        covered = part_distance(q, keys).min(-1).values
        if len(keys) < 20:
            assert float(covered.max()) <= 0.05  # stopped only because every pose is near
    q = rotvec_to_quat(poses[:, [4]])
    assert len(farthest_point_sampling(q, 20, min_distance=0.0)) == 20
    assert "M=" in adaptive.format_query(poses[0])


def test_settings_absent_from_an_old_checkpoint_keep_their_old_meaning():
    old = Settings.from_dict({})  # a checkpoint written before these settings existed
    assert (old.train.perceptual, old.data.view_weighting, old.vocab.min_key_distance) == ("off", "mean", 0.0)
    assert Settings().train.perceptual == "auto"  # today's default differs
    assert Settings.from_dict(Settings().to_dict()) == Settings()
