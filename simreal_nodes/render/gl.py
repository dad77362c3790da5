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

import cv2
import numpy as np

from simreal_nodes.errors import SimrealError
from simreal_nodes.vision.camera import CameraModel

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
    if (m.x >= 0.0) real = texture(u_real_depth, vec2((m.x + 0.5) / u_real_size.x, 1.0 - (m.y + 0.5) / u_real_size.y)).r;
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


BG_VERT = """
#version 330
in vec2 in_xy;
void main() { gl_Position = vec4(in_xy, 0.0, 1.0); }
"""

BG_FRAG = """
#version 330
uniform sampler2D u_bg;
uniform vec2 u_viewport;
layout(location = 0) out vec4 f_color;
layout(location = 1) out float f_depth;
void main() {
    vec2 p = gl_FragCoord.xy / u_viewport;
    f_color = vec4(texture(u_bg, vec2(p.x, 1.0 - p.y)).rgb, 1.0);  // image rows are top-down
    f_depth = 0.0;
}
"""


DISTORT_FRAG = """
#version 330
uniform sampler2D u_drawn;     // the meshes alone in the ideal render camera (RGBA, alpha = coverage)
uniform sampler2D u_bg;        // the camera image, rows top-down
uniform sampler2D u_map;       // camera pixel -> ideal render pixel, rows bottom-up like this framebuffer
uniform vec2 u_drawn_size;
uniform vec2 u_viewport;
layout(location = 0) out vec4 f_color;
void main() {
    vec2 m = texelFetch(u_map, ivec2(gl_FragCoord.xy), 0).xy;
    vec4 d = texture(u_drawn, vec2((m.x + 0.5) / u_drawn_size.x, 1.0 - (m.y + 0.5) / u_drawn_size.y));
    vec2 p = gl_FragCoord.xy / u_viewport;
    vec3 bg = texture(u_bg, vec2(p.x, 1.0 - p.y)).rgb;
    f_color = vec4(bg + (d.rgb - bg) * d.a, 1.0);
}
"""


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
    _vao: object = None
    _bufs: dict = field(default_factory=dict)
    _tex: object = None


