"""Exact closest point on a posed triangle mesh: face, barycentrics, UV, skinning weights.

Implements the projection of TexVocab Sec. 3.4, "Texture Map Sampling" (Eq. 5 of
shared/paper/texvocab.tex):

    (u*, v*, f*) = argmin_{u, v, f} || x - B_{u,v}(V_t[F(f)]) ||²

i.e. the closest point of the whole surface (not the nearest vertex), found exactly.

Acceleration (:class:`SurfaceIndex`, built once per posed mesh): every face is cut into
n² congruent sub-triangles (n = ceil(face radius / ``sample_radius``)); their centroids
("samples") go into a k-d tree. Every surface point lies within r_s (its sub-triangle's
radius) of a sample of its own face, so for a query x with a known upper bound d_up on
the distance (here: distance to the face of the nearest sample) the closest face is the
face of some sample s with |x - s| - r_s <= d_up. The k nearest samples are fetched,
candidates are pruned with that bound, and rows whose k-th sample is still inside the
bound are re-queried with a larger k, so the pruning is provably exact. Point-triangle
tests are Ericson's region tests (Real-Time Collision Detection, 5.1.5), batched in
float64 numpy; chunks run on a thread pool (numpy releases the GIL).

Sign: the angle-weighted pseudo-normal of the closest feature (face, edge or vertex;
Baerentzen & Aanaes 2005), used only when the mesh is closed and consistently oriented;
negative inside.
"""
from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, fields

import numpy as np
import torch
from scipy.spatial import cKDTree

_CHUNK = 8192  # points per work item
_K0 = 16  # samples fetched first per point
_FEATURE_EPS = 1e-12  # barycentric below this counts as zero when choosing the feature


@dataclass
class SurfaceProjection:
    """Closest surface points of N queries. Invalid rows (farther than ``max_distance``)
    have ``face == -1``, ``distance == inf`` and NaN elsewhere.

    face: (N,) int64 · bary: (N, 3) · closest: (N, 3) · distance: (N,), signed (negative
    inside) when ``signed`` · uv: (N, 2) or None · weights: (N, J) or None.
    Arrays are numpy, or torch tensors when the query points were a tensor.
    """

    face: np.ndarray | torch.Tensor
    bary: np.ndarray | torch.Tensor
    closest: np.ndarray | torch.Tensor
    distance: np.ndarray | torch.Tensor
    uv: np.ndarray | torch.Tensor | None = None
    weights: np.ndarray | torch.Tensor | None = None
    signed: bool = False

    @property
    def valid(self) -> np.ndarray | torch.Tensor:
        """(N,) bool: rows that have a closest point."""
        return self.face >= 0


def _numpy(x, dtype) -> np.ndarray:
    if isinstance(x, torch.Tensor):
        x = x.detach().cpu().numpy()
    return np.ascontiguousarray(np.asarray(x), dtype=dtype)


def closest_on_triangles(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray
                         ) -> np.ndarray:
    """Barycentrics (P, 3) of the closest point to p (P, 3) on triangles (a, b, c) (P, 3).

    Ericson's Voronoi-region tests; zero-area triangles fall back to their three edges.
    """
    ab, ac = b - a, c - a
    e00, e01, e11 = (ab * ab).sum(1), (ab * ac).sum(1), (ac * ac).sum(1)
    vw = _ericson(p - a, ab, ac, e00, e01, e11)
    bad = np.cross(ab, ac).__pow__(2).sum(1) <= 1e-24 * np.maximum(e00, e11) ** 2
    if bad.any():
        vw[bad] = _closest_on_edges(p[bad] - a[bad], ab[bad], ac[bad], e00[bad], e01[bad],
                                    e11[bad])
    return np.column_stack([1.0 - vw[:, 0] - vw[:, 1], vw[:, 0], vw[:, 1]])


