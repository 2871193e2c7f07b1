"""Texture encoder: torchvision ResNet34 layout, weight discovery and checking, the
fallback, and the PixelNeRF-style feature map. Checkpoints are random-init stand-ins
written by the tests in torchvision's key layout."""

import logging
import os

import pytest
import torch
from weights_cases import torch_home_with

from texvocab.errors import AssetError
from texvocab.method.encoder import ResNet34, build_encoder, find_resnet34_weights

BN = ("weight", "bias", "running_mean", "running_var", "num_batches_tracked")


def torchvision_resnet34_layout() -> list[tuple[str, tuple[int, ...]]]:
    """(key, shape) of torchvision's resnet34 state dict, in order, written out from the
    architecture: [3, 4, 6, 3] BasicBlocks, downsample in the first block of layers 2-4."""

    def bn(prefix, c):
        return [(f"{prefix}.{s}", () if s == "num_batches_tracked" else (c,)) for s in BN]

    out = [("conv1.weight", (64, 3, 7, 7))] + bn("bn1", 64)
    cin = 64
    for layer, (blocks, c) in enumerate(zip((3, 4, 6, 3), (64, 128, 256, 512)), start=1):
        for b in range(blocks):
            p = f"layer{layer}.{b}"
            out += [(f"{p}.conv1.weight", (c, cin if b == 0 else c, 3, 3))] + bn(f"{p}.bn1", c)
            out += [(f"{p}.conv2.weight", (c, c, 3, 3))] + bn(f"{p}.bn2", c)
            if b == 0 and layer > 1:
                out += [(f"{p}.downsample.0.weight", (c, cin, 1, 1))]
                out += bn(f"{p}.downsample.1", c)
        cin = c
    return out + [("fc.weight", (1000, 512)), ("fc.bias", (1000,))]


@pytest.fixture(scope="module")
def standin_state():
    """A torchvision-layout ResNet34 state dict (random init, BN stats made non-trivial)."""
    torch.manual_seed(0)
    state = ResNet34().state_dict()
    for k, v in state.items():
        if k.endswith(("running_mean", "running_var", "bn1.bias", "bn2.bias")):
            state[k] = torch.rand_like(v) + 0.5
    return state


@pytest.fixture(scope="module")
def standin_home(tmp_path_factory, standin_state):
    """A TORCH_HOME holding the stand-in as hub/checkpoints/resnet34-b627a593.pth."""
    return torch_home_with(tmp_path_factory.mktemp("torch_home"), {"resnet34-b627a593.pth": standin_state})


def test_state_dict_matches_torchvision_resnet34_layout():
    net = ResNet34()
    got = [(k, tuple(v.shape)) for k, v in net.state_dict().items()]
    assert got == torchvision_resnet34_layout()
    assert len(got) == 218
    assert sum(p.numel() for p in net.parameters()) == 21_797_672


def test_auto_loads_pretrained_weights_from_torch_home(standin_home, standin_state, monkeypatch, caplog):
    monkeypatch.setenv("TORCH_HOME", str(standin_home))
    path = standin_home / "hub" / "checkpoints" / "resnet34-b627a593.pth"
    assert find_resnet34_weights() == path
    with caplog.at_level(logging.DEBUG, logger="texvocab"):
        e = build_encoder()
    assert caplog.records == []
    assert (e.name, e.pretrained, e.trainable, e.feature_dim) == ("resnet34", True, False, 512)
    got = e.backbone.state_dict()
    for key in (
        "conv1.weight",
        "bn1.running_var",
        "layer1.0.conv1.weight",
        "layer2.0.downsample.0.weight",
        "layer3.5.bn2.running_mean",
    ):
        assert torch.equal(got[key], standin_state[key]), key
    assert not any(p.requires_grad for p in e.parameters())
    assert "layer4.0.conv1.weight" not in got  # stage 4 is not among the 4 levels
    out = e(torch.rand(1, 3, 256, 256))
    assert out.shape == (1, 512, 128, 128) and torch.isfinite(out).all()