def vertex_normals(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    fn = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    n = np.zeros_like(V)
    for k in range(3):
        np.add.at(n, F[:, k], fn)
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    return n / np.where(ln > 0, ln, 1.0)


class Renderer:
    """Offscreen renderer for one camera model (resolution, K, distortion)."""

    def __init__(self, cam: CameraModel, near: float = 0.05, far: float = 20.0, ssaa: int = 1,
                 light=(0.3, 0.8, 0.5), ambient: float = 0.55, background=(0, 0, 0)):
        import moderngl

        self.cam = cam
        self.near, self.far = near, far
        self.ssaa = int(ssaa)
        self.ambient = ambient
        self.light = np.asarray(light, dtype=np.float64)
        self.background = tuple(c / 255.0 for c in background)
        backend = os.environ.get("SIMREAL_GL_BACKEND", "egl")
        try:
            self.ctx = moderngl.create_standalone_context(backend=backend) if backend else moderngl.create_standalone_context()
        except Exception as e:  # noqa: BLE001
            raise RenderError(f"cannot create an OpenGL context over {backend or 'the default backend'} ({e}); "
                              "install libegl1 and libgl1-mesa-dri (./run setup does)") from None
        self.progs = {occ: self.ctx.program(vertex_shader=VERT, fragment_shader=FRAG.replace(
            "//DEFINES", "#define OCCLUSION" if occ else "")) for occ in (False, True)}
        self.prog = self.progs[False]
        self.meshes: dict[str, Mesh] = {}
        self._pass_buffers: list = []
        self._setup_camera(cam)

    @property
    def gl_renderer(self) -> str:
        return self.ctx.info.get("GL_RENDERER", "?")

    def _setup_camera(self, cam: CameraModel) -> None:
        """The ideal (undistorted) render camera: same focal lengths, a margin that covers the distorted
        field of view, scaled by the supersampling factor; plus the remap from it to the real camera."""
        self.cam = cam
        W, H = cam.width, cam.height
        margin_l = margin_t = 0
        Wr, Hr = W, H
        if cam.has_distortion:
            xs, ys = np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64))
            ideal = cam.undistort_points(np.c_[xs.ravel(), ys.ravel()]).reshape(H, W, 2)
            margin_l = int(np.ceil(max(0.0, -ideal[..., 0].min()))) + 2
            margin_t = int(np.ceil(max(0.0, -ideal[..., 1].min()))) + 2
            Wr = int(np.ceil(max(W, ideal[..., 0].max() + 1))) + margin_l + 2
            Hr = int(np.ceil(max(H, ideal[..., 1].max() + 1))) + margin_t + 2
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
        else:
            self._map = None
        rc = self.render_cam
        self.fbo = self.ctx.framebuffer(
            color_attachments=[self.ctx.texture((rc.width, rc.height), 4), self.ctx.texture((rc.width, rc.height), 1, dtype="f4")],
            depth_attachment=self.ctx.depth_renderbuffer((rc.width, rc.height)))
        self.proj = projection_matrix(rc, self.near, self.far)
        self._real_depth_tex = None

    # -- scene ---------------------------------------------------------------------------------------------
    def add(self, mesh: Mesh) -> Mesh:
        self.meshes[mesh.name] = mesh
        self._upload(mesh, first=True)
        return mesh

    def remove(self, name: str) -> None:
        m = self.meshes.pop(name, None)
        if m and m._vao:
            for v in m._vao.values():
                v.release()
            for b in m._bufs.values():
                b.release()

    def update(self, name: str, vertices: np.ndarray | None = None, colors: np.ndarray | None = None,
               pose: np.ndarray | None = None) -> None:
        m = self.meshes[name]
        if vertices is not None:
            m.vertices = np.asarray(vertices, dtype=np.float64)
        if colors is not None:
            m.colors = np.asarray(colors, dtype=np.float64)
        if pose is not None:
            m.pose = np.asarray(pose, dtype=np.float64)
        if vertices is not None or colors is not None:
            self._upload(m, first=False)

    def _attributes(self, m: Mesh) -> dict[str, np.ndarray]:
        V = np.asarray(m.vertices, dtype=np.float64)
        F = np.asarray(m.triangles, dtype=np.int64)
        ref = V if m.ref is None else np.asarray(m.ref, dtype=np.float64)
        if ref.shape[1] == 2:
            ref = np.c_[ref, np.zeros(len(ref))]
        col = np.ones_like(V) if m.colors is None else np.asarray(m.colors, dtype=np.float64)[:, :3]
        if m.smooth:
            n = vertex_normals(V, F)
            nref = vertex_normals(ref, F) if m.mode == "texture" else n
            idx = F.ravel()
            return {"in_pos": V[idx], "in_normal": n[idx], "in_ref": ref[idx], "in_nref": nref[idx], "in_color": col[idx]}
        fn = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
        fn /= np.maximum(np.linalg.norm(fn, axis=1, keepdims=True), 1e-300)
        frn = np.cross(ref[F[:, 1]] - ref[F[:, 0]], ref[F[:, 2]] - ref[F[:, 0]])
        frn /= np.maximum(np.linalg.norm(frn, axis=1, keepdims=True), 1e-300)
        idx = F.ravel()
        return {"in_pos": V[idx], "in_normal": np.repeat(fn, 3, axis=0), "in_ref": ref[idx],
                "in_nref": np.repeat(frn, 3, axis=0) if m.mode == "texture" else np.repeat(fn, 3, axis=0),
                "in_color": col[idx]}

    def _upload(self, m: Mesh, first: bool) -> None:
        attrs = self._attributes(m)
        if first or not m._bufs:
            m._bufs = {k: self.ctx.buffer(v.astype("f4").tobytes(), dynamic=True) for k, v in attrs.items()}
            m._vao = {occ: self.ctx.vertex_array(p, [(b, "3f", k) for k, b in m._bufs.items() if k in p])
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
        import moderngl

        rc = self.render_cam
        self.fbo.use()
        self.ctx.viewport = (0, 0, rc.width, rc.height)
        self.fbo.clear(*self.background, 0.0, depth=1.0)
        self._draw(T_world_cam, names, real_depth, occlusion_margin)
        rgb = np.frombuffer(self.fbo.read(components=3, attachment=0), np.uint8).reshape(rc.height, rc.width, 3)[::-1]
        depth = np.frombuffer(self.fbo.read(components=1, attachment=1, dtype="f4"), np.float32).reshape(rc.height, rc.width)[::-1]
        return self._to_camera(rgb, depth, background, distort)

    def composite(self, T_world_cam: np.ndarray, background_rgb: np.ndarray, names: list[str] | None = None,
                  real_depth: np.ndarray | None = None, occlusion_margin: float = 0.0) -> np.ndarray:
        """Meshes drawn over a camera image (RGB uint8, real-camera pixels), with optional occlusion by real
        depth. Without lens distortion or supersampling the image is composited on the GPU (the camera image
        is a background texture, one readback); otherwise through :meth:`render`'s remap."""
        import moderngl

        rc = self.render_cam
        if self.ssaa > 1:
            rgb, _ = self.render(T_world_cam, names, real_depth, occlusion_margin, background=background_rgb)
            return rgb
        if self._map is not None:
            # lens distortion: draw the meshes alone in the ideal camera, then a second pass at the camera's
            # pixels looks each one up through the distortion map and blends it over the camera image
            self.fbo.use()
            self.ctx.viewport = (0, 0, rc.width, rc.height)
            self.fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
            self._draw(T_world_cam, names, real_depth, occlusion_margin)
            return self._distort_composite(background_rgb)
        if not hasattr(self, "_bg_prog"):
            self._bg_prog, self._bg_vao = self._fullscreen_pass(BG_FRAG)
            self._bg_tex = self.ctx.texture((rc.width, rc.height), 3)
            self._bg_tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
            self._bg_out = np.empty((rc.height, rc.width, 3), np.uint8)
        bg = np.ascontiguousarray(background_rgb, dtype=np.uint8)
        if bg.shape != (rc.height, rc.width, 3):
            raise RenderError(f"background is {bg.shape}, expected {(rc.height, rc.width, 3)}")
        self._bg_tex.write(bg.tobytes())
        self.fbo.use()
        self.ctx.viewport = (0, 0, rc.width, rc.height)
        self.fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        self.ctx.disable(moderngl.DEPTH_TEST)
        self._bg_tex.use(location=2)
        self._bg_prog["u_bg"].value = 2
        self._bg_prog["u_viewport"].value = (float(rc.width), float(rc.height))
        self._bg_vao.render(moderngl.TRIANGLES)
        self._draw(T_world_cam, names, real_depth, occlusion_margin)
        self.fbo.read_into(self._bg_out, components=3, attachment=0)
        return cv2.flip(self._bg_out, 0)

    def _draw(self, T_world_cam, names, real_depth, occlusion_margin) -> None:
        import moderngl

        rc = self.render_cam
        self.ctx.enable(moderngl.DEPTH_TEST)
        self.ctx.disable(moderngl.CULL_FACE)
        occlude = real_depth is not None
        self.prog = self.progs[occlude]
        view = np.linalg.inv(T_world_cam)
        self.prog["u_view"].write(_gl(view))
        self.prog["u_proj"].write(_gl(self.proj))
        light_cam = view[:3, :3] @ (self.light / np.linalg.norm(self.light))
        self.prog["u_light"].value = tuple(float(x) for x in light_cam)
        self.prog["u_ambient"].value = float(self.ambient)
        if occlude:
            self._set_real_depth(real_depth)
            self._real_depth_tex.use(location=1)
            self._depth_map_tex.use(location=6)
            self.prog["u_real_depth"].value = 1
            self.prog["u_depth_map"].value = 6
            self.prog["u_real_size"].value = (float(self.cam.width), float(self.cam.height))
            self.prog["u_occlusion_margin"].value = float(occlusion_margin)
        for name in (names if names is not None else list(self.meshes)):
            m = self.meshes[name]
            if not m.visible:
                continue
            self.prog["u_model"].write(_gl(m.pose))
            self.prog["u_mode"].value = {"vertex": 0, "texture": 1, "flat": 2, "uv": 3}[m.mode]
            self.prog["u_tint"].value = tuple(float(x) for x in m.tint)
            self.prog["u_tex_scale"].value = float(m.tex_scale)
            self.prog["u_unlit"].value = 1.0 if m.unlit else 0.0
            if m._tex is not None:
                m._tex.use(location=0)
                self.prog["u_tex"].value = 0
            m._vao[occlude].render(moderngl.TRIANGLES)

    def _set_real_depth(self, real_depth: np.ndarray) -> None:
        """Upload real depth as it comes (real-camera pixels); the occlusion shader finds each render pixel's
        real pixel in a lookup texture (lens distortion, supersampling, margins), made once per camera."""
        import moderngl

        rc, cam = self.render_cam, self.cam
        d = np.nan_to_num(np.asarray(real_depth, dtype=np.float32), nan=0.0, posinf=0.0, neginf=0.0)
        if d.shape != (cam.height, cam.width):
            raise RenderError(f"real depth is {d.shape[1]}x{d.shape[0]}, the camera {cam.width}x{cam.height}")
        d[d < 0] = 0
        if self._real_depth_tex is None:
            self._real_depth_tex = self.ctx.texture((cam.width, cam.height), 1, dtype="f4")
            self._real_depth_tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
            # render pixel -> real camera pixel (distort the ideal ray); rows bottom-up like the framebuffer
            xs, ys = np.meshgrid(np.arange(rc.width, dtype=np.float64), np.arange(rc.height, dtype=np.float64))
            rays = np.stack([(xs - rc.cx) / rc.fx, (ys - rc.cy) / rc.fy, np.ones_like(xs)], -1).reshape(-1, 3)
            uv = cam.project(rays).reshape(rc.height, rc.width, 2)
            inside = np.all(np.isfinite(uv), axis=-1) & (uv[..., 0] > -0.5) & (uv[..., 0] < cam.width - 0.5) \
                & (uv[..., 1] > -0.5) & (uv[..., 1] < cam.height - 0.5)
            m = np.where(inside[..., None], uv, -1.0).astype(np.float32)
            self._depth_map_tex = self.ctx.texture((rc.width, rc.height), 2, np.ascontiguousarray(m[::-1]).tobytes(), dtype="f4")
            self._depth_map_tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self._real_depth_tex.write(np.ascontiguousarray(d[::-1]).tobytes())

    def _fullscreen_pass(self, fragment_shader: str):
        """(program, vertex array) drawing ``fragment_shader`` over the whole viewport (one big triangle)."""
        prog = self.ctx.program(vertex_shader=BG_VERT, fragment_shader=fragment_shader)
        vbo = self.ctx.buffer(np.array([-1, -1, 3, -1, -1, 3], dtype="f4").tobytes())
        self._pass_buffers.append(vbo)  # held as long as the renderer
        return prog, self.ctx.vertex_array(prog, [(vbo, "2f", "in_xy")])

    def _distort_composite(self, background_rgb: np.ndarray) -> np.ndarray:
        import moderngl

        cam, rc = self.cam, self.render_cam
        bg = np.ascontiguousarray(background_rgb, dtype=np.uint8)
        if bg.shape != (cam.height, cam.width, 3):
            raise RenderError(f"background is {bg.shape}, expected {(cam.height, cam.width, 3)}")
        if getattr(self, "_dist_for", None) is not self.fbo:  # first use, or a new camera
            self._dist_for = self.fbo
            self._dist_prog, self._dist_vao = self._fullscreen_pass(DISTORT_FRAG)
            self._dist_bg = self.ctx.texture((cam.width, cam.height), 3)
            self._dist_bg.filter = (moderngl.NEAREST, moderngl.NEAREST)
            self._dist_map = self.ctx.texture((cam.width, cam.height), 2, np.ascontiguousarray(self._map[::-1]).tobytes(), dtype="f4")
            self._dist_map.filter = (moderngl.NEAREST, moderngl.NEAREST)
            self._dist_fbo = self.ctx.framebuffer(color_attachments=[self.ctx.texture((cam.width, cam.height), 3)])
            self._dist_out = np.empty((cam.height, cam.width, 3), np.uint8)
            drawn = self.fbo.color_attachments[0]
            drawn.filter = (moderngl.LINEAR, moderngl.LINEAR)
            drawn.repeat_x = drawn.repeat_y = False
        self._dist_bg.write(bg.tobytes())
        self._dist_fbo.use()
        self.ctx.viewport = (0, 0, cam.width, cam.height)
        self.ctx.disable(moderngl.DEPTH_TEST)
        self.fbo.color_attachments[0].use(location=3)
        self._dist_bg.use(location=4)
        self._dist_map.use(location=5)
        pr = self._dist_prog
        pr["u_drawn"].value, pr["u_bg"].value, pr["u_map"].value = 3, 4, 5
        pr["u_drawn_size"].value = (float(rc.width), float(rc.height))
        pr["u_viewport"].value = (float(cam.width), float(cam.height))
        self._dist_vao.render(moderngl.TRIANGLES)
        self._dist_fbo.read_into(self._dist_out, components=3, attachment=0)
        return cv2.flip(self._dist_out, 0)

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
            rgb_o, inv_o, cov = rgb_i[: cam.height, : cam.width], inv_i[: cam.height, : cam.width], val_i[: cam.height, : cam.width]
            c = s // 2
            near = depth[c::s, c::s][: cam.height, : cam.width]
        full = cov > 0.9999
        d_o = np.where(full, 1.0 / np.where(full, inv_o / np.maximum(cov, 1e-6), 1.0), near).astype(np.float32)
        d_o[cov <= 0.0] = 0.0
        if background is not None:
            a = np.clip(cov, 0, 1)[..., None]
            rgb_o = (rgb_o.astype(np.float32) * a + background.astype(np.float32) * (1 - a)).round().astype(np.uint8)
        return np.ascontiguousarray(rgb_o), np.ascontiguousarray(d_o)

    def release(self) -> None:
        for n in list(self.meshes):
            self.remove(n)
        self.fbo.release()
        self.ctx.release()
