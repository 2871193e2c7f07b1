"""The subject's own body: fit the capture's body to the rest joints the capture gives.

A capture that records the subject's SMPL rest joints (HumanNeRF's ``tpose_joints``) but no
betas drives a body of other proportions unless the body is fitted first: the embedded
default body's bones differ from ZJU-MoCap 387's by up to 8.4 cm. A body with a shape space
(the user's SMPL files) gets the betas whose rest joints match in least squares; the default
body, which has none, gets its skeleton moved onto the joints with its surface following
(:func:`texvocab.body.fit.fit_rest_joints`). Either way the root translation is re-based so
the body's pelvis stays on the subject's.
"""

from __future__ import annotations

import dataclasses
import hashlib
import logging

import numpy as np
import torch

from texvocab.body.fit import betas_from_rest_joints, fit_rest_joints
from texvocab.body.smplx_joints import read_smplx_model, smplx_rest_joints
from texvocab.capture.capture import Capture

log = logging.getLogger(__name__)


def fit_subject_body(cap: Capture) -> Capture:
    """``cap`` with its body fitted to ``cap.rest_joints`` (unchanged when it has none,
    already has betas, or its body already has those joints); ``meta["body_fit"]`` records
    how and a fingerprint of the fit."""
    rest = cap.rest_joints
    if rest is None or cap.betas is not None:
        return cap
    body = cap.body
    if np.abs(body.rest_joints.double().numpy() - np.asarray(rest)).max() < 1e-6:
        return cap  # already the subject's skeleton
    j0_before = body.rest_joints[0].double().numpy()
    if body.shapedirs is not None and body.J_regressor is not None:
        betas, err = betas_from_rest_joints(body, rest)
        shaped = body.J_regressor.double() @ (
            body.v_template.double()
            + torch.einsum("vcs,s->vc", body.shapedirs.double()[..., : len(betas)], torch.as_tensor(betas))
        )
        j0_after = shaped[0].numpy()
        log.info(
            "body: %s shape fitted to the capture's rest joints (%d betas, joint error %.1f mm)",
            body.name,
            len(betas),
            err * 1000,
        )
        fitted = dataclasses.replace(cap, betas=np.asarray(betas, np.float32))
        how = "betas"
    else:
        body = fit_rest_joints(body, rest)
        j0_after = np.asarray(rest[0], np.float64)
        fitted = dataclasses.replace(cap, body=body)
        how = "skeleton"
    digest = hashlib.sha1(np.ascontiguousarray(rest, np.float64).tobytes()).hexdigest()[:8]
    trans = (cap.trans + (j0_before - j0_after)).astype(cap.trans.dtype)
    return dataclasses.replace(fitted, trans=trans, meta={**cap.meta, "body_fit": f"{how}-{digest}"})


def smplx_subject(cap: Capture, smplx) -> Capture:
    """A capture with SMPL-X betas (THUman4.0, ``meta["smplx_betas"]``): with the user's
    SMPL-X model file ``smplx``, its rest joints from them (for :func:`fit_subject_body`,
    the root translation pre-shifted so that the fit's re-basing leaves SMPL-X's ``transl``
    in place); without one, unchanged. One log line says which."""
    betas = cap.meta.get("smplx_betas")
    if betas is None:
        return cap
    if smplx is None:
        log.info(
            "body: %s has SMPL-X betas but no SMPL-X model file was given (TEXVOCAB_SMPLX): "
            "the body keeps its own shape",
            cap.root,
        )
        return cap
    rest = smplx_rest_joints(read_smplx_model(smplx), betas, cap.body.rest_joints.double().numpy())
    log.info("body: fitted to the rest joints of %s's SMPL-X betas (model %s)", cap.root, smplx)
    shift = rest[0] - cap.body.rest_joints[0].double().numpy()
    return dataclasses.replace(cap, rest_joints=rest, trans=(cap.trans + shift).astype(cap.trans.dtype))
