"""A tiny synthetic capture and a 2-step checkpoint on it, for tests that need a real run."""


def tiny_run(root, segments, num_train: int, views: int, field: dict, **settings):
    """A synthetic 64² capture of ``segments`` (motion.make_sequence) seen by ``views``
    ring cameras, and a checkpoint after 2 steps of a tiny model (FieldSettings(**field),
    ``settings`` by their flat names); returns the checkpoint's path (root/run/checkpoint.pt)."""
    from train_cases import flat_settings

    from texvocab.body import default_body
    from texvocab.capture import open as open_capture
    from texvocab.capture.motion import make_sequence
    from texvocab.capture.synth import SynthSettings, synthesize
    from texvocab.method.field import FieldSettings
    from texvocab.pipeline.train import Trainer

    poses, trans = make_sequence(segments[0], seed=segments[1])
    cap = synthesize(
        root / "cap",
        poses,
        trans,
        num_train,
        default_body(),
        SynthSettings(ring_views=views, raised_views=0, size=64, texture_size=128),
        progress=False,
    )
    s = flat_settings(encoder="small", iterations=2, field=FieldSettings(**field), **settings)
    trainer = Trainer(open_capture(cap), s, root / "run", progress=False)
    trainer.run()
    return trainer.checkpoint_path


def smallest_run(root):
    """The smallest real avatar: 2 frames (1 for training) x 3 views at 64 px, a 2-step
    run of a 16-wide model with one key per part; returns its checkpoint's path."""
    return tiny_run(
        root,
        ([("walk", 2)], 2),
        1,
        3,
        dict(hidden=16, sdf_layers=1, color_layers=1, pos_freqs=2),
        texture_size=32,
        num_keys=1,
        k=1,
        rays_per_batch=64,
        coarse_samples=8,
        fine_samples=4,
        checkpoint_every=2,
        eval_views=(1,),
    )
