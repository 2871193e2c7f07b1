"""A body's girth: how far the subject's clothes stand off the body, as one offset per joint
blended over the surface by the skinning weights.

A body fitted to the rest joints (:mod:`texvocab.body.fit`) has the subject's proportions
but the default body's slim surface; on ZJU-MoCap 387 (a loose hoodie) its silhouette
covers 68 % of the masks. The avatar field starts from the body (SDF = d_body + a residual
that starts at zero), so every centimetre the clothes stand off the body is a centimetre
its residual must learn first. With a girth the field starts from the level set
``d_body = g`` instead, where ``g(x) = sum_j w_j o_j`` blends the per-joint offsets ``o``
by the skinning weights ``w`` of x's closest body point
(:meth:`texvocab.method.field.AvatarField.set_girth`). The body's mesh is not moved:
moving its vertices along their normals by the same offsets makes the surface cross
itself where limbs meet and at the face and hands, and the signed distance to such a mesh
is wrong inside it.

Fitting the offsets needs the silhouette of the offset surface in many frames. The mesh
moved along its normals (``v + n_v * sum_j w_vj o_j``) has that silhouette wherever it
does not fold, and posing is linear in its vertices, so the posed offset is the posed
normal times the same blend (:func:`posed_normals`): each candidate costs one
rasterisation per image.
"""

from __future__ import annotations

import numpy as np
import torch

from texvocab.body.lbs import lbs
from texvocab.body.model import BodyModel


def vertex_normals(vertices: torch.Tensor, faces: torch.Tensor) -> torch.Tensor:
    """(V, 3) unit area-weighted vertex normals of a mesh (vertices (V, 3), faces (F, 3));
    float64."""
    v = vertices.double()
    face_n = torch.cross(v[faces[:, 1]] - v[faces[:, 0]], v[faces[:, 2]] - v[faces[:, 0]], dim=1)
    n = torch.zeros_like(v).index_add_(0, faces.reshape(-1), face_n.repeat_interleave(3, 0))
    return n / n.norm(dim=1, keepdim=True).clamp_min(1e-12)


def vertex_offsets(body: BodyModel, offsets) -> torch.Tensor:
    """(V,) each rest vertex's offset along its normal (m): the skinning-weighted blend of
    the per-joint ``offsets`` (J,)."""
    o = torch.as_tensor(np.asarray(offsets, np.float64))
    if o.shape != (body.num_joints,):
        raise ValueError(f"girth offsets: expected ({body.num_joints},), got {tuple(o.shape)}")
    return body.weights.double() @ o


def posed_normals(body: BodyModel, poses, trans, betas=None) -> tuple[torch.Tensor, torch.Tensor]:
    """Posed vertices (T, V, 3) and posed rest normals (T, V, 3) of frames ``poses``
    (T, J, 3), ``trans`` (T, 3), shape ``betas`` (1, S) or None: the surface grown by
    offsets o poses to ``vertices + normals * vertex_offsets(body, o)[:, None]`` exactly
    (float64)."""
    pose = torch.as_tensor(np.asarray(poses)).double()
    b = None if betas is None else torch.as_tensor(betas).expand(len(pose), -1)
    v, joints = body.shaped(b, len(pose))
    v, joints = v.double(), joints.double()
    posedirs = None if body.posedirs is None else body.posedirs.double()
    verts, _, transforms = lbs(pose, v, joints, body.parents, body.weights.double(), posedirs)
    verts = verts + torch.as_tensor(np.asarray(trans)).double()[:, None]
    rot = torch.einsum("vj,tjab->tvab", body.weights.double(), transforms[..., :3, :3])
    normals = torch.einsum("tvab,vb->tva", rot, vertex_normals(v[0], body.faces))
    return verts, normals


def symmetric_groups(names) -> list[list[int]]:
    """Joint indices grouped so that each ``left_X`` goes with its ``right_X`` (one offset
    for both sides), every other joint alone; in the order of their first joint."""
    index = {n: i for i, n in enumerate(names)}
    groups, seen = [], set()
    for i, n in enumerate(names):
        if i in seen:
            continue
        twin = index.get("right_" + n[5:]) if n.startswith("left_") else None
        group = [i] if twin is None else [i, twin]
        seen.update(group)
        groups.append(group)
    return groups
