"""One image of the surface-guided marcher: the surface plan of the camera's pixels, their
rays triaged (:func:`~texvocab.render.guided.triage.triage_rays`) in any pixel subsets, and
the shell and the mesh's SurfaceIndex built only when some ray needs them."""

from __future__ import annotations

import time

import torch

from texvocab.geometry.surface import SurfaceIndex
from texvocab.render.guided.plan import plan_surface
from texvocab.render.guided.triage import GuidedRays, triage_rays
from texvocab.render.results import RayResult, RenderResult, RenderStats, count_kinds
from texvocab.render.settings import MarchSettings
from texvocab.render.shell.geometry import ShellGeometry
from texvocab.render.shell.march import march_chunks
from texvocab.torch_threads import one_torch_thread

#: an image (or pixel subset) with fewer rays to triage renders with torch on one thread:
#: at 256² (about 17,000 such rays) one thread is faster, at 320² (about 26,000) the two
#: are even, from 384² two are faster (:mod:`texvocab.torch_threads`)
ONE_THREAD_RAYS = 24_000
#: and an image of fewer pixels makes its plan (the raster) on one thread
ONE_THREAD_PIXELS = 100_000


def render_image_guided(
    field,
    camera,
    vertices,
    faces,
    settings: MarchSettings | None = None,
    background=(0.0, 0.0, 0.0),
    shell: ShellGeometry | None = None,
    generator: torch.Generator | None = None,
    cancelled=None,
    index=None,
) -> RenderResult:
    """Render one image of ``field`` around the posed mesh (vertices (V, 3), faces (F, 3)).

    ``field`` is the marcher's ``(points, dirs) -> (density, rgb)`` callable that also
    has ``sdf_rgb(points, dirs) -> (sdf (N,), rgb (N, 3))`` and ``beta`` (float), with
    density = VolSDF(sdf, beta) (:class:`texvocab.method.field.PoseField`, the analytic
    fields of texvocab.render.analytic). Not differentiable (render time only), and
    deterministic (``generator`` is not used: no sample is random). ``stats.paths`` counts
    the rays of each kind and ``stats.kind`` (H, W) marks them (:class:`RayKind`). The
    fallback rays are marched by the shell marcher; ``shell`` (the posed mesh's
    :class:`ShellGeometry`, whose bounds the residual rays use too) is built when first
    needed if not given, and ``index`` (its SurfaceIndex) likewise for the residual rays.
    """
    image = GuidedImage(field, camera, vertices, faces, settings, background, shell, index)
    image.render(None, cancelled)
    return image.result()


