"""Offscreen OpenGL renderer (moderngl over EGL: Mesa llvmpipe on a CPU, the GPU where present).

One pinhole camera that matches sensor_msgs/CameraInfo (K, and lens distortion applied by remapping
an ideal render with a margin), colour and metric depth (z along the optical axis, 0 = nothing)
from the same pass, so they are pixel-aligned. Meshes are drawn lit (ambient + one directional
light, two-sided), coloured per vertex, flat, textured by UV, or textured triplanar in *reference*
coordinates so that a texture stays glued to a deforming material.

Projection (optical frame: x right, y down, z forward; pixel centres at integer coordinates):

    x_ndc = (2 fx / W) X/Z + (2 s / W) Y/Z + 2 (cx + 0.5) / W - 1
    y_ndc = -(2 fy / H) Y/Z + 1 - 2 (cy + 0.5) / H
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, cast

import cv2
import numpy as np

from simreal_nodes.camera import CameraModel
from simreal_nodes.errors import SimrealError
from simreal_nodes.geometry import vertex_normals

if TYPE_CHECKING:
    import moderngl

VERT = """
#version 330
uniform mat4 u_model;
uniform mat4 u_view;
uniform mat4 u_proj;
in vec3 in_pos;
in vec3 in_normal;
in vec3 in_ref;
in vec3 in_nref;
in vec3 in_color;
out vec3 v_ref;
out vec3 v_nref;
out vec3 v_normal;
out vec3 v_color;
out vec3 v_pos;
void main() {
    vec4 pc = u_view * u_model * vec4(in_pos, 1.0);
    gl_Position = u_proj * pc;
    v_pos = pc.xyz;
    v_ref = in_ref;
    v_nref = in_nref;
    v_normal = mat3(u_view * u_model) * in_normal;
    v_color = in_color;
}
"""

FRAG = """
#version 330
//DEFINES
uniform sampler2D u_tex;
uniform sampler2D u_real_depth;
uniform sampler2D u_depth_map;
uniform vec2 u_real_size;
uniform int u_mode;            // 0 vertex colour, 1 triplanar texture, 2 flat colour, 3 UV texture
uniform float u_occlusion_margin;
uniform vec3 u_tint;
uniform float u_tex_scale;
uniform vec3 u_light;          // direction the light travels, camera frame
uniform float u_ambient;
uniform float u_unlit;         // 1: no shading
in vec3 v_ref;
in vec3 v_nref;
in vec3 v_normal;
in vec3 v_color;
in vec3 v_pos;
layout(location = 0) out vec4 f_color;
layout(location = 1) out float f_depth;
void main() {
#ifdef OCCLUSION
    // a program of its own: 'discard' disables early depth testing, which the plain renders need.
    // u_depth_map: this render pixel's real-camera pixel (lens distortion, supersampling), negative outside
    vec2 m = texelFetch(u_depth_map, ivec2(gl_FragCoord.xy), 0).xy;
    float real = 0.0;
    if (m.x >= 0.0)
        real = texture(u_real_depth, vec2((m.x + 0.5) / u_real_size.x, 1.0 - (m.y + 0.5) / u_real_size.y)).r;
    if (real > 0.0 && real < v_pos.z - u_occlusion_margin) discard;
#endif
    vec3 base;
    if (u_mode == 0) {
        base = v_color;
    } else if (u_mode == 1) {
        vec3 w = abs(normalize(v_nref));
        w = pow(w, vec3(4.0));
        w /= (w.x + w.y + w.z);
        vec3 p = v_ref * u_tex_scale;
        base = texture(u_tex, p.yz).rgb * w.x + texture(u_tex, p.xz).rgb * w.y + texture(u_tex, p.xy).rgb * w.z;
        base *= u_tint;
    } else if (u_mode == 2) {
        base = u_tint;
    } else {
        base = texture(u_tex, v_ref.xy).rgb * u_tint;
    }
    vec3 n = normalize(v_normal);
    if (!gl_FrontFacing) n = -n;
    float diff = max(dot(n, -normalize(u_light)), 0.0);
    float shade = mix(u_ambient + (1.0 - u_ambient) * diff, 1.0, u_unlit);
    f_color = vec4(base * shade, 1.0);
    f_depth = v_pos.z;
}
"""


MAX_HALF_ANGLE_DEG = 75.0  # the widest ray off the optical axis a distorted (fisheye) camera's render draws
_UNDRAWN = -1e5  # a distortion map's entry for a camera pixel the render does not cover (read as outside it)
_MAP_STEP = 8  # pixel step of the coarse distortion-map search for a patch's camera pixels


class RenderError(SimrealError):
    pass


def projection_matrix(cam: CameraModel, near: float, far: float) -> np.ndarray:
    """OpenGL projection (row-major 4x4) for the optical frame and an OpenCV K (pixel centres)."""
    W, H = cam.width, cam.height
    fx, fy, s, cx, cy = cam.K[0, 0], cam.K[1, 1], cam.K[0, 1], cam.K[0, 2], cam.K[1, 2]
    P = np.zeros((4, 4))
    P[0, 0] = 2 * fx / W
    P[0, 1] = 2 * s / W
    P[0, 2] = 2 * (cx + 0.5) / W - 1
    P[1, 1] = -2 * fy / H
    P[1, 2] = 1 - 2 * (cy + 0.5) / H
    P[2, 2] = (far + near) / (far - near)
    P[2, 3] = -2 * far * near / (far - near)
    P[3, 2] = 1.0
    return P


def _gl(m: np.ndarray) -> bytes:
    return np.asarray(m, dtype="f4").T.copy().tobytes()  # column-major for GLSL


@dataclass
class Mesh:
    """A drawable triangle mesh (object frame). Update positions/normals/colours per frame for deformables."""

    name: str
    vertices: np.ndarray
    triangles: np.ndarray
    mode: str = "flat"  # vertex | texture | flat | uv
    tint: tuple = (1.0, 1.0, 1.0)
    texture: np.ndarray | None = None
    tex_scale: float = 1.0
    ref: np.ndarray | None = None  # reference coordinates (triplanar) or UVs in ref[:, :2] (uv mode)
    colors: np.ndarray | None = None
    smooth: bool = True
    unlit: bool = False
    pose: np.ndarray = field(default_factory=lambda: np.eye(4))  # T_world_object
    visible: bool = True
    cull_back: bool = False  # closed surface wound counter-clockwise seen from outside: skip back faces
    _vao: dict[bool, moderngl.VertexArray] | None = None  # per occlusion mode: the program it binds
    _bufs: dict[str, moderngl.Buffer] = field(default_factory=dict)
    _tex: moderngl.Texture | None = None


# a context made ahead of the first Renderer (prepare_context; loading the OpenGL driver is tens of milliseconds)
# or handed on by a released one (``release(keep=True)``), with its compiled programs: llvmpipe compiles a shader's
# code for a draw state at its first draw with it, and a program kept keeps what it compiled
_SPARE: list[tuple[moderngl.Context, dict[bool, moderngl.Program]]] = []


def _new_context() -> moderngl.Context:
    backend = os.environ.get("SIMREAL_GL_BACKEND", "egl")
    try:
        import moderngl

        # moderngl's stubs type each **settings value as a dict; backend is a string at run time
        return (moderngl.create_standalone_context(backend=backend)  # type: ignore[arg-type]
                if backend else moderngl.create_standalone_context())
    except Exception as e:  # noqa: BLE001
        raise RenderError(f"cannot create an OpenGL context over {backend or 'the default backend'} ({e}); "
                          "install libegl1 and libgl1-mesa-dri (./run setup does)") from None


def _programs(ctx: moderngl.Context) -> dict[bool, moderngl.Program]:
    """The renderer's shader program without (False) and with (True) per-pixel occlusion."""
    return {occ: ctx.program(vertex_shader=VERT, fragment_shader=FRAG.replace(
        "//DEFINES", "#define OCCLUSION" if occ else "")) for occ in (False, True)}