def _ericson(ap, ab, ac, e00, e01, e11) -> np.ndarray:
    """(v, w) (P, 2) with closest = a + v ab + w ac; inputs (P, 3) and per-pair dots (P,)."""
    d1, d2 = (ab * ap).sum(1), (ac * ap).sum(1)
    d3, d4, d5, d6 = d1 - e00, d2 - e01, d1 - e01, d2 - e11
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        den = va + vb + vc
        v, w = vb / den, vc / den  # face interior; regions below override it
        t = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        m = (va <= 0) & (d4 >= d3) & (d5 >= d6)  # edge BC
        v, w = np.where(m, 1.0 - t, v), np.where(m, t, w)
        m = (vb <= 0) & (d2 >= 0) & (d6 <= 0)  # edge AC
        v, w = np.where(m, 0.0, v), np.where(m, d2 / (d2 - d6), w)
        m = (d6 >= 0) & (d5 <= d6)  # vertex C
        v, w = np.where(m, 0.0, v), np.where(m, 1.0, w)
        m = (vc <= 0) & (d1 >= 0) & (d3 <= 0)  # edge AB
        v, w = np.where(m, d1 / (d1 - d3), v), np.where(m, 0.0, w)
        m = (d3 >= 0) & (d4 <= d3)  # vertex B
        v, w = np.where(m, 1.0, v), np.where(m, 0.0, w)
        m = (d1 <= 0) & (d2 <= 0)  # vertex A
        v, w = np.where(m, 0.0, v), np.where(m, 0.0, w)
    return np.column_stack([v, w])


def _closest_on_edges(ap, ab, ac, e00, e01, e11) -> np.ndarray:
    """(v, w) (P, 2) of the closest point on the three edges (for zero-area triangles)."""
    bc, bp = ac - ab, ap - ab
    ebc = e11 - 2 * e01 + e00

    def param(num, den):
        return np.clip(np.divide(num, den, out=np.zeros_like(num), where=den > 0), 0.0, 1.0)

    t_ab, t_ac, t_bc = param((ap * ab).sum(1), e00), param((ap * ac).sum(1), e11), \
        param((bp * bc).sum(1), ebc)
    cand = np.stack([np.column_stack([t_ab, 0 * t_ab]), np.column_stack([0 * t_ac, t_ac]),
                     np.column_stack([1 - t_bc, t_bc])])  # (3, P, 2)
    res = ap[None] - cand[..., :1] * ab[None] - cand[..., 1:] * ac[None]
    best = (res ** 2).sum(-1).argmin(0)
    return cand[best, np.arange(len(ap))]