def test_frozen_encoder_stays_in_eval_mode_inside_a_training_parent(standin_home, standin_state):
    e = build_encoder("resnet34", weights=standin_home / "hub/checkpoints/resnet34-b627a593.pth")
    parent = torch.nn.ModuleDict({"encoder": e, "head": torch.nn.Linear(2, 2)}).train()
    assert parent["head"].training and not any(m.training for m in e.modules())
    e(torch.rand(2, 3, 32, 32))
    assert torch.equal(e.backbone.bn1.running_mean, standin_state["bn1.running_mean"])


def test_feature_map_is_stem_then_upsampled_levels(standin_home):
    e = build_encoder("resnet34", weights=standin_home / "hub/checkpoints/resnet34-b627a593.pth")
    x = torch.rand(1, 3, 65, 47)
    out = e(x)
    assert out.shape == (1, 512, 33, 24)
    b = e.backbone
    stem = b.relu(b.bn1(b.conv1((x - e.mean) / e.std)))
    layer1 = b.layer1(b.maxpool(stem))
    torch.testing.assert_close(out[:, :64], stem)
    up = torch.nn.functional.interpolate(layer1, (33, 24), mode="bilinear", align_corners=True)
    torch.testing.assert_close(out[:, 64:128], up)


def test_old_checkpoint_explicit_path_and_name_preference(tmp_path, standin_state, standin_home, monkeypatch):
    old = {k: v for k, v in standin_state.items() if not k.endswith("num_batches_tracked")}
    path = tmp_path / "hub" / "checkpoints" / "resnet34-333f7ec4.pth"
    path.parent.mkdir(parents=True)
    torch.save(old, path, _use_new_zipfile_serialization=False)  # pre-1.6 file format
    e = build_encoder("resnet34", weights=path, num_levels=2)
    assert e.feature_dim == 128 and e.pretrained
    assert torch.equal(e.backbone.layer1[2].conv2.weight, standin_state["layer1.2.conv2.weight"])
    monkeypatch.setenv("TORCH_HOME", str(tmp_path))
    assert find_resnet34_weights() == path
    newer = path.with_name("resnet34-b627a593.pth")
    newer.symlink_to(standin_home / "hub" / "checkpoints" / "resnet34-b627a593.pth")
    assert find_resnet34_weights() == newer


def test_auto_falls_back_to_pyramid_with_one_log_line(empty_torch_home, caplog):
    with caplog.at_level(logging.INFO, logger="texvocab"):
        e = build_encoder()
        build_encoder("auto")
    assert len(caplog.records) == 1
    msg = caplog.records[0].getMessage()
    assert caplog.records[0].levelno == logging.WARNING
    assert str(empty_torch_home / "hub" / "checkpoints") in msg and "'pyramid'" in msg
    assert "resnet34-*.pth" in msg and "\n" not in msg
    assert (e.name, e.pretrained, e.trainable, e.feature_dim) == ("pyramid", False, False, 12)
    x = torch.rand(1, 3, 64, 64)
    out = e(x)
    assert out.shape == (1, 12, 32, 32)
    # level 0 is the texture box-filtered 2x2 (ImageNet-normalised)
    mean = torch.tensor([0.485, 0.456, 0.406]).view(1, 3, 1, 1)
    std = torch.tensor([0.229, 0.224, 0.225]).view(1, 3, 1, 1)
    expect = torch.nn.functional.avg_pool2d((x - mean) / std, 2)
    assert torch.allclose(out[:, :3], expect, atol=1e-6)


def test_small_encoder_trains(empty_torch_home):
    e = build_encoder("small")
    assert (e.name, e.pretrained, e.trainable, e.feature_dim) == ("small", False, True, 192)
    out = e(torch.rand(1, 3, 256, 256))
    assert out.shape == (1, 192, 128, 128) and torch.isfinite(out).all()
    out.square().mean().backward()
    assert all(p.grad is not None and p.grad.abs().sum() > 0 for p in e.parameters())


