"""The viewer's docked panels, in the order the window lists them: each one's title (its
window's, and the ImGui Test Engine's reference) and its ``draw(viewer)``. Where each one
docks depends on the window's size (:mod:`texvocab_viewer.layout`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from texvocab_viewer.panels.neural import draw_neural_panel
from texvocab_viewer.panels.pose import draw_pose_panel
from texvocab_viewer.panels.view import draw_view_panel
from texvocab_viewer.panels.vocab import draw_vocab_panel


@dataclass(frozen=True)
class Panel:
    """One docked panel: ``title`` and ``draw(viewer)``."""

    title: str
    draw: Callable[[object], None]


PANELS = (
    Panel("Pose", draw_pose_panel),
    Panel("3D view", draw_view_panel),
    Panel("Neural render", draw_neural_panel),
    Panel("Vocabulary", draw_vocab_panel),
)