class SurfaceIndex:
    """Acceleration structure of one posed mesh, reusable across queries of that frame.

    Args:
        vertices: (V, 3) posed vertices (metres). faces: (F, 3) vertex indices.
        sample_radius: target sub-triangle radius (metres); default half the median
            face radius. Smaller means more samples and fewer candidate faces per point.
        workers: threads for queries (default: the CPUs this process may use).
    """

    def __init__(self, vertices, faces, sample_radius: float | None = None,
                 workers: int | None = None):
        self.vertices = _numpy(vertices, np.float64)
        self.faces = _numpy(faces, np.int64)
        self.workers = workers or len(os.sched_getaffinity(0))
        tri = self.vertices[self.faces]  # (F, 3, 3)
        self._a, self._b, self._c = (np.ascontiguousarray(tri[:, i]) for i in range(3))
        centroid = tri.mean(1)
        radius = np.sqrt(((tri - centroid[:, None]) ** 2).sum(-1).max(1))  # (F,)
        target = sample_radius or max(0.5 * float(np.median(radius)), 1e-9)
        n_sub = np.clip(np.ceil(radius / target), 1, 64).astype(np.int64)
        samples, owner = [], []
        for n in np.unique(n_sub):
            fid = np.flatnonzero(n_sub == n)
            samples.append(np.einsum("sk,fkd->fsd", _sub_centroids(int(n)), tri[fid]))
            owner.append(np.repeat(fid, samples[-1].shape[1]))
        self._sample_face = np.concatenate(owner)
        self._sample_radius = (radius / n_sub)[self._sample_face]
        self._max_radius = float(self._sample_radius.max()) * (1 + 1e-9) + 1e-12
        self._tree = cKDTree(np.concatenate([s.reshape(-1, 3) for s in samples]))
        self._pseudo_normals(tri)

    def _pseudo_normals(self, tri: np.ndarray) -> None:
        """Angle-weighted pseudo-normals of faces, edges and vertices; closedness test."""
        f = self.faces
        cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        norm = np.linalg.norm(cross, axis=1, keepdims=True)
        self._face_normal = np.divide(cross, norm, out=np.zeros_like(cross), where=norm > 0)
        self._vertex_normal = np.zeros_like(self.vertices)
        for k in range(3):
            e1, e2 = tri[:, (k + 1) % 3] - tri[:, k], tri[:, (k + 2) % 3] - tri[:, k]
            angle = np.arctan2(np.linalg.norm(np.cross(e1, e2), axis=1), (e1 * e2).sum(1))
            np.add.at(self._vertex_normal, f[:, k], angle[:, None] * self._face_normal)
        # edge k of a face joins corners k and k+1; its pseudo-normal sums the faces on it
        directed = np.stack([f, np.roll(f, -1, axis=1)], -1).reshape(-1, 2)
        key = directed.min(1) * len(self.vertices) + directed.max(1)
        uniq, inverse, count = np.unique(key, return_inverse=True, return_counts=True)
        edge_sum = np.zeros((len(uniq), 3))
        np.add.at(edge_sum, inverse, np.repeat(self._face_normal, 3, axis=0))
        self._edge_normal = edge_sum[inverse].reshape(-1, 3, 3)  # (F, 3 edges, 3)
        directed_key = directed[:, 0] * len(self.vertices) + directed[:, 1]
        self.closed = bool(len(f)) and bool((count == 2).all()) and \
            len(np.unique(directed_key)) == len(directed_key)
        volume = (tri[:, 0] * np.cross(tri[:, 1], tri[:, 2])).sum() / 6.0
        self._orientation = -1.0 if volume < 0 else 1.0

    def project(self, points, vt=None, ft=None, weights=None,
                max_distance: float | None = None) -> SurfaceProjection:
        """Closest surface point of each of ``points`` (N, 3) (Eq. 5).

        vt (T, 2) with ft (F, 3) add ``uv`` (N, 2); weights (V, J) add ``weights`` (N, J).
        Points farther than ``max_distance`` are marked invalid (face -1).
        """
        x = _numpy(points, np.float64).reshape(-1, 3)
        bound = np.inf if max_distance is None else float(max_distance)
        starts = range(0, len(x), _CHUNK)
        if self.workers > 1 and len(x) > _CHUNK:
            with ThreadPoolExecutor(self.workers) as pool:
                parts = list(pool.map(lambda s: self._nearest(x[s:s + _CHUNK], bound), starts))
        else:
            parts = [self._nearest(x[s:s + _CHUNK], bound) for s in starts]
        face = np.concatenate([p[0] for p in parts]) if parts else np.zeros(0, np.int64)
        bary = np.concatenate([p[1] for p in parts]) if parts else np.zeros((0, 3))
        return self._finish(points, x, face, bary, vt, ft, weights)

    def _nearest(self, x: np.ndarray, bound: float) -> tuple[np.ndarray, np.ndarray]:
        """(face (M,), bary (M, 3)) for one chunk x (M, 3); face -1 beyond ``bound``."""
        face = np.full(len(x), -1, np.int64)
        bary = np.full((len(x), 3), np.nan)
        dist, idx = self._tree.query(x, k=1, distance_upper_bound=bound + self._max_radius)
        rows = np.flatnonzero(np.isfinite(dist))
        if not len(rows):
            return face, bary
        f0 = self._sample_face[idx[rows]]  # the nearest sample's face gives d_up
        b0 = closest_on_triangles(x[rows], self._a[f0], self._b[f0], self._c[f0])
        d_up = np.sqrt(((x[rows] - self._point(f0, b0)) ** 2).sum(1))
        k = _K0
        while len(rows):
            fk, bk, dk, done = self._refine(x[rows], d_up, k)
            better = dk < d_up
            f0[better], b0[better], d_up[better] = fk[better], bk[better], dk[better]
            ok = done & (d_up <= bound)
            face[rows[ok]], bary[rows[ok]] = f0[ok], b0[ok]
            keep = ~done
            rows, f0, b0, d_up, k = rows[keep], f0[keep], b0[keep], d_up[keep], k * 4
        return face, bary

    def _refine(self, x: np.ndarray, d_up: np.ndarray, k: int):
        """Test the faces of the k nearest samples that pass the exact bound.

        Returns best face (M,), bary (M, 3), distance (M,) (inf without candidates) and
        done (M,): True where no sample beyond the k fetched could hold a closer face.
        """
        k = min(k, self._tree.n)
        dist, idx = self._tree.query(x, k=k)
        dist, idx = dist.reshape(len(x), k), idx.reshape(len(x), k)
        slack = 1e-12 + 1e-9 * d_up[:, None]
        done = (k == self._tree.n) | (dist[:, -1] - self._max_radius > d_up + slack[:, 0])
        cand = np.where(dist - self._sample_radius[idx] <= d_up[:, None] + slack,
                        self._sample_face[idx], -1)
        cand.sort(axis=1)
        cand[:, 1:][cand[:, 1:] == cand[:, :-1]] = -1  # each face once per row
        r, c = np.nonzero(cand >= 0)
        fid = cand[r, c]
        b = closest_on_triangles(x[r], self._a[fid], self._b[fid], self._c[fid])
        d2 = np.full(cand.shape, np.inf)
        d2[r, c] = ((x[r] - self._point(fid, b)) ** 2).sum(1)
        best = d2.argmin(1)
        pair = np.full(cand.shape, -1)
        pair[r, c] = np.arange(len(r))
        pick = pair[np.arange(len(x)), best]
        has = pick >= 0
        out_b = np.zeros((len(x), 3))
        out_b[has] = b[pick[has]]
        return (np.where(has, fid[pick], -1), out_b,
                np.sqrt(d2[np.arange(len(x)), best]), done)

    def _point(self, face: np.ndarray, bary: np.ndarray) -> np.ndarray:
        """(M, 3) surface points from face (M,) and bary (M, 3)."""
        return (bary[:, :1] * self._a[face] + bary[:, 1:2] * self._b[face]
                + bary[:, 2:] * self._c[face])

    def _finish(self, points, x, face, bary, vt, ft, weights) -> SurfaceProjection:
        """Closest points, (signed) distances, UV and weights from face/bary."""
        ok = face >= 0
        f, b = face[ok], bary[ok]
        closest = np.full_like(x, np.nan)
        closest[ok] = self._point(f, b)
        distance = np.full(len(x), np.inf)
        diff = x[ok] - closest[ok]
        distance[ok] = np.sqrt((diff ** 2).sum(1))
        if self.closed:
            distance[ok] *= np.where((diff * self._feature_normal(f, b)).sum(1) < 0, -1.0, 1.0)
        uv = wts = None
        if vt is not None and ft is not None:
            uv = _interpolate(_numpy(vt, np.float64), _numpy(ft, np.int64), face, bary)
        if weights is not None:
            wts = _interpolate(_numpy(weights, np.float64), self.faces, face, bary)
        out = SurfaceProjection(face, bary, closest, distance, uv, wts, self.closed)
        return _like(points, out)

    def _feature_normal(self, face: np.ndarray, bary: np.ndarray) -> np.ndarray:
        """(M, 3) pseudo-normal of the face, edge or vertex holding each closest point."""
        zero = bary <= _FEATURE_EPS
        nz = zero.sum(1)
        normal = self._face_normal[face].copy()
        edge = nz == 1  # edge k joins corners k and k+1, i.e. lies opposite corner k+2
        k = (zero[edge].argmax(1) + 1) % 3
        normal[edge] = self._edge_normal[face[edge], k]
        vert = nz >= 2
        corner = bary[vert].argmax(1)
        normal[vert] = self._vertex_normal[self.faces[face[vert], corner]]
        return normal * self._orientation


