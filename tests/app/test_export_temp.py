"""The viewer's video export writes its frames in a temporary folder named for its
process; the next export sweeps one left by a viewer that was killed, and nothing else."""

import subprocess

import numpy as np

from texvocab.io.temp_files import TEMP_NAME, host_tag
from texvocab.pipeline import Camera
from texvocab_viewer.export.job import Export


class _FlatExport(Export):
    def _render(self, i, camera):
        return np.full((8, 8, 3), 40 * i, np.uint8)


def test_a_video_export_sweeps_a_killed_viewers_frames(tmp_path):
    proc = subprocess.Popen(["true"])
    proc.wait()
    folder = tmp_path / "exports"
    stale = folder / f".walk-frames.tmp-{proc.pid}-{host_tag()}-abcd1234"
    (stale / "sub").mkdir(parents=True)
    mine = folder / ".walk-frames-notours"
    mine.mkdir()
    cam = Camera(np.eye(3), np.eye(3), np.zeros(3), 8, 8)
    job = _FlatExport(None, None, cam, np.zeros((2, 24, 3)), np.zeros((2, 3)), "walk", 10.0, folder=folder)
    job.thread.join(60)
    assert job.error == "" and job.path.is_file()
    assert not stale.exists() and mine.is_dir()
    assert not [p for p in folder.iterdir() if TEMP_NAME.match(p.name)]  # its own is gone too
