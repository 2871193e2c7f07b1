"""The timeline's "Export video" and "Screenshot" buttons: neural renders of the loaded
sequence (or the current pose) from the 3D view's camera, in a background thread so the
window stays live; files go to ``exports/`` under the working folder with names that
never replace an existing file. The same frame renderer and MP4 writer as
``texvocab render`` (:mod:`texvocab.pipeline.clip`)."""

from __future__ import annotations

import shutil
import tempfile
import threading
import traceback
from pathlib import Path

import numpy as np

from texvocab.pipeline import save_png, sweep_stale, temp_prefix, write_mp4
from texvocab_viewer.export.shot import render_neural

EXPORT_DIR = Path("exports")


class ExportCancelled(Exception):
    """Raised inside the export's render when :meth:`Export.cancel` was called."""


def fresh_path(folder: Path, stem: str, suffix: str) -> Path:
    """folder/stem+suffix, or stem_2, stem_3, ... if taken (nothing is replaced)."""
    path, n = folder / f"{stem}{suffix}", 2
    while path.exists():
        path, n = folder / f"{stem}_{n}{suffix}", n + 1
    return path


class Export:
    """One background job: ``frames`` (poses (T, 24, 3), trans (T, 3)) rendered with
    ``model`` from ``camera`` (an OpenCV camera, or a list of one per frame) and written
    as an MP4 at ``fps`` (T > 1) or, for one frame, as neural.png beside ``view3d`` (an
    (H, W, 3) uint8 3D view) in a fresh folder (``model`` None: view3d alone). Every
    frame is rendered as ``texvocab shot`` renders one, over ``background`` (the 3D
    view's). ``done`` / ``total`` count frames; ``path`` is set when written, ``error``
    on failure. :meth:`cancel` stops it between ray chunks and removes what it began."""

    def __init__(
        self,
        model,
        march,
        camera,
        poses,
        trans,
        stem: str,
        fps: float = 30.0,
        view3d: np.ndarray | None = None,
        folder: Path = EXPORT_DIR,
        background=(0.0, 0.0, 0.0),
    ):
        self.model, self.march, self.camera = model, march, camera
        self.poses, self.trans, self.fps, self.view3d = poses, trans, float(fps), view3d
        self.stem, self.folder = stem, Path(folder)
        self.background = tuple(background)
        self.done, self.total = 0, len(poses)
        self.path: Path | None = None
        self.error = ""
        self.cancelled = threading.Event()
        self._partial: list[Path] = []  # what a cancelled job removes (frames, a shot folder)
        self.thread = threading.Thread(target=self._run, name="texvocab-export", daemon=True)
        self.thread.start()

    @property
    def running(self) -> bool:
        return self.thread.is_alive()

    def cancel(self, timeout: float = 1.5) -> bool:
        """Stop the job (its render checks between ray chunks) and wait up to ``timeout``
        seconds; whatever it began writing is removed (a finished file stays). True if it
        stopped."""
        self.cancelled.set()
        self.thread.join(timeout)
        for path in self._partial:
            if path.is_dir():
                shutil.rmtree(path, ignore_errors=True)
            else:
                path.unlink(missing_ok=True)
        return not self.thread.is_alive()

    def _check(self) -> bool:
        if self.cancelled.is_set():
            raise ExportCancelled
        return False

    def _render(self, i: int, camera) -> np.ndarray:
        self._check()
        return render_neural(
            self.model, self.march, self.poses[i], self.trans[i], camera, self.background, self._check
        )

    def _run(self) -> None:
        import torch

        torch.set_num_threads(1)  # as texvocab render's frame worker: the UI keeps a core
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            if self.total == 1:
                out = fresh_path(self.folder, self.stem, "")
                out.mkdir()
                self._partial.append(out)
                if self.model is not None:  # as texvocab shot renders it
                    save_png(out / "neural.png", self._render(0, self.camera))
                if self.view3d is not None:
                    save_png(out / "view3d.png", self.view3d)
                self._partial.remove(out)
                self.done, self.path = 1, out
                return
            out = fresh_path(self.folder, self.stem, ".mp4")
            sweep_stale(self.folder)  # the frames of an export whose viewer was killed
            frames = temp_prefix(f"{self.stem}-frames")  # named for this process
            with tempfile.TemporaryDirectory(dir=self.folder, prefix=frames) as tmp:
                self._partial.append(Path(tmp))
                paths = []
                for i in range(self.total):
                    cam = self.camera[i] if isinstance(self.camera, list) else self.camera
                    paths.append(save_png(Path(tmp) / f"frame_{i:05d}.png", self._render(i, cam)))
                    self.done = i + 1
                self._check()
                write_mp4(paths, out, self.fps)
            self.path = out
        except ExportCancelled:
            self.error = "cancelled"
        except Exception as exc:  # shown in the panel; the window keeps running
            self.error = f"{type(exc).__name__}: {exc}"
            traceback.print_exc()