def _sub_centroids(n: int) -> np.ndarray:
    """(n², 3) barycentrics of the centroids of the n² congruent sub-triangles."""
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    up = (i + j <= n - 1)
    down = (i + j <= n - 2)
    vw = np.concatenate([np.stack([i[up] + 1 / 3, j[up] + 1 / 3], 1),
                         np.stack([i[down] + 2 / 3, j[down] + 2 / 3], 1)]) / n
    return np.column_stack([1 - vw.sum(1), vw])


def _interpolate(values: np.ndarray, corners: np.ndarray, face: np.ndarray,
                 bary: np.ndarray) -> np.ndarray:
    """(N, C) barycentric blend of ``values`` (T, C) at corners[face] (N, 3); NaN if face<0."""
    out = np.full((len(face), values.shape[1]), np.nan)
    ok = face >= 0
    c = corners[face[ok]]
    out[ok] = np.einsum("nk,nkc->nc", bary[ok], values[c])
    return out


def _like(points, out: SurfaceProjection) -> SurfaceProjection:
    """Convert the numpy result to torch (points' float dtype and device) if needed."""
    if not isinstance(points, torch.Tensor):
        return out
    dtype = points.dtype if points.dtype.is_floating_point else torch.float64
    for fld in fields(out):
        value = getattr(out, fld.name)
        if isinstance(value, np.ndarray):
            t = torch.from_numpy(value)
            setattr(out, fld.name, t.to(points.device) if fld.name == "face"
                    else t.to(device=points.device, dtype=dtype))
    return out


