"""Render work too small for a second torch thread runs on one (texvocab.torch_threads):
the switch restores the count after the block (also after an error), a small guided image
triages its rays on one thread and a large one on all of them, and a render-time field
call on a few points runs on one thread while a training call keeps them all."""

import pytest
import torch
from render_cases import GUIDED

from texvocab.render.guided import image as guided_image
from texvocab.render.guided.image import GuidedImage
from texvocab.torch_threads import one_torch_thread


@pytest.fixture
def two_threads():
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    yield
    torch.set_num_threads(before)


def test_one_torch_thread_sets_and_restores(two_threads):
    with one_torch_thread():
        assert torch.get_num_threads() == 1
    assert torch.get_num_threads() == 2
    with one_torch_thread(False):
        assert torch.get_num_threads() == 2
    with pytest.raises(KeyError), one_torch_thread(True):
        raise KeyError("x")
    assert torch.get_num_threads() == 2


class CountingField:
    """The body's analytic field, recording torch's thread count at each call."""

    def __init__(self, field):
        self.field, self.beta, self.threads = field, field.beta, []

    def __call__(self, points, dirs):
        self.threads.append(torch.get_num_threads())
        return self.field(points, dirs)

    def sdf_rgb(self, points, dirs, known=None):
        self.threads.append(torch.get_num_threads())
        return self.field.sdf_rgb(points, dirs)


@pytest.mark.parametrize("limit,expected", [(guided_image.ONE_THREAD_RAYS, 1), (0, 2)])
def test_a_small_guided_image_triages_on_one_thread(body, two_threads, monkeypatch, limit, expected):
    monkeypatch.setattr(guided_image, "ONE_THREAD_RAYS", limit)  # 0: every image is "large"
    field = CountingField(body["field"])
    with torch.no_grad():
        image = GuidedImage(field, body["camera"], body["v"], body["f"], GUIDED, shell=body["shell"])
        image.render(None)
    assert field.threads and set(field.threads) == {expected}
    assert torch.get_num_threads() == 2 and image.alpha.max() > 0.9


def test_render_time_field_calls_on_few_points_run_on_one_thread(two_threads, monkeypatch):
    import numpy as np

    from texvocab.body import default_body
    from texvocab.body.poses import preset
    from texvocab.method import field as field_module
    from texvocab.method.encoder import build_encoder
    from texvocab.method.feature import PoseFeature
    from texvocab.method.field import AvatarField
    from texvocab.method.vocab import Vocabulary

    vocab = Vocabulary.build(np.random.default_rng(0).normal(0, 0.2, (4, 24, 3)), num_keys=4, k=2)
    model = AvatarField(PoseFeature(default_body(), vocab, torch.rand(4, 3, 32, 32), build_encoder("small")))
    seen = []
    inner = model.sdf_and_color

    def spy(*args, **kwargs):
        seen.append(torch.get_num_threads())
        return inner(*args, **kwargs)

    monkeypatch.setattr(model, "sdf_and_color", spy)
    ctx = model.pose_feature.context(*preset("walk"))
    pose_field = model.for_pose(ctx, "float32")
    pts = ctx.vertices.detach()[:50]
    dirs = torch.nn.functional.normalize(torch.ones_like(pts), dim=-1)
    with torch.no_grad():
        pose_field.sdf_rgb(pts, dirs)  # few points, rendering: one thread
        monkeypatch.setattr(field_module, "ONE_THREAD_POINTS", 10)
        pose_field.sdf_rgb(pts, dirs)  # "many" points: all threads
    pose_field.sdf_rgb(pts, dirs)  # autograd on (training): all threads
    assert seen == [1, 2, 2] and torch.get_num_threads() == 2
