"""Where the docked panels go for a window size, so that each keeps a usable size:

- **wide** (at least :data:`WIDE` pixels): four columns, Pose | 3D view | Neural render |
  Vocabulary;
- **medium**: three columns, Pose | the 3D view over the Neural render | Vocabulary;
- **narrow**: two columns, Pose and Vocabulary as tabs | the 3D view over the Neural
  render, or, in a window under :data:`TALL` pixels high, the two as tabs;
- **tabs** (under :data:`NARROW` pixels, where two columns cannot both keep their floor):
  one column, the four panels as tabs, each the window's whole width.

Without a trained avatar the Neural render panel only says why it is empty: a tab beside
Vocabulary (beside the 3D view in a short narrow window). Column widths are fractions of
the window with a floor in pixels (:data:`MIN_WIDTH`); a panel's contents scroll when they
need more room. When the window is resized so that another layout applies, or a panel
falls under its floor, the panels dock anew (:func:`needs_relayout`).
"""

from __future__ import annotations

from dataclasses import dataclass

from imgui_bundle import hello_imgui, imgui

MAIN = "MainDockSpace"  # hello_imgui's full-window dock space: the 3D view's
WIDE = 1100  # window width from which the four columns fit
MEDIUM = 840  # from which three do
NARROW = 590  # from which two columns do (the Vocabulary's floor and the 3D view's)
TALL = 560  # window height from which the 3D view and the neural render fit one above the other
#: smallest width of a column in pixels, per panel
MIN_WIDTH = {"Pose": 250, "Vocabulary": 270, "Neural render": 220, "3D view": 320}
#: the neural render's share of the column it shares with the 3D view (one above the other)
NEURAL_BELOW = 0.42


@dataclass(frozen=True)
class Split:
    """One dock split: ``new`` is cut from ``parent`` on side ``side`` ("left", "right",
    "down") with ``ratio`` of the parent's size."""

    parent: str
    new: str
    side: str
    ratio: float


@dataclass(frozen=True)
class Layout:
    """``kind`` ("wide", "medium", "narrow", "tabs"), the dock ``splits`` in order and each
    panel's dock space by title (``spaces``); panels that share a space are tabs."""

    kind: str
    splits: tuple[Split, ...]
    spaces: dict[str, str]


def _share(pixels: float, of: float) -> float:
    return min(0.9, max(0.05, pixels / max(of, 1.0)))


def layout_for(width: int, height: int, has_model: bool) -> Layout:
    """The layout of a ``width`` x ``height`` window (see the module docstring)."""
    w = float(width)
    if w < NARROW:
        return Layout("tabs", (), {name: MAIN for name in ("Pose", "3D view", "Neural render", "Vocabulary")})
    if w >= WIDE:
        pose = max(MIN_WIDTH["Pose"], 0.22 * w)
        vocab = max(MIN_WIDTH["Vocabulary"], 0.30 * (w - pose))
        splits = [Split(MAIN, "PoseSpace", "left", _share(pose, w))]
        splits.append(Split(MAIN, "VocabSpace", "right", _share(vocab, w - pose)))
        spaces = {"Pose": "PoseSpace", "3D view": MAIN, "Vocabulary": "VocabSpace"}
        if has_model:  # half the rest, or less so that the 3D view keeps its floor
            rest = w - pose - vocab
            neural = max(MIN_WIDTH["Neural render"], min(rest / 2, rest - MIN_WIDTH["3D view"]))
            splits.append(Split(MAIN, "NeuralSpace", "right", _share(neural, rest)))
            spaces["Neural render"] = "NeuralSpace"
        else:
            spaces["Neural render"] = "VocabSpace"
        return Layout("wide", tuple(splits), spaces)
    below = [Split(MAIN, "NeuralSpace", "down", NEURAL_BELOW)] if has_model else []
    if w >= MEDIUM:
        pose, vocab = MIN_WIDTH["Pose"], MIN_WIDTH["Vocabulary"]
        splits = [
            Split(MAIN, "PoseSpace", "left", _share(pose, w)),
            Split(MAIN, "VocabSpace", "right", _share(vocab, w - pose)),
            *below,
        ]
        neural = "NeuralSpace" if has_model else "VocabSpace"
        spaces = {"Pose": "PoseSpace", "3D view": MAIN, "Neural render": neural, "Vocabulary": "VocabSpace"}
        return Layout("medium", tuple(splits), spaces)
    side = max(MIN_WIDTH["Pose"], MIN_WIDTH["Vocabulary"], 0.4 * w)  # the two share it
    splits = [Split(MAIN, "PoseSpace", "left", _share(side, w))]
    stacked = has_model and height >= TALL
    if stacked:
        splits += below
    neural = "NeuralSpace" if stacked else MAIN
    spaces = {"Pose": "PoseSpace", "Vocabulary": "PoseSpace", "3D view": MAIN, "Neural render": neural}
    return Layout("narrow", tuple(splits), spaces)


SIDES = {"left": imgui.Dir.left, "right": imgui.Dir.right, "down": imgui.Dir.down}


def dock_splits(layout: Layout) -> list[hello_imgui.DockingSplit]:
    """hello_imgui's dock splits of ``layout``."""
    return [hello_imgui.DockingSplit(s.parent, s.new, SIDES[s.side], s.ratio) for s in layout.splits]


def needs_relayout(current: Layout, wanted: Layout, resized: bool, widths: dict[str, float]) -> bool:
    """Whether to dock the panels anew: the window's size calls for another layout, or it
    was resized and a panel drawn ``widths`` wide (by title) lies under its floor (a user's
    own splitter drags are kept otherwise)."""
    if (wanted.kind, wanted.spaces) != (current.kind, current.spaces):
        return True
    return resized and any(w < MIN_WIDTH[name] - 2 for name, w in widths.items())
