"""The 3D view: the posed body drawn with the GLSL programs in ``shaders/`` into an
offscreen framebuffer of any moderngl context (the window's, EGL or OSMesa); this module
never creates a context.

Colour modes (first that applies): ``novelty`` (each vertex coloured by the distance of
its vocabulary part(s) to the nearest key, Eq. 4, blended by skinning attention; heat
scale :func:`texvocab_viewer.gl.colors.heat_color` over [0, ``novelty_scale``]), ``part_colors`` (the
five body parts of Table 1), ``textured`` (the blended vocabulary texture of the pose;
a neutral grey checker without a vocabulary). ``wireframe`` draws triangle edges over
it and ``skeleton`` the joints and bones on top of everything.
"""

from __future__ import annotations

from dataclasses import dataclass

import moderngl
import numpy as np
from scipy import sparse

from texvocab.pipeline import BODY_PARTS, Camera, outward_orientation, part_attention
from texvocab_viewer.gl.camera import gl_mvp
from texvocab_viewer.gl.colors import PART_COLORS, heat_color
from texvocab_viewer.gl.glsl import build_program, set_uniform


@dataclass
class SceneOptions:
    """What the 3D view shows (see the module docstring for the colour modes)."""

    textured: bool = True
    part_colors: bool = False
    novelty: bool = False
    wireframe: bool = False
    skeleton: bool = False
    lighting: bool = True
    novelty_scale: float = 0.1  # part distance (Eq. 4) drawn fully red
    background: tuple[float, float, float] = (0.13, 0.14, 0.16)
    wire_color: tuple[float, float, float] = (0.05, 0.05, 0.05)
    bone_color: tuple[float, float, float] = (1.0, 0.85, 0.1)
    joint_color: tuple[float, float, float] = (0.95, 0.15, 0.15)


def as_camera(camera, width: int, height: int) -> Camera:
    """An OpenCV :class:`Camera` of exactly ``width`` × ``height`` for an orbit camera or a
    capture camera (scaled when its size differs; the aspect ratio must match)."""
    if hasattr(camera, "to_texvocab_camera"):
        return camera.to_texvocab_camera(width, height)
    if (camera.width, camera.height) == (width, height):
        return camera
    factor = width / camera.width
    if round(camera.height * factor) != height:
        raise ValueError(
            f"camera {camera.name!r} is {camera.width}x{camera.height}; cannot draw "
            f"it at {width}x{height} (different aspect ratio)"
        )
    return camera.scaled(factor)


