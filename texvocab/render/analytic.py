"""Analytic fields with the marcher's interface, for tests and benchmarks (no network).

Both turn a signed distance into a VolSDF density (Yariv et al. 2021's Laplace CDF, as the
avatar field does) and colour points by a smooth function of position.
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F
from scipy import ndimage

from texvocab.geometry.surface import SurfaceIndex

_FAR = 1.0  # |sdf| given to grid points beyond the exact band (metres; density ~ 0 there)


def volsdf_density(sdf: torch.Tensor, beta: torch.Tensor) -> torch.Tensor:
    """σ = (1/β) Ψ_β(-sdf), Ψ_β the Laplace CDF with scale β; sdf (N,) negative inside.
    Only exp of non-positive numbers is taken: finite values and gradients for any β > 0."""
    e = torch.exp(-sdf.abs() / beta)
    return torch.where(sdf >= 0, 0.5 * e, 1.0 - 0.5 * e) / beta


def smooth_colour(points: torch.Tensor, albedo: torch.Tensor, freq: float) -> torch.Tensor:
    """(N, 3) in [0, 1]: albedo (3,) modulated by sinusoids of position (N, 3)."""
    phase = torch.tensor([0.0, 2.1, 4.2], dtype=points.dtype)
    wave = torch.sin(
        freq
        * points
        @ torch.tensor([[1.0, 0.3, -0.5], [0.4, 1.0, 0.2], [-0.3, 0.5, 1.0]], dtype=points.dtype)
        + phase
    )
    return (albedo * (0.6 + 0.4 * wave)).clamp(0, 1)


class _AnalyticField:
    """The marchers' interface of an analytic field from its ``sdf(points)``, ``beta``,
    ``albedo`` and ``freq``: ``field(points, dirs) -> (density, rgb)`` and
    ``field.sdf_rgb(points, dirs) -> (sdf, rgb)``."""

    def __call__(self, points: torch.Tensor, dirs: torch.Tensor):
        return volsdf_density(self.sdf(points), self.beta), smooth_colour(points, self.albedo, self.freq)

    def sdf_rgb(self, points: torch.Tensor, dirs: torch.Tensor):
        """(sdf (N,), rgb (N, 3)): what the surface-guided marcher reads."""
        return self.sdf(points), smooth_colour(points, self.albedo, self.freq)


class SphereField(_AnalyticField):
    """Sphere of ``radius`` at ``center``; ``beta`` and ``albedo`` are tensors that may
    require grad. Call: (points (N, 3), dirs (N, 3)) -> (density (N,), rgb (N, 3))."""

    def __init__(
        self,
        center=(0.0, 0.0, 0.0),
        radius: float = 0.3,
        beta: float = 0.005,
        albedo=(0.8, 0.5, 0.3),
        freq: float = 0.0,
    ):
        self.center = torch.tensor(center, dtype=torch.float32)
        self.radius = float(radius)
        self.beta = torch.tensor(float(beta))
        self.albedo = torch.tensor(albedo, dtype=torch.float32)
        self.freq = freq

    def sdf(self, points: torch.Tensor) -> torch.Tensor:
        """(N,) signed distance of points (N, 3)."""
        return (points - self.center).norm(dim=1) - self.radius


class MeshSDFField(_AnalyticField):
    """VolSDF density of a closed posed mesh, the body's own shape.

    The exact signed distance (:class:`~texvocab.geometry.surface.SurfaceIndex`) is sampled once
    on a grid of side ``voxel`` and interpolated trilinearly (so a call is cheap, like a
    field lookup). Grid points beyond ``band`` from the surface get ±1 m: they form
    connected regions walled off by the band (wider than half a voxel), and one exact
    signed query per region gives its sign; a band of 12β plus a voxel keeps the density
    there below e^-12 / (2β), so no haze fills the empty space. The zero level set lies
    within about a voxel of the mesh.

    Args:
        vertices: (V, 3), faces: (F, 3) closed, consistently oriented mesh.
        beta: VolSDF scale (metres); a tensor attribute that may require grad.
        band: exact-distance band (default max(3 voxel, 12 beta) + voxel).
    """

    def __init__(
        self,
        vertices,
        faces,
        beta: float = 0.004,
        voxel: float = 0.01,
        band: float | None = None,
        albedo=(0.9, 0.7, 0.5),
        freq: float = 12.0,
    ):
        v = np.asarray(torch.as_tensor(vertices).detach().cpu(), dtype=np.float64)
        index = SurfaceIndex(v, faces)
        if not index.closed:
            raise ValueError("MeshSDFField needs a closed, consistently oriented mesh")
        band = float(band or max(3 * voxel, 12 * beta) + voxel)
        lo, hi = v.min(0) - band - 2 * voxel, v.max(0) + band + 2 * voxel
        shape = np.ceil((hi - lo) / voxel).astype(int) + 1
        axes = [lo[k] + voxel * np.arange(shape[k]) for k in range(3)]
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
        dist = np.asarray(index.project(grid, max_distance=band).distance).reshape(shape)
        far = ~np.isfinite(dist)
        labels, _ = ndimage.label(far)  # regions walled off by the band share one sign
        ids, first = np.unique(labels.reshape(-1), return_index=True)
        keep = ids > 0
        sign = np.sign(np.asarray(index.project(grid[first[keep]]).distance))
        lookup = np.zeros(labels.max() + 1)
        lookup[ids[keep]] = sign
        dist[far] = lookup[labels[far]] * _FAR
        self.lo, self.hi = torch.tensor(lo), torch.tensor(lo + voxel * (shape - 1))
        self.grid = torch.from_numpy(dist.transpose(2, 1, 0).copy()).float()[None, None]
        self.beta = torch.tensor(float(beta))
        self.albedo = torch.tensor(albedo, dtype=torch.float32)
        self.freq = freq

    def sdf(self, points: torch.Tensor) -> torch.Tensor:
        """(N,) interpolated signed distance of points (N, 3); +1 m outside the grid."""
        x = (2 * (points.double() - self.lo) / (self.hi - self.lo) - 1).float()
        out = F.grid_sample(
            self.grid, x.view(1, -1, 1, 1, 3), mode="bilinear", padding_mode="border", align_corners=True
        )
        return out.view(-1).to(points.dtype)


class MeshResidualField(_AnalyticField):
    """The avatar field's structure without a network: the posed mesh's exact signed
    distance (``band`` beyond ``band``, where the density is nil) plus a residual
    ``amplitude`` sin(``wavenumber`` x·(1, 0.7, 0.4) + 1) that moves the surface by up
    to ``amplitude`` and varies over 2π / ``wavenumber`` metres, as the avatar's SDF
    network does on top of the body; VolSDF density and a smooth colour.

    Args:
        vertices: (V, 3), faces: (F, 3) closed, consistently oriented mesh.
        beta: VolSDF scale (metres). amplitude, wavenumber: the residual.
    """

    def __init__(
        self,
        vertices,
        faces,
        beta: float = 0.003,
        amplitude: float = 0.002,
        wavenumber: float = 20.0,
        band: float = 0.06,
        albedo=(0.9, 0.7, 0.5),
        freq: float = 12.0,
    ):
        v = np.asarray(torch.as_tensor(vertices).detach().cpu(), dtype=np.float64)
        self.index = SurfaceIndex(v, faces)
        if not self.index.closed:
            raise ValueError("MeshResidualField needs a closed, consistently oriented mesh")
        self.beta = torch.tensor(float(beta))
        self.amplitude, self.wavenumber, self.band = float(amplitude), float(wavenumber), band
        self.albedo = torch.tensor(albedo, dtype=torch.float32)
        self.freq = freq

    def residual(self, points: torch.Tensor) -> torch.Tensor:
        """(N,) the residual at points (N, 3)."""
        axis = torch.tensor([1.0, 0.7, 0.4], dtype=points.dtype)
        return self.amplitude * torch.sin(self.wavenumber * points @ axis + 1.0)

    def sdf(self, points: torch.Tensor) -> torch.Tensor:
        """(N,) the mesh's signed distance plus the residual; ``band`` beyond band."""
        proj = self.index.project(points.detach().double().numpy(), max_distance=self.band)
        d = torch.from_numpy(np.where(proj.face >= 0, proj.distance, self.band))
        return torch.where(
            d < self.band,
            d.to(points.dtype) + self.residual(points),
            torch.full_like(points[:, 0], self.band),
        )
