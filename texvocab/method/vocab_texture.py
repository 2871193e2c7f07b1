"""The vocabulary's texture for a pose, as a picture: per body part the K selected keys'
texture maps blended with their weights (Eq. 5 applied to U_t instead of features),
each texel taking the blend of the part(s) it belongs to with the skinning attention
Ω(x, p) of Sec. 3.4 (Eq. 8):

    U(Θ)[x] = Σ_p Ω(x, p) Σ_k ŵ_{p,k} U_{t(p,k)}[x].

Texels deep inside one part (Ω = 1) show exactly that part's blend; texels near a part
boundary mix the neighbouring parts' blends as the pose feature does. For viewers.
"""

from __future__ import annotations

import numpy as np
import torch

from texvocab.body.parts import part_attention
from texvocab.geometry.uv import texel_map
from texvocab.method._blend_jit import blend_texels


def part_coefficients(vocab, pose, query=None) -> tuple[np.ndarray, np.ndarray]:
    """The vocabulary query of one pose as blend coefficients per (part, frame).

    Args:
        pose: (24, 3) axis-angle.
        query: ``vocab.query(pose)`` when the caller has it already (the viewer's frame
            asks once for the panel and the texture); computed here otherwise.

    Returns:
        frames (U,) the distinct training frames any part's keys point to; coef (P, U):
        Σ_k ŵ_{p,k} over the keys of part p pointing to frame u (rows sum to one).
    """
    parts = vocab.query(np.asarray(pose, dtype=np.float64)) if query is None else query
    all_frames = np.concatenate([np.asarray(q.frames, np.int64) for q in parts])
    frames, inverse = np.unique(all_frames, return_inverse=True)
    coef = np.zeros((vocab.num_parts, len(frames)), np.float64)
    start = 0
    for p, q in enumerate(parts):
        k = len(q.weights)
        np.add.at(coef[p], inverse[start : start + k], np.asarray(q.weights, np.float64))
        start += k
    return frames, coef


class VocabTexture:
    """Blends a vocabulary's key texture maps for any pose.

    Args:
        body: the :class:`~texvocab.body.BodyModel` (with UVs) the texture maps belong to.
        vocab: :class:`~texvocab.method.vocab.Vocabulary` whose key frames index ``textures``.
        textures: (T, S, S, 3) float32 texture maps U_t of the training frames.
    """

    def __init__(self, body, vocab, textures: np.ndarray):
        textures = np.asarray(textures, dtype=np.float32)
        if textures.ndim != 4 or textures.shape[3] != 3 or textures.shape[1] != textures.shape[2]:
            raise ValueError(f"textures must be (T, S, S, 3), got {textures.shape}")
        top = max(int(kf.max()) for kf in vocab.key_frames)
        if top >= len(textures):
            raise ValueError(
                f"the vocabulary points to frame {top}, but only {len(textures)} texture maps were given"
            )
        self.vocab, self.textures = vocab, textures
        self.size = textures.shape[1]
        self.tmap = texel_map(body, self.size)
        weights = self.tmap.interpolate(body.weights.double().numpy(), body.faces.numpy())
        #: (N, P) attention Ω of each covered texel to each vocabulary part
        self.attention = part_attention(torch.as_tensor(weights), vocab.part_joints).numpy()
        # (T, N, 3) row-major: one frame's covered texels contiguous for the gathers
        self._flat = np.ascontiguousarray(
            textures.reshape(len(textures), -1, 3)[:, self.tmap.covered.reshape(-1)]
        )
        # per part: the texels attending to it at all, and their attention (float32)
        self._part_texels = []
        for p in range(self.attention.shape[1]):
            idx = np.nonzero(self.attention[:, p] > 0)[0]
            self._part_texels.append((idx, self.attention[idx, p, None].astype(np.float32)))
        # the same lists back to back for the compiled blend (part p: ptr[p]..ptr[p + 1])
        self._ptr = np.cumsum([0] + [len(i) for i, _ in self._part_texels]).astype(np.int64)
        self._idx = np.concatenate([i for i, _ in self._part_texels]).astype(np.int64)
        self._omega = np.concatenate([o[:, 0] for _, o in self._part_texels])

    def blend(self, pose, query=None) -> np.ndarray:
        """(S, S, 3) float32 blended texture for a pose (24, 3); uncovered texels copy
        the nearest covered texel (as the texture maps themselves do). ``query``: the
        pose's ``vocab.query`` if the caller has it."""
        frames, coef = part_coefficients(self.vocab, pose, query)
        colour = np.zeros((self._flat.shape[1], 3), np.float32)
        blend_texels(
            self._flat,
            frames.astype(np.int64),
            coef.astype(np.float32),
            self._ptr,
            self._idx,
            self._omega,
            colour,
        )
        return self.tmap.to_image(colour, fill=True)

    def blend_reference(self, pose) -> np.ndarray:
        """:meth:`blend` in numpy, part by part and frame by frame (the test reference)."""
        frames, coef = part_coefficients(self.vocab, pose)
        colour = np.zeros((self._flat.shape[1], 3), np.float32)
        for (idx, omega), row in zip(self._part_texels, coef, strict=True):
            if len(idx) == 0:
                continue
            blend = np.zeros((len(idx), 3), np.float32)  # Eq. 5 on this part's texels
            for u in np.nonzero(row > 0)[0]:  # np.take: 4x faster than [frame, idx]
                blend += np.float32(row[u]) * np.take(self._flat[frames[u]], idx, axis=0)
            colour[idx] += omega * blend
        return self.tmap.to_image(colour, fill=True)