def face_normals(verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F, 3) area-weighted face normals (b - a) x (c - a) of verts (V, 3), faces (F, 3),
    in verts' dtype: the cross product written out (np.cross on float64, with its axis
    handling, made the per-pose normals 2.4 ms instead of 0.75 with this in float32)."""
    a = verts[faces[:, 0]]
    e1, e2 = verts[faces[:, 1]] - a, verts[faces[:, 2]] - a
    out = np.empty_like(e1)
    out[:, 0] = e1[:, 1] * e2[:, 2] - e1[:, 2] * e2[:, 1]
    out[:, 1] = e1[:, 2] * e2[:, 0] - e1[:, 0] * e2[:, 2]
    out[:, 2] = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    return out


class SceneRenderer:
    """Draws a :class:`~texvocab_viewer.state.ViewerState` of ``data`` into its own framebuffer.

    Args:
        ctx: a current moderngl context (3.3 core).
        data: :class:`~texvocab_viewer.state.ViewerData` (body, vocabulary, textures).
        samples: MSAA samples (0: none); resolved into the returned texture.
    """

    def __init__(self, ctx: moderngl.Context, data, samples: int = 0):
        self.ctx, self.data = ctx, data
        self.samples = min(int(samples), ctx.max_samples) if samples else 0
        body = data.body
        faces = body.faces.numpy()
        self.faces = faces
        self.num_corners = faces.size
        self.mesh_prog = build_program(ctx, "mesh.vert", "mesh.frag")
        self.bone_prog = build_program(ctx, "bone.vert", "flat.frag")
        self.joint_prog = build_program(ctx, "joint.vert", "flat.frag")
        n = self.num_corners
        ft = body.ft.numpy() if body.vt is not None and body.ft is not None else None
        vt = body.vt.numpy() if ft is not None else None
        uv = vt[ft].reshape(-1, 2) if ft is not None else np.zeros((n, 2))
        # Unrolled: one GL vertex per triangle corner, with barycentrics for the wireframe.
        bary = np.tile(np.eye(3), (len(faces), 1))
        self.vbo_pos = ctx.buffer(reserve=n * 12, dynamic=True)
        self.vbo_nrm = ctx.buffer(reserve=n * 12, dynamic=True)
        self.vbo_col = ctx.buffer(reserve=n * 12, dynamic=True)
        self.vbo_uv = ctx.buffer(uv.astype("f4").tobytes())
        self.vbo_bary = ctx.buffer(bary.astype("f4").tobytes())
        self.mesh_vao = ctx.vertex_array(
            self.mesh_prog,
            self._bindings(
                self.mesh_prog,
                [
                    (self.vbo_pos, "3f", "in_position"),
                    (self.vbo_nrm, "3f", "in_normal"),
                    (self.vbo_uv, "2f", "in_uv"),
                    (self.vbo_col, "3f", "in_color"),
                    (self.vbo_bary, "3f", "in_bary"),
                ],
            ),
        )
        # Indexed (without the wireframe): one GL vertex per distinct (vertex, uv) pair, so
        # the per-pose upload and the vertex stage handle ~V vertices instead of 3F corners
        # (the default body: 7.8k against 41k; llvmpipe runs the vertex stage on the UI thread).
        pairs = np.stack([faces.reshape(-1), (ft if ft is not None else faces).reshape(-1)], 1)
        unique, inverse = np.unique(pairs, axis=0, return_inverse=True)
        self.corner_vertex = unique[:, 0]
        self.num_indexed = len(unique)
        m = self.num_indexed
        uv_indexed = vt[unique[:, 1]] if vt is not None else np.zeros((m, 2))
        self.ivbo_pos = ctx.buffer(reserve=m * 12, dynamic=True)
        self.ivbo_nrm = ctx.buffer(reserve=m * 12, dynamic=True)
        self.ivbo_col = ctx.buffer(reserve=m * 12, dynamic=True)
        self.ivbo_uv = ctx.buffer(uv_indexed.astype("f4").tobytes())
        self.ibo = ctx.buffer(inverse.reshape(-1).astype("i4").tobytes())
        self.indexed_vao = ctx.vertex_array(
            self.mesh_prog,
            self._bindings(
                self.mesh_prog,
                [
                    (self.ivbo_pos, "3f", "in_position"),
                    (self.ivbo_nrm, "3f", "in_normal"),
                    (self.ivbo_uv, "2f", "in_uv"),
                    (self.ivbo_col, "3f", "in_color"),
                ],
            ),
            index_buffer=self.ibo,
            index_element_size=4,
        )
        parents = body.parents.numpy()
        self.bones = np.stack([parents[1:], np.arange(1, len(parents))], 1)
        self.vbo_bones = ctx.buffer(reserve=len(self.bones) * 24, dynamic=True)
        self.vbo_joints = ctx.buffer(reserve=len(parents) * 12, dynamic=True)
        self.bone_vao = ctx.vertex_array(self.bone_prog, [(self.vbo_bones, "3f 3f/i", "in_a", "in_b")])
        self.joint_vao = ctx.vertex_array(self.joint_prog, [(self.vbo_joints, "3f", "in_position")])
        # vertex -> incident faces, for smooth normals: (V, F) sparse incidence
        rows = faces.reshape(-1)
        cols = np.repeat(np.arange(len(faces)), 3)
        self._incidence = sparse.csr_matrix(
            (np.ones(len(rows), np.float32), (rows, cols)), shape=(body.num_vertices, len(faces))
        )
        #: the winding GL culls against ("ccw"/"cw"), None to draw both sides: a closed,
        #: consistently wound body seen from outside never shows a back face (each lies
        #: behind a front face), so llvmpipe need not set up or shade them (measured at
        #: 520x700: 3.3 -> 2.7 ms of vertex stage on the UI thread, 5.1 -> 3.0 ms of
        #: rasterisation, the same image). A camera inside the body then sees out.
        orientation = outward_orientation(body.v_template, faces)
        self.front_face = {1: "ccw", -1: "cw"}.get(orientation)
        weights = body.weights.double()
        attn5 = part_attention(weights, list(BODY_PARTS.values())).numpy()
        palette = np.array([PART_COLORS[p] for p in BODY_PARTS])
        self._part_rgb = palette[attn5.argmax(1)].astype("f4")  # (V, 3)
        self._vocab_attention = None
        if data.vocab is not None:
            self._vocab_attention = part_attention(weights, data.vocab.part_joints).numpy()
        self.force_unrolled = False  # tests: the unrolled layout without the wireframe
        self.texture = None
        self.grey = ctx.texture((1, 1), 3, bytes([158, 158, 158]))
        self.size = None
        self._geometry_key = None
        self._texture_key = None
        self._color_key = None

    @staticmethod
    def _bindings(prog, items):
        """VAO content without attributes the compiler dropped (one buffer each)."""
        return [item for item in items if item[2] in prog]

    # -- resources --------------------------------------------------------------------
    def _ensure_target(self, size: tuple[int, int]) -> None:
        if self.size == size:
            return
        for name in ("fbo", "color", "depth", "msaa_fbo", "msaa_color", "msaa_depth"):
            obj = getattr(self, name, None)
            if obj is not None:
                obj.release()
        ctx = self.ctx
        self.color = ctx.texture(size, 4)
        self.color.filter = (moderngl.LINEAR, moderngl.LINEAR)
        self.depth = ctx.depth_texture(size)
        self.fbo = ctx.framebuffer([self.color], self.depth)
        self.msaa_fbo = self.msaa_color = self.msaa_depth = None
        if self.samples:
            self.msaa_color = ctx.renderbuffer(size, 4, samples=self.samples)
            self.msaa_depth = ctx.depth_renderbuffer(size, samples=self.samples)
            self.msaa_fbo = ctx.framebuffer([self.msaa_color], self.msaa_depth)
        self.size = size

    def _layout(self, options: SceneOptions) -> str:
        """ "unrolled" with the wireframe (it needs barycentrics), else "indexed"."""
        return "unrolled" if options.wireframe or self.force_unrolled else "indexed"

    def _per_vertex(self, values: np.ndarray, layout: str) -> bytes:
        """(V, 3) per-vertex values as the chosen layout's vertex buffer contents."""
        rows = self.faces.reshape(-1) if layout == "unrolled" else self.corner_vertex
        return np.ascontiguousarray(values[rows], dtype="f4").tobytes()

    def _update_geometry(self, state, layout: str) -> None:
        key = (id(state), state.version, layout)
        if key == self._geometry_key:
            return
        verts, joints = state.posed()
        vn = self._incidence @ face_normals(verts.astype(np.float32, copy=False), self.faces)
        vn /= np.maximum(np.sqrt((vn * vn).sum(1, keepdims=True)), 1e-12)
        pos, nrm = (self.vbo_pos, self.vbo_nrm) if layout == "unrolled" else (self.ivbo_pos, self.ivbo_nrm)
        pos.write(self._per_vertex(verts, layout))
        nrm.write(self._per_vertex(vn, layout))
        j = joints.astype("f4")
        self.vbo_bones.write(np.concatenate([j[self.bones[:, 0]], j[self.bones[:, 1]]], 1).tobytes())
        self.vbo_joints.write(j.tobytes())
        self._geometry_key = key

    def _update_texture(self, state) -> bool:
        """Upload the blended texture of the pose; False when there is none."""
        key = (id(state), state.version)
        if key == self._texture_key:
            return self.texture is not None
        tex = state.blended_texture()
        self._texture_key = key
        if tex is None:
            return False
        # row 0 of a texture image is v = 1 (texvocab.geometry.uv); GL's first row is t = 0, so the
        # image goes up flipped and the shader samples at the OBJ uv unchanged
        data = (np.clip(np.flipud(tex), 0, 1) * 255 + 0.5).astype(np.uint8)
        h, w = data.shape[:2]
        if self.texture is None or self.texture.size != (w, h):
            if self.texture is not None:
                self.texture.release()
            self.texture = self.ctx.texture((w, h), 3, alignment=1)
            self.texture.filter = (moderngl.LINEAR, moderngl.LINEAR)  # no mipmaps: 10 ms a pose
        self.texture.write(np.ascontiguousarray(data).tobytes())
        return True

    def novelty_colors(self, state, scale: float) -> np.ndarray:
        """(V, 3) per-vertex heat colours: Σ_p Ω(v, p) d_p / scale (grey without vocabulary)."""
        if self._vocab_attention is None:
            return np.full((self.data.body.num_vertices, 3), 0.6)
        per_vertex = self._vocab_attention @ state.novelty()
        return heat_color(per_vertex / max(scale, 1e-9))

    def _update_colors(self, state, options: SceneOptions, layout: str) -> None:
        key = (id(state), state.version, options.novelty, options.part_colors, options.novelty_scale, layout)
        if key == self._color_key:
            return
        if options.novelty:
            rgb = self.novelty_colors(state, options.novelty_scale)
        else:
            rgb = self._part_rgb
        (self.vbo_col if layout == "unrolled" else self.ivbo_col).write(self._per_vertex(rgb, layout))
        self._color_key = key

    # -- drawing ----------------------------------------------------------------------
    def render(
        self, state, camera, size: tuple[int, int] = (1280, 800), options: SceneOptions | None = None
    ) -> moderngl.Texture:
        """Draw ``state`` seen by ``camera`` (an :class:`~texvocab_viewer.gl.camera.OrbitCamera` or a
        capture :class:`Camera`) at ``size`` = (width, height); returns the RGBA colour
        texture (rows bottom-up, as GL stores them)."""
        o = options or SceneOptions()
        w, h = int(size[0]), int(size[1])
        cam = as_camera(camera, w, h)
        ctx = self.ctx
        self._ensure_target((w, h))
        layout = self._layout(o)
        self._update_geometry(state, layout)
        mode = 0
        if o.novelty or o.part_colors:
            self._update_colors(state, o, layout)
            mode = 2
        elif o.textured and self._update_texture(state):
            mode = 1
        previous = ctx.fbo  # given back at the end (the window draws its GUI there)
        target = self.msaa_fbo or self.fbo
        target.use()
        ctx.viewport = (0, 0, w, h)
        ctx.clear(*o.background, 1.0, depth=1.0)
        cull = moderngl.CULL_FACE if self.front_face else 0
        ctx.enable_only(moderngl.DEPTH_TEST | moderngl.PROGRAM_POINT_SIZE | cull)
        if self.front_face:
            ctx.front_face = self.front_face
        mvp = gl_mvp(cam)
        prog = self.mesh_prog
        set_uniform(prog, "mvp", mvp)
        set_uniform(prog, "mode", mode)
        set_uniform(prog, "lighting", bool(o.lighting))
        set_uniform(prog, "eye", tuple(float(x) for x in cam.center))
        set_uniform(prog, "wireframe", bool(o.wireframe))
        set_uniform(prog, "wire_color", tuple(o.wire_color))
        set_uniform(prog, "wire_width", 0.75)
        set_uniform(prog, "tex", 0)
        (self.texture if mode == 1 else self.grey).use(0)
        if layout == "unrolled":
            self.mesh_vao.render(moderngl.TRIANGLES, vertices=self.num_corners)
        else:
            self.indexed_vao.render(moderngl.TRIANGLES)
        ctx.disable(moderngl.CULL_FACE)  # bones face either way; the GUI draws after
        if o.skeleton:
            ctx.disable(moderngl.DEPTH_TEST)
            scale = max(h / 800.0, 0.45)  # sizes in pixels for an 800-pixel-high view
            for p, color, extra in (
                (self.bone_prog, o.bone_color, {"width": 3.0 * scale}),
                (self.joint_prog, o.joint_color, {"size": 9.0 * scale}),
            ):
                set_uniform(p, "mvp", mvp)
                set_uniform(p, "color", tuple(color))
                set_uniform(p, "viewport", (float(w), float(h)))
                set_uniform(p, "round_points", p is self.joint_prog)
                for name, value in extra.items():
                    set_uniform(p, name, value)
            self.bone_vao.render(moderngl.TRIANGLE_STRIP, vertices=4, instances=len(self.bones))
            self.joint_vao.render(moderngl.POINTS, vertices=len(self.bones) + 1)
        if self.msaa_fbo is not None:
            ctx.copy_framebuffer(self.fbo, self.msaa_fbo)
        if previous is not None:
            previous.use()
        return self.color

    def read(self, size: tuple[int, int] | None = None) -> np.ndarray:
        """(H, W, 3) uint8 of the last render, top row first."""
        if self.size is None or (size is not None and tuple(size) != self.size):
            raise ValueError(f"nothing rendered at size {size}; last render: {self.size}")
        w, h = self.size
        data = np.frombuffer(self.fbo.read(components=3, alignment=1), np.uint8)
        return np.flipud(data.reshape(h, w, 3)).copy()

    def read_depth(self) -> np.ndarray:
        """(H, W) float32 window depth of the last render in [0, 1] (1: background),
        top row first."""
        w, h = self.size
        data = np.frombuffer(self.depth.read(alignment=1), np.float32)
        return np.flipud(data.reshape(h, w)).copy()

    def release(self) -> None:
        for obj in list(vars(self).values()):
            if hasattr(obj, "release") and obj is not self.ctx and hasattr(obj, "glo"):
                obj.release()
