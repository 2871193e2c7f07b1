"""Vocabulary panel: per body part, the K keys the current pose selects (key id, source
frame t, thumbnail of the key's texture map U_t), each key's distance d to the query
(Eq. 4), its raw weight (Eq. 6: J_p - d for the paper's weighting, 1/d for inverse) and the
share of the part's feature its texture contributes after normalisation (the bar), with
how far that share is from uniform 1/K; under it, the key's distance as a bar against
the part's range (0 to its farthest key), which shows the choice where the paper's
weights stay near 1/K; and the part's distance to its nearest key. The parts the last edit
moved are highlighted. Clicking a key moves that part's pose to the key.

Widget IDs: window "Vocabulary", key buttons ``<part>/keys/key<K>`` (K = key id; the
test engine's "**" wildcard does not reach into the table).
"""

from __future__ import annotations

import numpy as np
from imgui_bundle import imgui

THUMB = 64  # thumbnail side, texels
THUMB_PX = 36  # thumbnail side on screen, pixels
MOVED_COLOUR = (1.0, 0.8, 0.3, 1.0)  # a part the last edit moved: its name and its mark
DISTANCE_COLOUR = (0.85, 0.5, 0.2, 1.0)  # the distance bars


class ThumbnailCache:
    """Small GL textures of training-frame texture maps, uploaded once per frame index.

    ``textures``: (T, S, S, 3) float32 in [0, 1], row 0 the top (v = 1) as in
    DESIGN.md, so the thumbnails show with uv (0, 0)-(1, 1).
    """

    def __init__(self, ctx, textures: np.ndarray | None, side: int = THUMB):
        self.ctx, self.textures, self.side = ctx, textures, side
        self._cache: dict[int, object] = {}

    def get(self, frame: int):
        tex = self._cache.get(frame)
        if tex is None:
            img = self.textures[frame]
            step = max(1, img.shape[0] // self.side)
            small = np.ascontiguousarray((np.clip(img[::step, ::step], 0, 1) * 255 + 0.5).astype(np.uint8))
            tex = self.ctx.texture((small.shape[1], small.shape[0]), 3, small.tobytes())
            tex.filter = (self.ctx.LINEAR, self.ctx.LINEAR)
            self._cache[frame] = tex
        return tex

    def __len__(self) -> int:
        return len(self._cache)

    def release(self) -> None:
        for tex in self._cache.values():
            tex.release()
        self._cache.clear()


def raw_weight(weighting: str, num_joints: int, d: float) -> float:
    """The unnormalised weight of a key at distance ``d`` (Eq. 6, or 1/d for inverse)."""
    if weighting == "paper":
        return max(num_joints - d, 0.0)
    return float("inf") if d <= 0 else 1.0 / d


def key_caption(weighting: str, num_joints: int, d: float, share: float, k: int) -> str:
    """ "d 0.0123 · w 2.988 · 33.4% (+0.1)" — distance, raw weight, share and its offset
    from uniform 1/K in percentage points."""
    w = raw_weight(weighting, num_joints, d)
    w_text = "exact" if w == float("inf") else f"{w:.4g}"
    return f"d {d:.4f}  w {w_text}  {100 * share:.1f}% ({100 * (share - 1 / k):+.1f})"


def distance_bar(d: float, farthest: float) -> float:
    """The length (0..1) of a key's distance bar: ``d`` against the part's range, 0 to its
    ``farthest`` key."""
    return float(min(max(d / farthest, 0.0), 1.0)) if farthest > 0 else 0.0


def _key_cell(
    viewer, part: str, key_id: int, frame: int, weight: float, d: float, num_joints: int, farthest: float
) -> None:
    """Thumbnail button, key id and source frame beside it; the share as a bar below, then
    d and the raw weight on the distance bar (d against 0 .. ``farthest``)."""
    size = imgui.ImVec2(THUMB_PX, THUMB_PX)
    if viewer.thumbs is not None and viewer.data.textures is not None:
        ref = imgui.ImTextureRef(viewer.thumbs.get(frame).glo)
        clicked = imgui.image_button(f"key{key_id}", ref, size)
    else:
        clicked = imgui.button(f"{key_id}##key{key_id}", size)
    if imgui.is_item_hovered():
        imgui.set_tooltip(
            f"key {key_id} of {part.replace('_', ' ')}: the texture map of "
            f"training frame t = {frame}.\nClick to move the part to this key."
        )
    if clicked:
        viewer.state.set_part_to_key(part, key_id)
    imgui.same_line()
    imgui.begin_group()
    imgui.text(f"key {key_id}")
    imgui.text_disabled(f"t = {frame}")
    imgui.end_group()
    vocab = viewer.data.vocab
    imgui.progress_bar(
        weight, imgui.ImVec2(-1, 0), f"{100 * weight:.1f}% ({100 * (weight - 1 / vocab.k):+.1f})"
    )
    caption = key_caption(vocab.weighting, num_joints, d, weight, vocab.k)
    bar = distance_bar(d, farthest)
    viewer.drawn_distances.setdefault(part, []).append((key_id, bar))
    imgui.push_style_color(imgui.Col_.plot_histogram, imgui.ImVec4(*DISTANCE_COLOUR))
    imgui.progress_bar(bar, imgui.ImVec2(-1, 0), caption.rsplit("  ", 1)[0])
    imgui.pop_style_color()
    if imgui.is_item_hovered():
        imgui.set_tooltip(_weight_tooltip(vocab.weighting, num_joints, caption))


def _weight_tooltip(weighting: str, num_joints: int, caption: str) -> str:
    if weighting == "paper":
        return (
            f"{caption}\nd: quaternion distance of the part's pose to this key (Eq. 4); the "
            "bar: d against the part's farthest key.\n"
            f"w = J_p - d with J_p = {num_joints} joints (Eq. 6), then normalised over the "
            "K keys.\nWith d much smaller than J_p every key gets about 1/K: the shares "
            "show how little d moves them."
        )
    return (
        f"{caption}\nd: quaternion distance of the part's pose to this key (Eq. 4).\n"
        "w = 1/d (inverse weighting), normalised over the K keys: the nearest key "
        "dominates."
    )


def _part_row(viewer, q, farthest: float, moved: bool) -> None:
    """One body part: name, nearest-key distance, then its K keys side by side (in rows
    when the panel is too narrow for all K)."""
    imgui.push_id(q.part)
    name = q.part.replace("_", " ")
    if moved:
        imgui.text_colored(imgui.ImVec4(*MOVED_COLOUR), f"{name}  (moved)")
        if imgui.is_item_hovered():
            imgui.set_tooltip(f"the last edit ({viewer.state.change}) turned a joint of the {name}")
    else:
        imgui.text(name)
    imgui.same_line()
    imgui.text_disabled(f"  nearest key d = {q.novelty:.4f}")
    if imgui.is_item_hovered():
        imgui.set_tooltip(f"the part's keys lie at d = {q.novelty:.4f} .. {farthest:.4f} from this pose")
    keys = [(int(k), int(f), float(w)) for k, f, w in zip(q.key_ids, q.frames, q.weights, strict=True)]
    viewer.drawn_keys[q.part] = keys
    vocab = viewer.data.vocab
    num_joints = len(vocab.part_joints[vocab.part_names.index(q.part)])
    # as many keys a row as fit their captions; the rest wrap to the next rows
    cell = THUMB_PX + imgui.calc_text_size("d 0.0000  w 2.988").x - THUMB_PX / 2
    columns = max(1, min(len(keys), int(imgui.get_content_region_avail().x // max(cell, 1.0))))
    if imgui.begin_table("keys", columns, imgui.TableFlags_.sizing_stretch_same):
        for (key_id, frame, weight), d in zip(keys, q.distances, strict=True):
            imgui.table_next_column()
            _key_cell(viewer, q.part, key_id, frame, weight, float(d), num_joints, farthest)
        imgui.end_table()
    imgui.separator()
    imgui.pop_id()


def draw_vocab_panel(viewer) -> None:
    """The "Vocabulary" window's contents."""
    vocab = viewer.data.vocab
    if vocab is None:
        imgui.push_text_wrap_pos(0.0)
        imgui.text_disabled(
            "No vocabulary: open a capture folder or a checkpoint (texvocab view CAPTURE | CHECKPOINT.pt)."
        )
        imgui.pop_text_wrap_pos()
        return
    imgui.text_disabled(
        f"{vocab.strategy}: {len(vocab.key_frames[0])} keys/part, K = {vocab.k}, weights: {vocab.weighting}"
    )
    imgui.separator()
    state = viewer.state
    moved = state.moved_parts()
    viewer.drawn_moved = list(moved)
    viewer.drawn_distances = {}
    for q, dists in zip(state.query(), state.key_distances(), strict=True):
        _part_row(viewer, q, float(dists.max()), q.part in moved)
