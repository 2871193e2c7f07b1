"""A tiny synthetic capture and a 2-step checkpoint on it, for tests that need a real run."""
def tiny_run(root, segments, num_train: int, views: int, field: dict, **settings):
    """A synthetic 64² capture of ``segments`` (motion.make_sequence) seen by ``views``
    ring cameras, and a checkpoint after 2 steps of a tiny model (FieldSettings(**field),
    Settings(**settings)); returns the checkpoint's path (root/run/checkpoint.pt)."""
    from texvocab.body import default_body
    from texvocab.capture import open as open_capture
    from texvocab.capture.motion import make_sequence
    from texvocab.capture.synth import SynthSettings, synthesize
    from texvocab.method.field import FieldSettings
    from texvocab.pipeline.settings import Settings
    from texvocab.pipeline.train import Trainer

    poses, trans = make_sequence(segments[0], seed=segments[1])
    cap = synthesize(root / "cap", poses, trans, num_train, default_body(),
                     SynthSettings(ring_views=views, raised_views=0, size=64, texture_size=128),
                     progress=False)
    s = Settings(encoder="small", iterations=2, field=FieldSettings(**field), **settings)
    trainer = Trainer(open_capture(cap), s, root / "run", progress=False)
    trainer.run()
    return trainer.checkpoint_path
