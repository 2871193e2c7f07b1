"""Shared training-test cases: a tiny model's settings."""
import sys
from pathlib import Path

from texvocab.method.field import FieldSettings
from texvocab.pipeline.settings import Settings

TEXVOCAB = str(Path(sys.executable).parent / "texvocab")


def tiny_settings(**kw) -> Settings:
    base = dict(texture_size=64, num_keys=3, k=2, encoder="small", rays_per_batch=256,
                coarse_samples=8, fine_samples=8, iterations=40, checkpoint_every=10,
                field=FieldSettings(hidden=48, sdf_layers=2, color_layers=1, pos_freqs=4),
                lr=2e-3)
    base.update(kw)
    return Settings(**base)
