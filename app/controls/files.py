"""The File menu: open a checkpoint or capture (in the background; the window then
reopens on it), open a pose file, screenshot; the desktop's file dialogs' answers. Errors
go to the status line (:mod:`texvocab_viewer.status`)."""

from __future__ import annotations

import threading

from imgui_bundle import hello_imgui, imgui

from texvocab_viewer.dialogs import POSE_FILTERS, SOURCE_FILTERS
from texvocab_viewer.panels.pose import load_sequence
from texvocab_viewer.state import load_viewer_data


class FileControls:
    """Mixed into the Viewer: ``dialogs``, ``reopen`` (the data File > Open loaded),
    ``open_error`` and the ``status`` line."""

    def show_menus(self) -> None:
        """The File menu: open a checkpoint or capture (the window restarts on it), open a
        pose file, screenshot."""
        missing = self.dialogs.missing()
        if imgui.begin_menu("File"):
            if imgui.menu_item("Open checkpoint...", "", False, not missing)[0]:
                self.dialogs.ask("source", "Open a checkpoint", SOURCE_FILTERS)
            if imgui.menu_item("Open pose file...", "", False, not missing)[0]:
                self.dialogs.ask("poses", "Open a pose file", POSE_FILTERS, self.sequence_path)
            if missing:
                imgui.text_disabled(missing)
            imgui.separator()
            if imgui.menu_item("Screenshot", "F12", False, True)[0]:
                self.screenshot()
            imgui.end_menu()

    def poll_dialogs(self) -> None:
        """Act on a file dialog's answer (once per frame)."""
        if self.reopen is not None:
            hello_imgui.get_runner_params().app_shall_exit = True
        answer = self.dialogs.poll()
        if answer is None:
            return
        purpose, path = answer
        if purpose == "poses":
            load_sequence(self, path)
        elif purpose == "source":
            self.open_source(path)

    def open_source(self, path: str) -> None:
        """Load a checkpoint or capture in the background; when it loaded, the window
        closes and reopens on it (the pose sequence stays); an error goes to the status line
        and the window stays as it was."""

        def load() -> None:
            try:
                self.reopen = load_viewer_data(path, self.smpl)
            except Exception as exc:  # noqa: BLE001 - any failure is shown, the window stays
                self.open_error = f"{path}: {exc}"
                self.status.fail(f"could not open {self.open_error}")
            hello_imgui.request_refresh()

        self.open_error = ""
        self.status.done(f"opening {path} ...")
        threading.Thread(target=load, name="texvocab-open", daemon=True).start()