def project_to_surface(points, vertices, faces, vt=None, ft=None, weights=None,
                       max_distance: float | None = None,
                       index: SurfaceIndex | None = None) -> SurfaceProjection:
    """Exact closest point of ``points`` (N, 3) on the mesh (vertices (V, 3), faces (F, 3)).

    TexVocab Eq. 5: (u*, v*, f*) = argmin ||x - B_{u,v}(V[F(f)])||. Pass ``index`` (a
    :class:`SurfaceIndex` of the same mesh) to reuse the acceleration structure.
    See :meth:`SurfaceIndex.project` for vt/ft/weights/max_distance.
    """
    if index is None:
        index = SurfaceIndex(vertices, faces)
    elif faces is not None and tuple(np.shape(faces)) != index.faces.shape:
        raise ValueError(f"index was built for faces {index.faces.shape}, "
                         f"got {tuple(np.shape(faces))}")
    return index.project(points, vt=vt, ft=ft, weights=weights, max_distance=max_distance)


def project_brute_force(points, vertices, faces, chunk: int = 128) -> SurfaceProjection:
    """Reference: tests every triangle for every point (O(N F); for tests only).

    Same outputs as :func:`project_to_surface` (signed the same way), no uv/weights.
    """
    index = SurfaceIndex.__new__(SurfaceIndex)
    index.vertices, index.faces = _numpy(vertices, np.float64), _numpy(faces, np.int64)
    tri = index.vertices[index.faces]
    index._a, index._b, index._c = tri[:, 0], tri[:, 1], tri[:, 2]
    index._pseudo_normals(tri)
    x = _numpy(points, np.float64).reshape(-1, 3)
    nf = len(index.faces)
    face = np.zeros(len(x), np.int64)
    bary = np.zeros((len(x), 3))
    for s in range(0, len(x), chunk):
        xs = np.repeat(x[s:s + chunk], nf, axis=0)
        a, b, c = (np.tile(t, (len(xs) // nf, 1)) for t in (index._a, index._b, index._c))
        bc = closest_on_triangles(xs, a, b, c)
        d2 = ((xs - (bc[:, :1] * a + bc[:, 1:2] * b + bc[:, 2:] * c)) ** 2).sum(1)
        best = d2.reshape(-1, nf).argmin(1)
        face[s:s + chunk] = best
        bary[s:s + chunk] = bc.reshape(-1, nf, 3)[np.arange(len(best)), best]
    return index._finish(points, x, face, bary, None, None, None)