def prepare_context() -> str:
    """Create the OpenGL context (and its programs) the next :class:`Renderer` of this process takes, and return its
    GL_RENDERER: a node that renders calls it at start-up, so that the driver loads then and not while its first
    frame waits (the camera's intrinsics, which the renderer needs, come with that frame). :class:`RenderError` as
    Renderer gives it."""
    if not _SPARE:
        ctx = _new_context()
        try:
            programs = _programs(ctx)
        except Exception as e:  # noqa: BLE001 - the driver's own error type, said as a RenderError
            ctx.release()
            raise RenderError(f"cannot compile the renderer's shaders ({type(e).__name__}: {e})") from None
        _SPARE.append((ctx, programs))
    return _SPARE[0][0].info.get("GL_RENDERER", "?")


class Renderer:
    """Offscreen renderer for one camera model (resolution, K, distortion)."""

    def __init__(self, cam: CameraModel, near: float = 0.05, far: float = 20.0, ssaa: int = 1,
                 light=(0.3, 0.8, 0.5), ambient: float = 0.55, background=(0, 0, 0), map_step: int = 1):
        """``map_step``: the lens-distortion map's step (``CameraModel.ideal_pixel_map``): 1, every pixel exact (the
        renders that make synthetic camera data); the overlay, a display, takes ``IDEAL_MAP_STEP`` (within 0.02 px,
        a tenth of the time, which its first frame waits for)."""
        if map_step not in (1, 2, 4, 8, 16, 32):
            raise ValueError(f"map_step {map_step}: 1 or a power of two up to 32")
        self.cam = cam
        self.map_step = int(map_step)
        self.near, self.far = near, far
        self.ssaa = int(ssaa)
        self.ambient = ambient
        self.light = np.asarray(light, dtype=np.float64)
        self.background = tuple(c / 255.0 for c in background)
        if _SPARE:  # the one prepare_context made or a released renderer handed on
            self.ctx, self.progs = _SPARE.pop()
            self._current()
        else:
            self.ctx = _new_context()
            self.progs = _programs(self.ctx)
        self.prog = self.progs[False]
        self.meshes: dict[str, Mesh] = {}
        try:
            self._setup_camera(cam)
        except Exception:
            _SPARE.append((self.ctx, self.progs))  # the context goes to the next renderer, not lost with this one
            raise

    @property
    def gl_renderer(self) -> str:
        return self.ctx.info.get("GL_RENDERER", "?")

    def _current(self) -> None:
        """Make this renderer's context the thread's current one before its GL calls: moderngl issues them to
        whichever context is current, and with several renderers in one thread (the overlay's and an aero flow's;
        a context made ahead by :func:`prepare_context`) the last one made would take every renderer's drawing."""
        self.ctx.__enter__()

    def _setup_camera(self, cam: CameraModel) -> None:
        """The ideal (undistorted) render camera: same focal lengths, a margin that covers the distorted
        field of view, scaled by the supersampling factor; plus the remap from it to the real camera."""
        self.cam = cam
        W, H = cam.width, cam.height
        margin_l = margin_t = 0
        Wr, Hr = W, H
        if cam.has_distortion:
            ideal = cam.ideal_pixel_map(self.map_step)
            # the ideal render covers rays up to MAX_HALF_ANGLE_DEG off the axis: a fisheye's wider rays (and its
            # pixels with no ray in front, NaN) are left undrawn, far outside the render
            reach = np.tan(np.radians(MAX_HALF_ANGLE_DEG)) * np.array([cam.fx, cam.fy])
            with np.errstate(invalid="ignore"):
                drawn = np.all(np.abs(ideal - [cam.cx, cam.cy]) <= reach, axis=-1)
            if not drawn.any():
                raise RenderError("no pixel of the camera sees a ray the renderer can draw (a damaged CameraInfo?)")
            ideal[~drawn] = _UNDRAWN
            margin_l = int(np.ceil(max(0.0, -ideal[drawn, 0].min()))) + 2
            margin_t = int(np.ceil(max(0.0, -ideal[drawn, 1].min()))) + 2
            Wr = int(np.ceil(max(W, ideal[drawn, 0].max() + 1))) + margin_l + 2
            Hr = int(np.ceil(max(H, ideal[drawn, 1].max() + 1))) + margin_t + 2
            self._ideal = ideal
        K = cam.K.copy()
        K[0, 2] += margin_l
        K[1, 2] += margin_t
        ideal_cam = CameraModel(Wr, Hr, K, np.zeros(5), "plumb_bob")
        self.render_cam = ideal_cam.scaled(self.ssaa) if self.ssaa > 1 else ideal_cam
        if cam.has_distortion:
            # distorted pixel -> coordinates in the (supersampled) ideal render
            m = (self._ideal + np.array([margin_l, margin_t]) + 0.5) * self.ssaa - 0.5
            self._map = m.astype(np.float32)
            self._map_coarse = self._map[::_MAP_STEP, ::_MAP_STEP]  # for finding a patch's camera pixels
        else:
            self._map = None
        rc = self.render_cam
        self.fbo = self.ctx.framebuffer(
            color_attachments=[self.ctx.texture((rc.width, rc.height), 4),
                               self.ctx.texture((rc.width, rc.height), 1, dtype="f4")],
            depth_attachment=self.ctx.depth_renderbuffer((rc.width, rc.height)))
        # compositing needs colour and coverage only: a framebuffer without the metric-depth attachment
        self.patch_fbo = self.ctx.framebuffer(color_attachments=[self.fbo.color_attachments[0]],
                                              depth_attachment=self.fbo.depth_attachment)
        self.proj = projection_matrix(rc, self.near, self.far)
        self._real_depth_tex: moderngl.Texture | None = None
        self._depth_map_tex: moderngl.Texture | None = None

    # -- scene ---------------------------------------------------------------------------------------------
    def add(self, mesh: Mesh) -> Mesh:
        self._current()
        self.meshes[mesh.name] = mesh
        self._upload(mesh, first=True)
        return mesh

    def remove(self, name: str) -> None:
        self._current()
        m = self.meshes.pop(name, None)
        if m and m._vao:
            for v in m._vao.values():
                v.release()
            for b in m._bufs.values():
                b.release()
        if m and m._tex:
            m._tex.release()
        if m:  # (added again, it uploads afresh)
            m._vao, m._bufs, m._tex = None, {}, None

    def update(self, name: str, vertices: np.ndarray | None = None, colors: np.ndarray | None = None,
               pose: np.ndarray | None = None) -> None:
        self._current()
        m = self.meshes[name]
        if vertices is not None:
            m.vertices = np.asarray(vertices, dtype=np.float64)
        if colors is not None:
            m.colors = np.asarray(colors, dtype=np.float64)
        if pose is not None:
            m.pose = np.asarray(pose, dtype=np.float64)
        if vertices is not None or colors is not None:
            self._upload(m, first=False)

    def _attributes(self, m: Mesh) -> tuple[dict[str, np.ndarray], np.ndarray | None]:
        """Vertex attributes and the index buffer's triangles: smooth meshes are drawn indexed (one entry
        per vertex); flat ones repeat each vertex per triangle to carry the face normal (no indices)."""
        V = np.asarray(m.vertices, dtype=np.float64)
        F = np.asarray(m.triangles, dtype=np.int64)
        ref = V if m.ref is None else np.asarray(m.ref, dtype=np.float64)
        if ref.shape[1] == 2:
            ref = np.c_[ref, np.zeros(len(ref))]
        col = np.ones_like(V) if m.colors is None else np.asarray(m.colors, dtype=np.float64)[:, :3]
        if m.smooth:
            n = vertex_normals(V, F)
            nref = vertex_normals(ref, F) if m.mode == "texture" else n
            return {"in_pos": V, "in_normal": n, "in_ref": ref, "in_nref": nref, "in_color": col}, F
        fn = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
        fn /= np.maximum(np.linalg.norm(fn, axis=1, keepdims=True), 1e-300)
        frn = np.cross(ref[F[:, 1]] - ref[F[:, 0]], ref[F[:, 2]] - ref[F[:, 0]])
        frn /= np.maximum(np.linalg.norm(frn, axis=1, keepdims=True), 1e-300)
        idx = F.ravel()
        return {"in_pos": V[idx], "in_normal": np.repeat(fn, 3, axis=0), "in_ref": ref[idx],
                "in_nref": np.repeat(frn, 3, axis=0) if m.mode == "texture" else np.repeat(fn, 3, axis=0),
                "in_color": col[idx]}, None

    def _upload(self, m: Mesh, first: bool) -> None:
        attrs, tris = self._attributes(m)
        if first or not m._bufs:
            m._bufs = {k: self.ctx.buffer(v.astype("f4").tobytes(), dynamic=True) for k, v in attrs.items()}
            ibo = None
            if tris is not None:
                ibo = m._bufs["_index"] = self.ctx.buffer(np.ascontiguousarray(tris, dtype="i4").tobytes())
            m._vao = {occ: self.ctx.vertex_array(p, [(b, "3f", k) for k, b in m._bufs.items() if k in p],
                                                 index_buffer=ibo, index_element_size=4)
                      for occ, p in self.progs.items()}
            if m.texture is not None:
                tex = np.asarray(m.texture)
                if tex.ndim == 2:
                    tex = np.repeat(tex[:, :, None], 3, axis=2)
                tex = np.ascontiguousarray(tex[::-1, :, :3])
                if tex.dtype != np.uint8:
                    tex = np.clip(tex * 255 if tex.max() <= 1.0 else tex, 0, 255).astype(np.uint8)
                m._tex = self.ctx.texture((tex.shape[1], tex.shape[0]), 3, tex.tobytes())
                m._tex.build_mipmaps()
                m._tex.repeat_x = m._tex.repeat_y = True
                import moderngl
                m._tex.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
                m._tex.anisotropy = float(os.environ.get("SIMREAL_GL_ANISOTROPY", "1"))
        else:
            for k, v in attrs.items():
                buf = m._bufs[k]
                data = v.astype("f4").tobytes()
                if len(data) != buf.size:
                    buf.orphan(len(data))
                buf.write(data)

    # -- drawing -------------------------------------------------------------------------------------------
    def render(self, T_world_cam: np.ndarray, names: list[str] | None = None, real_depth: np.ndarray | None = None,
               occlusion_margin: float = 0.0, background: np.ndarray | None = None,
               distort: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Render from camera pose ``T_world_cam`` (optical frame). Returns (RGB uint8 HxWx3, depth float32 HxW
        metres along the optical axis, 0 where nothing was drawn), in the real camera (with distortion).

        ``real_depth`` (metres, real camera pixels, 0/NaN invalid): fragments farther than it are discarded
        (occlusion by real geometry). ``background`` (HxWx3 uint8): composited under the drawn pixels.
        """
        self._current()
        rc = self.render_cam
        self.fbo.use()
        self.ctx.viewport = (0, 0, rc.width, rc.height)
        # background is (r, g, b); mypy cannot count a tuple built from a generator
        self.fbo.clear(*self.background, 0.0, depth=1.0)  # type: ignore[call-arg, misc]
        self._draw(T_world_cam, names, real_depth, occlusion_margin)
        rgb = np.frombuffer(self.fbo.read(components=3, attachment=0), np.uint8).reshape(rc.height, rc.width, 3)[::-1]
        depth = np.frombuffer(self.fbo.read(components=1, attachment=1, dtype="f4"),
                              np.float32).reshape(rc.height, rc.width)[::-1]
        return self._to_camera(rgb, depth, background, distort)

    def composite(self, T_world_cam: np.ndarray, background: np.ndarray, names: list[str] | None = None,
                  real_depth: np.ndarray | None = None, occlusion_margin: float = 0.0, bgr: bool = False) -> np.ndarray:
        """Meshes drawn over a camera image (uint8 HxWx3 in real-camera pixels, RGB or ``bgr``), with optional
        occlusion by real depth; returns a new image in the same channel order.

        Only the meshes' screen box is drawn, read back and blended: the box is the projection of their
        vertices in the ideal render camera (the whole view if one lies behind the near plane). With lens
        distortion the box's camera pixels look their colour and coverage up in the drawn patch through the
        distortion map (bilinear, so edges are antialiased by coverage). With supersampling: :meth:`render`."""
        self._current()
        cam = self.cam
        bg = np.asarray(background)
        if bg.dtype != np.uint8 or bg.shape != (cam.height, cam.width, 3):
            raise RenderError(f"background is {bg.shape} {bg.dtype}, expected {(cam.height, cam.width, 3)} uint8")
        if self.ssaa > 1:
            rgb, _ = self.render(T_world_cam, names, real_depth, occlusion_margin,
                                 background=bg[..., ::-1] if bgr else bg)
            return np.ascontiguousarray(rgb[..., ::-1]) if bgr else rgb
        out = bg.copy()
        box = self.screen_box(T_world_cam, names)
        if box is None:
            return out
        x0, y0, _x1, _y1 = box
        # the camera pixels of the box (where it lands, and the real depth its fragments look up)
        cbox = box if self._map is None else self._camera_box(box)
        if cbox is None:
            return out
        cx0, cy0, cx1, cy1 = cbox
        patch = self._draw_patch(T_world_cam, names, real_depth, occlusion_margin, box, cbox)
        if self._map is not None:
            mm = self._map[cy0:cy1, cx0:cx1] - np.array([x0, y0], np.float32)
            patch = cv2.remap(patch, mm[..., 0], mm[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                              borderValue=0)
        rgb = cv2.cvtColor(patch, cv2.COLOR_RGBA2BGR if bgr else cv2.COLOR_RGBA2RGB)
        a = patch[..., 3].astype(np.float32) * (1.0 / 255.0)
        out[cy0:cy1, cx0:cx1] = cv2.blendLinear(rgb, out[cy0:cy1, cx0:cx1], a, 1.0 - a)
        return out

    def screen_box(self, T_world_cam: np.ndarray, names: list[str] | None = None) -> tuple[int, int, int, int] | None:
        """(x0, y0, x1, y1), top-down pixel box of the render camera that holds every drawn vertex (2 px
        margin), the whole view if a vertex is behind the near plane, None if nothing is in view."""
        rc = self.render_cam
        view = np.linalg.inv(T_world_cam)
        lo, hi = np.full(2, np.inf), np.full(2, -np.inf)
        for name in (names if names is not None else list(self.meshes)):
            m = self.meshes[name]
            if not m.visible or not len(m.vertices):
                continue
            T = view @ m.pose
            X = np.asarray(m.vertices, dtype=np.float64) @ T[:3, :3].T + T[:3, 3]
            if not np.all(np.isfinite(X)) or X[:, 2].min() <= self.near:
                if np.all(X[:, 2] <= self.near):
                    continue  # wholly behind the camera
                return 0, 0, rc.width, rc.height
            uv = np.c_[rc.fx * X[:, 0] / X[:, 2] + rc.K[0, 1] * X[:, 1] / X[:, 2] + rc.cx,
                       rc.fy * X[:, 1] / X[:, 2] + rc.cy]
            lo, hi = np.minimum(lo, uv.min(axis=0)), np.maximum(hi, uv.max(axis=0))
        if not np.all(np.isfinite(lo)):
            return None
        x0, y0 = (max(0, int(np.floor(v)) - 2) for v in lo)
        x1, y1 = min(rc.width, int(np.ceil(hi[0])) + 3), min(rc.height, int(np.ceil(hi[1])) + 3)
        return (x0, y0, x1, y1) if x1 > x0 and y1 > y0 else None

    def _draw_patch(self, T_world_cam, names, real_depth, occlusion_margin, box, depth_box) -> np.ndarray:
        """Draw the meshes inside ``box`` only (scissor) and read back that patch, RGBA top-down, alpha =
        coverage (0 where nothing was drawn)."""
        rc = self.render_cam
        x0, y0, x1, y1 = box
        gl_box = (x0, rc.height - y1, x1 - x0, y1 - y0)  # the framebuffer's rows run bottom-up
        self.patch_fbo.use()
        self.ctx.viewport = (0, 0, rc.width, rc.height)
        self.ctx.scissor = gl_box
        try:
            self.patch_fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0, viewport=gl_box)
            self._draw(T_world_cam, names, real_depth, occlusion_margin, depth_box)
            patch = np.empty((y1 - y0, x1 - x0, 4), np.uint8)
            self.patch_fbo.read_into(patch, viewport=gl_box, components=4, attachment=0)
        finally:
            self.ctx.scissor = None
        return cv2.flip(patch, 0)

    def _camera_box(self, box) -> tuple[int, int, int, int] | None:
        """(x0, y0, x1, y1) of the camera pixels whose ideal-render coordinates fall inside ``box``: tested on
        every ``_MAP_STEP``-th pixel, grown by that step (a few extra pixels map outside the patch: alpha 0)."""
        k = _MAP_STEP
        x0, y0, x1, y1 = box
        mx, my = self._map_coarse[..., 0], self._map_coarse[..., 1]
        inside = (mx >= x0 - 1) & (mx <= x1) & (my >= y0 - 1) & (my <= y1)
        rows, cols = np.nonzero(inside.any(axis=1))[0], np.nonzero(inside.any(axis=0))[0]
        if not len(rows):
            return None
        cam = self.cam
        return (max(0, (cols[0] - 1) * k), max(0, (rows[0] - 1) * k),
                min(cam.width, (cols[-1] + 1) * k + 1), min(cam.height, (rows[-1] + 1) * k + 1))

    def _uniform(self, name: str) -> moderngl.Uniform:
        """A uniform of the current program (moderngl types ``prog[name]`` as any kind of program member)."""
        return cast("moderngl.Uniform", self.prog[name])

    def _draw(self, T_world_cam, names, real_depth, occlusion_margin, depth_box=None) -> None:
        import moderngl

        self.ctx.enable(moderngl.DEPTH_TEST)
        self.ctx.front_face = "ccw"  # the projection keeps a counter-clockwise triangle counter-clockwise
        occlude = real_depth is not None
        self.prog = self.progs[occlude]
        view = np.linalg.inv(T_world_cam)
        self._uniform("u_view").write(_gl(view))
        self._uniform("u_proj").write(_gl(self.proj))
        light_cam = view[:3, :3] @ (self.light / np.linalg.norm(self.light))
        self._uniform("u_light").value = tuple(float(x) for x in light_cam)
        self._uniform("u_ambient").value = float(self.ambient)
        if occlude:
            self._set_real_depth(real_depth, depth_box)
            assert self._real_depth_tex is not None and self._depth_map_tex is not None  # _set_real_depth made them
            self._real_depth_tex.use(location=1)
            self._depth_map_tex.use(location=6)
            self._uniform("u_real_depth").value = 1
            self._uniform("u_depth_map").value = 6
            self._uniform("u_real_size").value = (float(self.cam.width), float(self.cam.height))
            self._uniform("u_occlusion_margin").value = float(occlusion_margin)
        for name in (names if names is not None else list(self.meshes)):
            m = self.meshes[name]
            if not m.visible:
                continue
            (self.ctx.enable if m.cull_back else self.ctx.disable)(moderngl.CULL_FACE)
            self._uniform("u_model").write(_gl(m.pose))
            self._uniform("u_mode").value = {"vertex": 0, "texture": 1, "flat": 2, "uv": 3}[m.mode]
            self._uniform("u_tint").value = tuple(float(x) for x in m.tint)
            self._uniform("u_tex_scale").value = float(m.tex_scale)
            self._uniform("u_unlit").value = 1.0 if m.unlit else 0.0
            if m._tex is not None:
                m._tex.use(location=0)
                self._uniform("u_tex").value = 0
            assert m._vao is not None  # add() uploaded the mesh
            m._vao[occlude].render(moderngl.TRIANGLES)

    def _set_real_depth(self, real_depth: np.ndarray, box=None) -> None:
        """Upload real depth as it comes (real-camera pixels; only ``box`` (x0, y0, x1, y1) of it when given:
        the pixels this draw can look up); the occlusion shader finds each render pixel's real pixel in a
        lookup texture (lens distortion, supersampling, margins), made once per camera."""
        import moderngl

        rc, cam = self.render_cam, self.cam
        real_depth = np.asarray(real_depth)
        if real_depth.shape != (cam.height, cam.width):
            raise RenderError(f"real depth is {real_depth.shape[1]}x{real_depth.shape[0]}, the camera "
                              f"{cam.width}x{cam.height}")
        x0, y0, x1, y1 = box if box is not None else (0, 0, cam.width, cam.height)
        d = np.array(real_depth[y0:y1, x0:x1], dtype=np.float32)  # a copy: invalid values are zeroed in place
        d[~((d > 0) & (d < np.inf))] = 0  # NaN, +-inf, negative: invalid
        if self._real_depth_tex is None:
            self._real_depth_tex = self.ctx.texture((cam.width, cam.height), 1, dtype="f4")
            self._real_depth_tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
            # render pixel -> real camera pixel (the ideal ray distorted, as CameraModel.project does it); rows
            # bottom-up like the framebuffer. OpenCV's rectification map is that lookup (K_render as the new camera):
            # the same pixels to 3e-5 px as projecting each ray, in milliseconds where projectPoints took 0.1-1 s
            import cv2

            mx, my = cam.undistort_maps(rc.K, (rc.width, rc.height), cv2.CV_32FC1)
            uv = np.dstack([mx, my])
            inside = np.all(np.isfinite(uv), axis=-1) & (uv[..., 0] > -0.5) & (uv[..., 0] < cam.width - 0.5) \
                & (uv[..., 1] > -0.5) & (uv[..., 1] < cam.height - 0.5)
            # inside: at least 0 (the shader reads a negative x as outside; -0.5 < x < 0 is pixel 0's own)
            uv = np.clip(uv, 0.0, [cam.width - 1, cam.height - 1])
            m = np.where(inside[..., None], uv, -1.0).astype(np.float32)
            self._depth_map_tex = self.ctx.texture((rc.width, rc.height), 2, np.ascontiguousarray(m[::-1]).tobytes(),
                                                   dtype="f4")
            self._depth_map_tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self._real_depth_tex.write(np.ascontiguousarray(d[::-1]).tobytes(),
                                   viewport=(x0, cam.height - y1, x1 - x0, y1 - y0))

    def _to_camera(self, rgb, depth, background, distort):
        """Supersampled ideal render -> real camera pixels. Colour is area-averaged then remapped; depth
        goes through 1/Z (affine in pixels on a plane, so exact there) where all samples are valid and
        takes the nearest sample at silhouettes (no blending of two surfaces)."""
        cam, s = self.cam, self.ssaa
        valid = (depth > 0).astype(np.float32)
        inv = np.where(depth > 0, 1.0 / np.where(depth > 0, depth, 1.0), 0.0).astype(np.float32)
        if s > 1:
            down = lambda a: cv2.resize(a, (a.shape[1] // s, a.shape[0] // s), interpolation=cv2.INTER_AREA)  # noqa: E731
            rgb_i, inv_i, val_i = down(rgb), down(inv), down(valid)
        else:
            rgb_i, inv_i, val_i = rgb, inv, valid
        if self._map is not None and distort:
            mm = (self._map + 0.5) / s - 0.5  # coordinates in the ideal (not supersampled) render
            rgb_o = cv2.remap(rgb_i, mm[..., 0], mm[..., 1], cv2.INTER_LINEAR)
            inv_o = cv2.remap(inv_i, mm[..., 0], mm[..., 1], cv2.INTER_LINEAR)
            cov = cv2.remap(val_i, mm[..., 0], mm[..., 1], cv2.INTER_LINEAR)
            near = cv2.remap(depth, self._map[..., 0], self._map[..., 1], cv2.INTER_NEAREST)
        else:
            rgb_o, inv_o, cov = (rgb_i[: cam.height, : cam.width], inv_i[: cam.height, : cam.width],
                                 val_i[: cam.height, : cam.width])
            c = s // 2
            near = depth[c::s, c::s][: cam.height, : cam.width]
        full = cov > 0.9999
        d_o = np.where(full, 1.0 / np.where(full, inv_o / np.maximum(cov, 1e-6), 1.0), near).astype(np.float32)
        d_o[cov <= 0.0] = 0.0
        if background is not None:
            a = np.clip(cov, 0, 1)[..., None]
            rgb_o = (rgb_o.astype(np.float32) * a + background.astype(np.float32) * (1 - a)).round().astype(np.uint8)
        return np.ascontiguousarray(rgb_o), np.ascontiguousarray(d_o)

    def release(self, keep: bool = False) -> None:
        """Free the renderer's GL objects; ``keep``: its context and compiled programs go to the next Renderer of this
        process (a warm-up's renderer: :meth:`SceneOverlay.warm_up`), else they are freed too."""
        self._current()
        for n in list(self.meshes):
            self.remove(n)
        attached = (*self.fbo.color_attachments, self.fbo.depth_attachment)  # (a framebuffer's release leaves them)
        self.patch_fbo.release()
        self.fbo.release()
        if not keep:
            self.ctx.release()
            return
        for obj in (*attached, self._real_depth_tex, self._depth_map_tex):
            if obj is not None:
                obj.release()
        self._real_depth_tex = self._depth_map_tex = None
        _SPARE.append((self.ctx, self.progs))
