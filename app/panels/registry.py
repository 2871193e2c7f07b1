"""The viewer's docked panels, in the order the window lists them: each one's title (its
window's, and the ImGui Test Engine's reference), the dock space it opens in and its
``draw(viewer)``; and the dock spaces, split off the window's main one."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from imgui_bundle import hello_imgui, imgui

from texvocab_viewer.panels.neural import draw_neural_panel
from texvocab_viewer.panels.pose import draw_pose_panel
from texvocab_viewer.panels.view import draw_view_panel
from texvocab_viewer.panels.vocab import draw_vocab_panel

MAIN_SPACE = "MainDockSpace"  # hello_imgui's full-window dock space


@dataclass(frozen=True)
class Panel:
    """One docked panel: ``title``, its dock ``space`` (``space_without_model`` when no
    trained avatar is loaded, if it differs) and ``draw(viewer)``."""

    title: str
    space: str
    draw: Callable[[object], None]
    space_without_model: str | None = None

    def space_for(self, has_model: bool) -> str:
        if has_model or self.space_without_model is None:
            return self.space
        return self.space_without_model


PANELS = (
    Panel("Pose", "PoseSpace", draw_pose_panel),
    Panel("3D view", MAIN_SPACE, draw_view_panel),
    # without a model the panel only explains why it is empty: a tab beside Vocabulary
    Panel("Neural render", "NeuralSpace", draw_neural_panel, space_without_model="VocabSpace"),
    Panel("Vocabulary", "VocabSpace", draw_vocab_panel),
)


def dock_splits(has_model: bool) -> list[hello_imgui.DockingSplit]:
    """The dock spaces: Pose on the left, Vocabulary on the right and, with a model, the
    Neural render between the 3D view and Vocabulary."""
    splits = [
        hello_imgui.DockingSplit(MAIN_SPACE, "PoseSpace", imgui.Dir.left, 0.22),
        hello_imgui.DockingSplit(MAIN_SPACE, "VocabSpace", imgui.Dir.right, 0.30),
    ]
    if has_model:
        splits.append(hello_imgui.DockingSplit(MAIN_SPACE, "NeuralSpace", imgui.Dir.right, 0.5))
    return splits
