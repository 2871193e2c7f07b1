"""Native file dialogs for the viewer (imgui-bundle's portable-file-dialogs).

On Linux those dialogs are the desktop's own programs (zenity, kdialog, qarma or
matedialog) run as a child process; :class:`FileDialogs` opens one at a time without
blocking the window and hands its answer back through :meth:`FileDialogs.poll`. With
none of those programs installed, :meth:`FileDialogs.missing` says so and the panels keep
their path fields.
"""

from __future__ import annotations

import functools
import os
import shutil
import sys

from imgui_bundle import portable_file_dialogs as pfd

#: what portable-file-dialogs runs on Linux, in its order of preference
DIALOG_PROGRAMS = ("zenity", "matedialog", "qarma", "kdialog")
POSE_FILTERS = ["Pose files (.npz)", "*.npz", "All files", "*"]
SOURCE_FILTERS = ["Checkpoints (.pt)", "*.pt", "All files", "*"]


@functools.lru_cache(maxsize=4)
def _dialog_program_found(path: str) -> bool:
    """Whether a dialog program (zenity, kdialog, ...) is on the search path ``path``."""
    return any(shutil.which(p, path=path) for p in DIALOG_PROGRAMS)


class FileDialogs:
    """At most one open dialog; ``purpose`` tells the caller what its answer is for."""

    def __init__(self):
        self._dialog = None
        self._purpose = ""

    @staticmethod
    def missing() -> str:
        """Why no native dialog can open here ("" when one can). The menu asks every
        frame; the search runs once per PATH value (:func:`_dialog_program_found`)."""
        path = os.environ.get("PATH", os.defpath)
        if sys.platform.startswith("linux") and not _dialog_program_found(path):
            return "no file dialog program found (install zenity or kdialog); type the path instead"
        return ""

    @property
    def open(self) -> bool:
        return self._dialog is not None

    def ask(self, purpose: str, title: str, filters: list[str], start: str = "") -> None:
        """Open a file dialog for ``purpose`` (ignored while another one is open)."""
        if self._dialog is None and not self.missing():
            self._dialog, self._purpose = pfd.open_file(title, start, filters), purpose

    def poll(self) -> tuple[str, str] | None:
        """(purpose, chosen path) once the dialog closed with a file; None otherwise
        (still open, none open, or cancelled)."""
        if self._dialog is None or not self._dialog.ready(0):
            return None
        chosen, self._dialog = self._dialog.result(), None
        return (self._purpose, chosen[0]) if chosen else None