def test_resnet34_scratch_is_trainable(empty_torch_home, caplog):
    with caplog.at_level(logging.INFO, logger="texvocab"):
        e = build_encoder("resnet34-scratch")
    assert caplog.records == []
    assert (e.name, e.pretrained, e.trainable, e.feature_dim) == ("resnet34-scratch", False, True, 512)
    e.train()
    out = e(torch.rand(2, 3, 64, 64))
    assert out.shape == (2, 512, 32, 32) and torch.isfinite(out).all()
    out.square().mean().backward()
    assert all(p.grad is not None and p.grad.abs().sum() > 0 for p in e.parameters())


def test_explicit_resnet34_without_weights_names_where_it_looked(empty_torch_home):
    with pytest.raises(AssetError, match="hub/checkpoints: no resnet34"):
        build_encoder("resnet34")
    with pytest.raises(AssetError, match="not found"):
        build_encoder("auto", weights=empty_torch_home / "nope.pth")


def test_bad_settings_are_rejected():
    with pytest.raises(ValueError, match="encoder must be one of"):
        build_encoder("resnet50")
    with pytest.raises(ValueError, match="weights="):
        build_encoder("small", weights="x.pth")
    with pytest.raises(ValueError, match="num_levels"):
        build_encoder("small", num_levels=5)
    with pytest.raises(ValueError, match=r"\(B, 3, H, W\)"):
        build_encoder("small")(torch.rand(3, 16, 16))


def _head(state, upto="bn1.num_batches_tracked"):
    keys = list(state)
    return {k: state[k] for k in keys[: keys.index(upto) + 1]}


@pytest.mark.parametrize(
    "case, pattern",
    [
        (
            "wrong_shape",
            r"key 'layer1.0.conv1.weight' expected shape \(64, 64, 3, 3\), "
            r"got \(64, 64, 1, 1\)",
        ),
        ("missing", r"key 'layer1.0.conv1.weight' missing \(expected shape \(64, 64, 3, 3\)\)"),
        ("unexpected", r"unexpected key 'layer5.0.conv1.weight'"),
        ("not_a_dict", r"expected a torchvision ResNet34 state dict, got list"),
        ("empty_file", r"not loadable as a torch state dict with weights_only=True \(EOFError\)"),
    ],
)
def test_wrong_checkpoint_raises_one_line_naming_file_and_key(
    tmp_path, standin_state, monkeypatch, case, pattern
):
    path = tmp_path / "hub" / "checkpoints" / "resnet34-b627a593.pth"
    path.parent.mkdir(parents=True)
    if case == "wrong_shape":
        torch.save(_head(standin_state) | {"layer1.0.conv1.weight": torch.zeros(64, 64, 1, 1)}, path)
    elif case == "missing":
        torch.save(_head(standin_state), path)
    elif case == "unexpected":
        torch.save(standin_state | {"layer5.0.conv1.weight": torch.zeros(1)}, path)
    elif case == "not_a_dict":
        torch.save([torch.zeros(1)], path)
    else:
        path.write_bytes(b"")
    monkeypatch.setenv("TORCH_HOME", str(tmp_path))
    with pytest.raises(AssetError, match=pattern) as info:
        build_encoder()  # a broken file in the cache is an error, not a silent fallback
    msg = str(info.value)
    assert msg.startswith(str(path)) and "\n" not in msg


class _Exploit:
    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return os.system, (f"touch {self.marker}",)


def test_malicious_pickle_is_refused_and_never_runs(tmp_path):
    marker = tmp_path / "pwned"
    path = tmp_path / "resnet34-b627a593.pth"
    torch.save({"conv1.weight": _Exploit(marker)}, path)
    with pytest.raises(AssetError, match="weights_only=True") as info:
        build_encoder("resnet34", weights=path)
    msg = str(info.value)
    assert msg.startswith(str(path)) and "\n" not in msg
    assert "system" in msg and "weights_only` set to `False" not in msg  # no unsafe advice
    assert not marker.exists()