class GuidedImage:
    """One image of the surface-guided marcher, rendered in any pixel subsets: the plan
    (rasterisation and each ray's class) is made once for the whole image, then
    :meth:`render` triages the rays of a subset; every ray's result depends only on the
    plan and the field, so rendering the image in parts (coarse pixel grids first, as the
    viewer's progressive levels) gives the same image with no ray rendered twice.

    ``shell``: the posed mesh's :class:`ShellGeometry`, or a function that builds it
    (called the first time a ray needs it), or None (built then from the mesh).
    ``index``: the posed mesh's SurfaceIndex for the residual rays (None: built when
    first needed)."""

    def __init__(
        self,
        field,
        camera,
        vertices,
        faces,
        settings: MarchSettings | None = None,
        background=(0.0, 0.0, 0.0),
        shell=None,
        index=None,
    ):
        s = self.settings = settings or MarchSettings()
        self.start = time.perf_counter()
        self.field, self.camera, self.shell, self.index = field, camera, shell, index
        self._bounds = None
        self.beta, delta = float(field.beta), float(s.shell.width)
        H, W = self.H, self.W = camera.height, camera.width
        self.bg = torch.as_tensor(background, dtype=torch.float32)
        self.verts = torch.as_tensor(vertices).detach().float()
        self.faces = torch.as_tensor(faces).long()
        self.origins, self.dirs = camera.pixel_rays()
        # the surface lies within δ of the mesh, so a ray passing farther from it meets
        # nothing; "margin" assumes it lies on the mesh outside the silhouette, so that a
        # ray farther than miss_margin β sees < e^-miss_margin / 2β density
        reach = delta if s.band.miss_reach == "shell" else min(delta, s.band.miss_margin * self.beta)
        with one_torch_thread(H * W < ONE_THREAD_PIXELS):
            self.plan = plan_surface(self.verts, self.faces, camera, self.dirs, delta, reach, s.band.min_cos)
        self.rgb = self.bg.repeat(H * W, 1)
        self.alpha, self.depth = torch.zeros(H * W), torch.zeros(H * W)
        self.kind = torch.zeros(H * W, dtype=torch.uint8)  # RayKind per pixel
        self.evals = 0

    def render(self, subset: torch.Tensor | None = None, cancelled=None, preview: bool = False) -> None:
        """Render the rays of ``subset`` ((H·W,) bool; None: all) into the image.
        ``preview``: the rays that would be residual or marched rays are left at their
        probe's colour (hits) or the background (passing rays), kind NONE."""
        plan = self.plan
        if not plan.hit.any():
            return
        sub = torch.ones_like(plan.hit) if subset is None else subset.view(-1)
        pix = torch.nonzero((plan.hit | plan.passby) & sub).squeeze(1)
        rays = GuidedRays(
            self.origins[0],
            self.dirs[pix],
            plan.t_hit[pix],
            plan.cos[pix],
            torch.stack([plan.t_pass[pix], plan.t_behind[pix]], 1),
            plan.face[pix] if self.settings.surface_reuse else None,
        )

        def march(idx: torch.Tensor) -> RayResult:
            return self._fallback(pix[idx], cancelled)

        # a few tens of thousands of rays: their operations are too small for a second
        # torch thread (texvocab.torch_threads: 256² frames 0.112 s on one, 0.125 s on two)
        with one_torch_thread(len(pix) < ONE_THREAD_RAYS):
            out = triage_rays(
                self.field,
                self.beta,
                rays,
                self.settings,
                march=None if preview else march,
                bounds=lambda idx: self._shell_interval(pix[idx]),
                index=self._index,
                background=self.bg,
                cancelled=cancelled,
            )
        self.rgb[pix], self.alpha[pix], self.depth[pix] = out.rgb, out.opacity, out.depth
        self.kind[pix] = out.kind
        self.evals += out.field_evals

    def _shell_bounds(self, grid: bool = False):
        """The posed mesh's shell and its image bounds, built on first use: its bounding
        balls only, unless ``grid`` (the shell marcher's occupancy grid) is asked for."""
        s = self.settings
        if callable(self.shell):
            self.shell = self.shell()
        if self.shell is None or (grid and not self.shell.has_grid):
            self.shell = ShellGeometry.build(
                self.verts, self.faces, float(s.shell.width), s.shell.voxel, s.shell.exact, self.index, grid
            )
        if self._bounds is None:  # the balls, hence the bounds, do not depend on the grid
            self._bounds = self.shell.image_bounds(self.camera)
        return self.shell, self._bounds

    def _shell_interval(self, pix: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(near, far) (n,) of pixels pix (n,) in the shell's bounds."""
        _, bounds = self._shell_bounds()
        return bounds.near.view(-1)[pix], bounds.far.view(-1)[pix]

    def _index(self) -> SurfaceIndex:
        """The posed mesh's SurfaceIndex (built on first use when not given)."""
        if self.index is None:
            self.index = SurfaceIndex(self.verts.double().numpy(), self.faces.numpy())
        return self.index

    def _fallback(self, pix: torch.Tensor, cancelled) -> RayResult:
        """The shell marcher on the rays of pixels pix (n,), with the fallback group's
        segment and scout threshold; a few rays march [near, far] without the grid."""
        s = self.settings
        gridless = len(pix) <= s.fallback.grid_rays
        shell, bounds = self._shell_bounds(grid=not gridless)
        near, far = bounds.near.view(-1)[pix], bounds.far.view(-1)[pix]
        fs = s.replace(segment=s.fallback.segment, scout_threshold=s.fallback.scout_threshold)
        if gridless:
            fs = fs.replace(skip_empty=False)
        return march_chunks(
            self.field, self.origins[pix], self.dirs[pix], near, far, fs, None, shell, self.bg, cancelled
        )

    def result(self) -> RenderResult:
        H, W = self.H, self.W
        paths = count_kinds(self.kind)
        stats = RenderStats(
            self.evals,
            paths["band"] + paths["residual"] + paths["fallback"],
            H * W,
            time.perf_counter() - self.start,
            paths=paths,
            kind=self.kind.view(H, W),
        )
        return RenderResult(self.rgb.view(H, W, 3), self.alpha.view(H, W), self.depth.view(H, W), stats)
