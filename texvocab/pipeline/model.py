"""Building the avatar model of a run from its settings and its capture: the training
views, the texture maps back-projected from them (Eq. 2), the texture vocabulary (Eqs.
3-4) and the field on the pose feature (Eqs. 1, 5-9). Training builds a fresh one;
loading a checkpoint (:mod:`texvocab.pipeline.avatar`) rebuilds it with the stored
vocabulary before loading the weights.
"""

from __future__ import annotations

import logging

import torch

from texvocab.errors import TexvocabError
from texvocab.method.encoder import build_encoder
from texvocab.method.feature import PoseFeature
from texvocab.method.field import AvatarField
from texvocab.method.texmap import (
    TexmapSettings,
    coverage_note,
    load_texture_map,
    prepare_texture_maps,
    seen_texel_share,
)
from texvocab.method.unseen_texels import fill_unseen_texels
from texvocab.method.vocab import Vocabulary
from texvocab.pipeline.settings import Settings
from texvocab.pipeline.split import one_camera, one_camera_train_views

log = logging.getLogger("texvocab")


def train_views(capture, s: Settings) -> list[int]:
    """The views a run trains on: ``data.train_views``, or every view not held out. The
    held-out ``data.eval_views`` must exist in the capture (the defaults need views 1 and
    5); a one-camera capture trains on its camera and holds out frames only."""
    data = s.data
    if one_camera(capture):
        return one_camera_train_views(capture, data.train_views)
    last = capture.num_views - 1
    bad_eval = [v for v in data.eval_views if v > last]
    if bad_eval:
        raise TexvocabError(
            f"setting data.eval_views={list(data.eval_views)}: {capture.root} "
            f"has views 0..{last}; choose held-out views that exist (--set "
            "data.eval_views=...)"
        )
    if data.train_views is not None:
        views = list(data.train_views)
    else:
        views = [v for v in range(capture.num_views) if v not in data.eval_views]
    bad = [v for v in views if not 0 <= v <= last]
    if bad or not views:
        raise TexvocabError(
            f"setting data.train_views={views}: {capture.root} has views "
            f"0..{last} and eval_views {list(data.eval_views)} are held out"
        )
    return views


def texmap_settings(capture, s: Settings) -> TexmapSettings:
    """Texture-map settings of a run: its texture size and its training views."""
    return TexmapSettings(
        size=s.data.texture_size, views=tuple(train_views(capture, s)), view_weighting=s.data.view_weighting
    )


def load_textures(capture, s: Settings, progress: bool = True) -> torch.Tensor:
    """(T, 3, S, S) texture maps of the training frames, back-projected from the training
    views only (prepared and cached if needed), their unseen texels filled as
    ``data.unseen_texels`` says (:mod:`texvocab.method.unseen_texels`)."""
    paths = prepare_texture_maps(capture, texmap_settings(capture, s), progress=progress)
    maps = [load_texture_map(p) for p in paths]
    textures = torch.stack([torch.from_numpy(t).permute(2, 0, 1) for t, _ in maps])
    coverage = torch.stack([torch.from_numpy(c) for _, c in maps])
    _, warning = coverage_note(seen_texel_share(coverage.numpy(), capture.body), capture.frame_ids)
    if warning is not None:
        log.warning("%s: %s", capture.root, warning)
    return fill_unseen_texels(textures, coverage, s.data.unseen_texels)


def build_vocabulary(capture, s: Settings) -> Vocabulary:
    """The texture vocabulary of the capture's training poses (``vocab`` settings)."""
    v = s.vocab
    return Vocabulary.build(
        capture.poses[: capture.num_train],
        v.strategy,
        v.num_keys,
        v.k,
        v.weighting,
        v.min_key_distance,
        v.pose_condition,
    )


def build_model(
    capture, s: Settings, textures: torch.Tensor, vocab: Vocabulary | None = None, encoder_weights=None
) -> AvatarField:
    """The avatar field for a capture's training frames (vocabulary built unless given)."""
    vocab = vocab or build_vocabulary(capture, s)
    encoder = build_encoder(s.vocab.encoder, weights=encoder_weights)
    return AvatarField(PoseFeature(capture.body, vocab, textures, encoder, capture.shape()), s.field)


TEXTURES_KEY = "pose_feature.textures"


def load_stored_textures(model, weights: dict, source) -> dict:
    """The texture maps a checkpoint stored (written before they were left out of it) put
    into ``model``, so it renders with the very maps it trained with; returns the other
    weights. A stored stack of another shape is an error naming ``source``."""
    if TEXTURES_KEY not in weights:
        return weights
    rest = {k: v for k, v in weights.items() if k != TEXTURES_KEY}
    stored, ours = weights[TEXTURES_KEY], model.pose_feature.textures
    if tuple(stored.shape) != tuple(ours.shape):
        raise TexvocabError(
            f"{source}: its texture maps are {tuple(stored.shape)}, the capture's "
            f"{tuple(ours.shape)} (another capture, split or texture size?)"
        )
    with torch.no_grad():
        ours.copy_(stored)
    return rest
