"""A run with tri-plane position features (field.position_encoding=triplane): the planes
train at their own rate, the checkpoint keeps them and their box, the loaded avatar renders
what the trained one does, and a resumed run ends as a straight one."""

import torch
from train_cases import tiny_settings

from texvocab.capture import open as open_capture
from texvocab.method.field import FieldSettings
from texvocab.pipeline.avatar import load_avatar
from texvocab.pipeline.evaluate import render_view
from texvocab.pipeline.settings import march_settings
from texvocab.pipeline.train import Trainer

FIELD = FieldSettings(
    hidden=48,
    sdf_layers=2,
    color_layers=1,
    pos_freqs=4,
    position_encoding="triplane",
    triplane_resolution=32,
    triplane_channels=4,
)


def _settings(**kw):
    return tiny_settings(field=FIELD, triplane_lr_scale=10, **kw)


def test_planes_train_and_the_checkpoint_renders_them(capture, tmp_path, one_thread):
    cap = open_capture(capture)
    s = _settings(iterations=6, checkpoint_every=3)
    trainer = Trainer(cap, s, tmp_path / "run", progress=False)
    assert [g["lr"] for g in trainer.optim.param_groups] == [2e-3, 2e-2]
    assert trainer.optim.param_groups[1]["params"] == [trainer.model.triplane.planes]
    logs = trainer.run()
    assert all(torch.isfinite(torch.tensor(r["loss"])) for r in logs)
    planes = trainer.model.triplane.planes.detach()
    assert planes.abs().max() > 1e-3  # they started at zero and learned
    ck = torch.load(tmp_path / "run" / "checkpoint.pt", weights_only=True)
    assert torch.equal(ck["model"]["triplane.planes"], planes)
    assert torch.equal(ck["model"]["triplane.lo"], trainer.model.triplane.lo)
    avatar = load_avatar(tmp_path / "run" / "checkpoint.pt", cap, progress=False)
    assert avatar.model.triplane is not None and torch.equal(avatar.model.triplane.planes, planes)
    t, cam = cap.num_train, cap.cameras[1]
    a, _ = render_view(trainer.model.eval(), cap.poses[t], cap.trans[t], cam, march_settings(s))
    b, _ = render_view(avatar.model, cap.poses[t], cap.trans[t], cam, march_settings(s))
    assert torch.equal(torch.as_tensor(a), torch.as_tensor(b)) and float(torch.as_tensor(a).std()) > 0
    # three steps, then three more after --resume: the planes end as the straight run's
    first = Trainer(cap, s, tmp_path / "b", progress=False)
    first.run(until=3)
    resumed = Trainer(cap, s, tmp_path / "b", progress=False)
    assert resumed.resume() and resumed.step == 3
    resumed.run()
    torch.testing.assert_close(resumed.model.triplane.planes, planes, rtol=0, atol=0)
