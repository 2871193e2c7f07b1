"""The front door's shared world: a tiny capture and a 2-step checkpoint on it."""

import pytest
from readonly_mount import unmount_all
from train_cases import tiny_settings

from texvocab.body import default_body
from texvocab.capture import open as open_capture
from texvocab.capture.motion import make_sequence
from texvocab.capture.synth import SynthSettings, synthesize
from texvocab.pipeline.train import Trainer


@pytest.fixture(scope="module")
def world(tmp_path_factory, request):
    """base/cap (6 views, 64², 5 frames, 4 training), base/run/checkpoint.pt (2 steps);
    read-only mounts the cases make under base are unmounted after the module."""
    base = tmp_path_factory.mktemp("front_door")
    request.addfinalizer(unmount_all)
    poses, trans = make_sequence([("walk", 3), ("arm_raise", 2)], seed=5)
    cap = synthesize(
        base / "cap",
        poses,
        trans,
        4,
        default_body(),
        SynthSettings(ring_views=6, raised_views=0, size=64, texture_size=256),
        progress=False,
    )
    trainer = Trainer(
        open_capture(cap), tiny_settings(iterations=2, perceptual="off"), base / "run", progress=False
    )
    trainer.run()
    return base
