"""Clothing as geometry: the body surface pushed out along its normals by a per-vertex
cloth thickness plus pose-dependent fold ridges, skinned with the body's weights.

The cloth is one closed surface with the body's topology, subdivided so that folds a few
centimetres apart are resolved (each subdivision splits every triangle in four). Every
render vertex is a fixed linear combination of body vertices (``combo``), so the copies
of a vertex on a UV seam get the same position and normal and the surface never cracks.
Skin (hands, head) has thickness 0 and lies on the body. A :class:`~texvocab.capture.
garment_sets.GarmentSpec` says how thick each region is and how deep the folds are.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import scipy.sparse as sp
import torch

from texvocab.body.lbs import skin_points
from texvocab.body.poses import J
from texvocab.capture.garment import FOLD_SOURCES, fold_intensity, fold_localities, regions

#: Per fold source, the joints whose skinning weights make up its part's surface: an
#: elbow fold lies on the upper arm and forearm, a knee fold on the thigh and shin, ...
FOLD_SKIN: dict[str, tuple[int, ...]] = {
    "left_elbow": (J["left_shoulder"], J["left_elbow"]),
    "right_elbow": (J["right_shoulder"], J["right_elbow"]),
    "left_knee": (J["left_hip"], J["left_knee"]),
    "right_knee": (J["right_hip"], J["right_knee"]),
    "left_hip": (J["pelvis"], J["left_hip"]),
    "right_hip": (J["pelvis"], J["right_hip"]),
    "left_shoulder": (J["spine3"], J["left_collar"], J["left_shoulder"]),
    "right_shoulder": (J["spine3"], J["right_collar"], J["right_shoulder"]),
    "torso": (J["pelvis"], J["spine1"], J["spine2"], J["spine3"]),
}


def subdivide(combo: sp.csr_matrix, uv: np.ndarray, faces: np.ndarray):
    """One midpoint subdivision of a render mesh.

    Args:
        combo: (R, V) sparse, each render vertex as a combination of body vertices.
        uv: (R, 2); faces: (F, 3) into the render vertices.

    Returns:
        (combo (R', V), uv (R', 2), faces (4F, 3)).
    """
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    edges.sort(1)
    uniq, inv = np.unique(edges, axis=0, return_inverse=True)
    n, f = combo.shape[0], len(faces)
    mid = n + inv.reshape(3, f)  # midpoint of edge (0,1), (1,2), (2,0) per face
    half = sp.csr_matrix(
        (np.full(2 * len(uniq), 0.5), (np.repeat(np.arange(len(uniq)), 2), uniq.reshape(-1))),
        shape=(len(uniq), n),
    )
    a, b, c = faces.T
    m01, m12, m20 = mid
    new_faces = np.concatenate(
        [np.stack(x, 1) for x in ((a, m01, m20), (m01, b, m12), (m20, m12, c), (m01, m12, m20))]
    )
    return sp.vstack([combo, half @ combo]).tocsr(), np.concatenate([uv, half @ uv]), new_faces


def smooth_weights(weights: np.ndarray, faces: np.ndarray, iterations: int) -> np.ndarray:
    """(V, J) skinning weights averaged ``iterations`` times over each vertex's
    neighbours (rows still sum to 1): loose cloth bends smoothly over a joint."""
    n = len(weights)
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    adj = sp.coo_matrix((np.ones(2 * len(e)), (e.reshape(-1), e[:, ::-1].reshape(-1))), shape=(n, n))
    adj = (adj > 0).astype(np.float64) + sp.eye(n)
    adj = sp.diags(1.0 / np.asarray(adj.sum(1)).ravel()) @ adj
    w = weights
    for _ in range(iterations):
        w = adj @ w
    return w


def _vertex_normals(verts: np.ndarray, faces: np.ndarray, weld: np.ndarray, n_weld: int) -> np.ndarray:
    """(R, 3) unit normals, area-weighted over the welded mesh (seam copies share one)."""
    tri = verts[faces]
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    acc = np.zeros((n_weld, 3))
    for k in range(3):
        np.add.at(acc, weld[faces[:, k]], fn)
    acc /= np.maximum(np.linalg.norm(acc, axis=1, keepdims=True), 1e-12)
    return acc[weld]


class ClothMesh:
    """The clothed surface of one body for a :class:`GarmentSpec`.

    Args:
        body: a :class:`~texvocab.body.BodyModel` with UVs.
        spec: thickness profile and fold depth (texvocab.capture.garment_sets).
    """

    def __init__(self, body, spec):
        self.body, self.spec = body, spec
        faces = body.faces.numpy()
        pairs = np.stack([faces.reshape(-1), body.ft.numpy().reshape(-1)], 1)
        uniq, inverse = np.unique(pairs, axis=0, return_inverse=True)
        r = len(uniq)
        combo = sp.csr_matrix((np.ones(r), (np.arange(r), uniq[:, 0])), shape=(r, body.num_vertices))
        uv, rfaces = body.vt.numpy()[uniq[:, 1]].astype(np.float64), inverse.reshape(-1, 3)
        for _ in range(spec.subdivisions):
            combo, uv, rfaces = subdivide(combo, uv, rfaces)
        self.uv, self.faces = uv.astype(np.float32), rfaces
        rest = body.v_template.double().numpy()
        self.rest = combo @ rest  # (R, 3)
        key = np.round(self.rest, 7)
        _, self.weld, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
        self.weld = self.weld.reshape(-1)
        self._n_weld = len(counts)
        self.normals = _vertex_normals(self.rest, self.faces, self.weld, self._n_weld)
        joints = body.rest_joints.double().numpy()
        w_body = body.weights.double().numpy()
        w_point = combo @ w_body
        self.region = regions(self.rest, w_point, joints)
        self.thickness = spec.thickness(self.rest, self.normals, self.region, joints)
        # cloth weights: the body's, blended toward neighbour-averaged ones where the cloth is
        # loose (alpha = thickness / 6 cm, at most 1), so a flared hem bends without folding over
        smooth = combo @ smooth_weights(w_body, faces, spec.weight_smoothing)
        alpha = np.clip(self.thickness / 0.06, 0, 1)[:, None]
        self.weights = (1 - alpha) * w_point + alpha * smooth
        sources = [
            replace(s, reach=s.reach * spec.fold_reach, spacing=s.spacing * spec.fold_spacing)
            for s in FOLD_SOURCES
        ]
        self._local = fold_localities(self.rest, joints, sources)
        self.amplitude = spec.fold_depth * np.clip(self.thickness / 0.03, 0.5, 2.0)
        clothed = self.region >= 2  # shirt, pants: fabric folds; skin, hair, shoes do not
        self._skin = {
            s.name: clothed * np.clip((w_point[:, list(FOLD_SKIN[s.name])].sum(1) - 0.3) / 0.4, 0, 1)
            for s in FOLD_SOURCES
        }

    def fold_depth(self, pose) -> np.ndarray:
        """(R,) outward fold displacement in metres for a pose (24, 3) axis-angle: ridges
        ``spec.fold_depth`` high on cloth 3 cm off the body, scaled with the cloth's slack
        (thickness / 3 cm, between 0.5 and 2)."""
        return self.amplitude * np.clip(
            fold_intensity(self._local, pose, self._skin, sharpness=1, buckling=True), 0, 1
        )

    def posed(self, pose, trans, fold_pose=None) -> tuple[np.ndarray, np.ndarray]:
        """(vertices (R, 3), normals (R, 3)) of the cloth at a pose (24, 3) and root
        translation (3,), world space; ``fold_pose``: take the folds from another pose."""
        out = self.body.forward(torch.as_tensor(pose)[None], torch.as_tensor(trans)[None])
        offset = self.thickness + self.fold_depth(pose if fold_pose is None else fold_pose)
        rest = self.rest + self.normals * offset[:, None]
        verts = skin_points(
            torch.as_tensor(rest)[None], torch.as_tensor(self.weights), out.transforms.double()
        )[0].numpy()
        return verts, _vertex_normals(verts, self.faces, self.weld, self._n_weld)

    def offset(self) -> np.ndarray:
        """(R,) rest-pose distance of each cloth vertex from the body surface (metres)."""
        return self.thickness
