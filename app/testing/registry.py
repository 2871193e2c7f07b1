"""Every scripted run of the viewer window by its ``--script`` name: the ImGui Test Engine
scripts (:mod:`.scripts`, :mod:`.daily_scripts`, :mod:`.window_scripts`,
:mod:`.mocap_scripts`) and the benchmark's per-frame driver
(``bench[:SECONDS[:RES[:RENDERS]]]``, :mod:`.bench`). :class:`Script` is what
:func:`texvocab_viewer.window.run_viewer` calls on each window it opens."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from texvocab.errors import TexvocabError
from texvocab_viewer.testing.bench import RENDERS, BenchDriver
from texvocab_viewer.testing.daily_scripts import DAILY_SCRIPTS
from texvocab_viewer.testing.driver import Driver, EngineDriver
from texvocab_viewer.testing.mocap_scripts import script_mocap_frames, script_mocap_novelty
from texvocab_viewer.testing.scripts import ENGINE_SCRIPTS
from texvocab_viewer.testing.window_scripts import WINDOW_SCRIPTS

#: every ImGui Test Engine script by name
SCRIPTS = {
    **ENGINE_SCRIPTS,
    **DAILY_SCRIPTS,
    **WINDOW_SCRIPTS,
    "mocap-frames": script_mocap_frames,
    "mocap-novelty": script_mocap_novelty,
}

#: a scripted run whose window reopens (File > Open) goes on with this script, whose
#: report replaces the first one
AFTER_REOPEN = {"open-checkpoint": "reopened"}


def make_driver(name: str, viewer, rp) -> Driver:
    """The driver for ``--script NAME``: an engine script or
    ``bench[:SECONDS[:RES[:RENDERS[:REST_LEVELS]]]]`` (REST_LEVELS: the levels of a
    dragged pose's full render once it rests, as ``8-4-2-1``; default the viewer's)."""
    if name.startswith("bench"):
        parts = name.split(":")
        seconds = float(parts[1]) if len(parts) > 1 else 8.0
        res = int(parts[2]) if len(parts) > 2 else 256
        renders = int(parts[3]) if len(parts) > 3 else RENDERS
        rest = tuple(int(x) for x in parts[4].split("-")) if len(parts) > 4 and parts[4] else None
        return BenchDriver(viewer, rp, seconds, res, renders, rest)
    check_script(name)
    return EngineDriver(name, SCRIPTS[name], viewer, rp)


def check_script(name: str) -> None:
    """TexvocabError naming --script unless ``name`` is a script or a bench spec."""
    if name not in SCRIPTS and not name.startswith("bench"):
        raise TexvocabError(
            f"--script {name!r}: expected one of {sorted(SCRIPTS)} or bench[:SECONDS[:RESOLUTION[:RENDERS]]]"
        )


@dataclass(frozen=True)
class Script:
    """``--script NAME`` with the files its ``report`` (JSON) and the window's last frame
    (``screenshot``, PNG) go to. Called with a viewer and its runner parameters before a
    window opens, it sets the run up (:class:`ScriptedRun`)."""

    name: str
    report: str | None = None
    screenshot: str | None = None

    def __post_init__(self) -> None:
        check_script(self.name)

    def __call__(self, viewer, rp) -> ScriptedRun:
        return ScriptedRun(self, make_driver(self.name, viewer, rp))


class ScriptedRun:
    """One window's scripted run (:class:`texvocab_viewer.window.ScriptedRun`)."""

    def __init__(self, script: Script, driver: Driver):
        self.script, self.driver = script, driver

    def finish(self, shot: np.ndarray | None, reopens: bool) -> tuple[int, Script | None]:
        """Write the report and ``shot`` (the last frame); the exit code, and the script
        of the window that reopens (``reopens``) if the run goes on there."""
        rc = self.driver.finish(self.script.report, self.script.screenshot, shot)
        after = AFTER_REOPEN.get(self.script.name) if reopens else None
        return rc, None if after is None else replace(self.script, name=after)
