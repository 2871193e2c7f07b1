"""Vocabulary panel: per body part, the K keys the current pose selects (key id, source
frame t, weight bar, thumbnail of the key's texture map U_t) and the part's distance to
its nearest key; clicking a key moves that part's pose to the key.

Widget IDs: window "Vocabulary", key buttons ``<part>/keys/key<K>`` (K = key id; the
test engine's "**" wildcard does not reach into the table).
"""
from __future__ import annotations

import numpy as np
from imgui_bundle import imgui

THUMB = 64  # thumbnail side, texels
THUMB_PX = 36  # thumbnail side on screen, pixels


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
            small = np.ascontiguousarray((np.clip(img[::step, ::step], 0, 1) * 255 + 0.5)
                                         .astype(np.uint8))
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


def _key_cell(viewer, part: str, key_id: int, frame: int, weight: float) -> None:
    """Thumbnail button, key id and source frame beside it, the weight bar below."""
    size = imgui.ImVec2(THUMB_PX, THUMB_PX)
    if viewer.thumbs is not None and viewer.data.textures is not None:
        ref = imgui.ImTextureRef(viewer.thumbs.get(frame).glo)
        clicked = imgui.image_button(f"key{key_id}", ref, size)
    else:
        clicked = imgui.button(f"{key_id}##key{key_id}", size)
    if imgui.is_item_hovered():
        imgui.set_tooltip(f"key {key_id} of {part.replace('_', ' ')}: the texture map of "
                          f"training frame t = {frame}.\nClick to move the part to this key.")
    if clicked:
        viewer.state.set_part_to_key(part, key_id)
    imgui.same_line()
    imgui.begin_group()
    imgui.text(f"key {key_id}")
    imgui.text_disabled(f"t = {frame}")
    imgui.end_group()
    imgui.progress_bar(weight, imgui.ImVec2(-1, 0), f"{weight:.2f}")


def _part_row(viewer, q) -> None:
    """One body part: name, nearest-key distance, then its K keys side by side."""
    imgui.push_id(q.part)
    imgui.text(q.part.replace("_", " "))
    imgui.same_line()
    imgui.text_disabled(f"  nearest key d = {q.novelty:.4f}")
    keys = [(int(k), int(f), float(w)) for k, f, w in
            zip(q.key_ids, q.frames, q.weights, strict=True)]
    viewer.drawn_keys[q.part] = keys
    if imgui.begin_table("keys", max(len(keys), 1), imgui.TableFlags_.sizing_stretch_same):
        for key_id, frame, weight in keys:
            imgui.table_next_column()
            _key_cell(viewer, q.part, key_id, frame, weight)
        imgui.end_table()
    imgui.separator()
    imgui.pop_id()


def draw_vocab_panel(viewer) -> None:
    """The "Vocabulary" window's contents."""
    vocab = viewer.data.vocab
    if vocab is None:
        imgui.push_text_wrap_pos(0.0)
        imgui.text_disabled("No vocabulary: open a capture folder or a checkpoint "
                            "(texvocab view CAPTURE | CHECKPOINT.pt).")
        imgui.pop_text_wrap_pos()
        return
    imgui.text_disabled(f"{vocab.strategy}: {len(vocab.key_frames[0])} keys/part, "
                        f"K = {vocab.k}, weights: {vocab.weighting}")
    imgui.separator()
    for q in viewer.state.query():
        _part_row(viewer, q)
