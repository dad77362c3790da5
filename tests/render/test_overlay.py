"""Overlay core: occlusion by real depth in the compositing path, live choice of modes against the
on-screen truncation error, colour maps and von Mises, an object behind the camera."""

import numpy as np
import pytest

from simreal_nodes import geometry as G
from simreal_nodes.camera import CameraModel
from simreal_nodes.render.gl import Mesh, Renderer
from simreal_nodes.render.overlay import ObjectOverlay, OverlayCompositor, apply_colormap, colormap_lut, von_mises
from tests.modelkit import beam_model, strip_load_model

CAMS = {
    "pinhole": CameraModel.from_intrinsics(320, 240, 262.0, 260.0, 159.3, 120.6),
    "distorted": CameraModel.from_intrinsics(320, 240, 262.0, 260.0, 159.3, 120.6, D=[-0.2, 0.05, 0.001, -0.001, 0.0]),
}


@pytest.mark.parametrize("name", list(CAMS))
def test_composite_occlusion_is_exact(name):
    """A red virtual plane at 2 m over a grey image: hidden where real depth is closer (1.5 m), shown where the
    real surface is farther (2.5 m) or depth is invalid (NaN, 0); untouched image outside the plane."""
    cam = CAMS[name]
    r = Renderer(cam)
    V = np.array([[-0.5, -0.4, 0], [0.5, -0.4, 0], [0.5, 0.4, 0], [-0.5, 0.4, 0]], float)
    r.add(Mesh("v", V, np.array([[0, 1, 2], [0, 2, 3]]), tint=(1, 0, 0), unlit=True, pose=G.make_T(t=[0, 0, 2.0])))
    bg = np.full((cam.height, cam.width, 3), 100, np.uint8)
    real = np.zeros((cam.height, cam.width), np.float32)
    real[:, : cam.width // 2] = 1.5
    real[:60, cam.width // 2:] = 2.5
    real[60:120, cam.width // 2:] = np.nan
    out = r.composite(np.eye(4), bg, real_depth=real)
    # where the plane projects (exact footprint from the camera model)
    corners = cam.project(V + [0, 0, 2.0])
    u0, v0 = np.ceil(corners.min(0)).astype(int) + 2
    u1, v1 = np.floor(corners.max(0)).astype(int) - 2
    red = (out[..., 0] == 255) & (out[..., 1] == 0)
    inside = np.zeros_like(red)
    inside[v0:v1, u0:u1] = True
    left = np.zeros_like(red)
    left[:, : cam.width // 2 - 2] = True
    assert not red[left].any(), "virtual pixels behind a closer real surface must be hidden"
    right = inside.copy()
    right[:, : cam.width // 2 + 2] = False
    assert red[right].all(), "virtual pixels in front of real depth (or over invalid depth) must show"
    assert (out[~inside & ~np.roll(inside, 3, 0) & ~np.roll(inside, -3, 0) & ~np.roll(inside, 3, 1)
                & ~np.roll(inside, -3, 1) & left] == 100).all()
    # no real depth at all: the whole plane shows
    out2 = r.composite(np.eye(4), bg)
    assert ((out2[..., 0] == 255) & (out2[..., 1] == 0))[inside].all()
    r.release()


def test_gpu_distortion_composite_matches_the_cpu_remap():
    """The lens-distortion composite runs as a second GPU pass (map lookup + blend); it must give the same
    picture as drawing, reading back and remapping on the CPU (``render(background=...)``), edges included."""
    cam = CAMS["distorted"]
    r = Renderer(cam)
    V = np.array([[-0.6, -0.45, 0], [0.6, -0.45, 0], [0.6, 0.45, 0], [-0.6, 0.45, 0]], float)
    col = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0]], float)
    pose = G.make_T(G.rot_axis("y", 0.4), [0.1, 0.05, 1.6])
    r.add(Mesh("v", V, np.array([[0, 1, 2], [0, 2, 3]]), mode="vertex", colors=col, pose=pose))
    rng = np.random.default_rng(0)
    bg = rng.integers(0, 256, (cam.height, cam.width, 3), dtype=np.uint8)
    real = np.full((cam.height, cam.width), 1.55, np.float32)
    real[:, : cam.width // 3] = np.nan
    gpu = r.composite(np.eye(4), bg, real_depth=real).astype(int)
    cpu = r.render(np.eye(4), real_depth=real, background=bg)[0].astype(int)
    diff = np.abs(gpu - cpu).max(axis=2)
    assert (gpu != bg).any(axis=2).mean() > 0.1  # something was drawn (part hidden by the real depth)
    assert diff.mean() < 0.5 and np.mean(diff > 2) < 0.005
    r.release()


def _view(distance):
    """Camera above the beam (object frame: x along, z up), looking down, ``distance`` metres away."""
    return G.make_T(G.rot_axis("x", np.pi), [0.25, 0.01, distance])


def test_modes_chosen_live_bound_the_screen_error():
    m = beam_model(n_modes=8)
    cam = CAMS["pinhole"]
    ob = ObjectOverlay(m, np.eye(4), "displacement", modes=0, max_error_px=0.5)
    chosen = []
    for d in (0.4, 1.0, 4.0, 20.0):
        V, _col, st = ob.geometry(["s"], [0.45], _view(d), cam)
        # the bound holds: compare with the full-mode drawing projected
        full = m.points[ob.nodes] + m.displacement([0.45], ob.nodes)
        T_co = np.linalg.inv(_view(d))
        e = np.linalg.norm(cam.project(G.transform(T_co, V)) - cam.project(G.transform(T_co, full)), axis=1).max()
        assert e <= 0.5 + 1e-6, f"{d} m: {e:.3f} px with {st.modes} modes"
        assert st.error_px <= 0.5
        chosen.append(st.modes)
    assert chosen == sorted(chosen, reverse=True), f"farther views need no more modes: {chosen}"
    assert chosen[0] > 1 and chosen[-1] == 1, chosen
    fixed = ObjectOverlay(m, np.eye(4), modes=3)
    assert fixed.geometry(["s"], [0.45], _view(1.0), cam)[2].modes == 3
    with pytest.raises(ValueError, match="8"):
        ObjectOverlay(m, np.eye(4), modes=9)


def test_out_of_range_and_missing_parameters_are_clamped_not_crashing():
    m = beam_model()
    ob = ObjectOverlay(m, np.eye(4))
    V, _, _ = ob.geometry(["s"], [7.0], _view(1.0), CAMS["pinhole"])
    V2, _, _ = ob.geometry(["s"], [0.5], _view(1.0), CAMS["pinhole"])
    np.testing.assert_allclose(V, V2)
    V3, _, _ = ob.geometry(["s"], [float("nan")], _view(1.0), CAMS["pinhole"])
    np.testing.assert_allclose(V3, m.points[ob.nodes], atol=1e-12)  # NaN -> lower bound (s = 0: no load)


def test_object_behind_the_camera_is_stated_and_image_passes_through():
    m = beam_model()
    cam = CAMS["pinhole"]
    comp = OverlayCompositor(cam, {"beam": ObjectOverlay(m, np.eye(4))}, colorbar=False)
    img = np.random.default_rng(0).integers(0, 255, (cam.height, cam.width, 3), dtype=np.uint8)
    behind = G.make_T(np.eye(3), [0.25, 0.0, 1.0])  # looking along +z, the beam lies at z = 0 behind
    out, st = comp.compose(img, behind, {"beam": (["s"], [0.3])})
    assert st["beam"].behind_camera and st["beam"].visible_nodes == 0
    np.testing.assert_array_equal(out, img)
    out, st = comp.compose(img, _view(0.8), {"beam": (["s"], [0.3])})
    assert not st["beam"].behind_camera and (out != img).any()
    with pytest.raises(ValueError, match="320x240"):
        comp.compose(img[:100], _view(0.8), {})
    comp.release()


def test_colormap_and_von_mises():
    lut = colormap_lut("viridis")
    c = apply_colormap(np.array([0.0, 1.0, 2.0, np.nan]), 0.0, 1.0, lut)
    np.testing.assert_allclose(c[0], lut[0])
    np.testing.assert_allclose(c[1], lut[255])
    np.testing.assert_allclose(c[2], lut[255])  # clipped
    np.testing.assert_allclose(c[3], 0.5)
    with pytest.raises(ValueError, match="unknown colour map"):
        colormap_lut("rainbowish")
    s = np.zeros((3, 6))
    s[0, 0] = 5.0  # uniaxial
    s[1, 3] = 2.0  # pure shear
    s[2, :3] = 7.0  # hydrostatic
    np.testing.assert_allclose(von_mises(s), [5.0, 2.0 * np.sqrt(3), 0.0], atol=1e-12)


def test_a_closed_surface_drawn_without_back_faces_looks_the_same():
    """Closed model surfaces are drawn without back faces (half the fragments): from outside, the picture
    must equal drawing every face, occlusion by real depth and lens distortion included. An open surface
    keeps both faces."""
    from tests.test_geometry import CUBE_F, CUBE_V

    cam = CAMS["distorted"]
    V = (CUBE_V - 0.5) * [0.4, 0.1, 0.05]
    col = np.random.default_rng(0).random((len(V), 3))
    F = G.outward_triangles(V, CUBE_F)
    img = np.random.default_rng(1).integers(0, 255, (cam.height, cam.width, 3), dtype=np.uint8)
    real = np.full((cam.height, cam.width), 2.0, np.float32)
    real[:, : cam.width // 2] = 0.3  # a real surface in front of the left half
    out = {}
    for cull in (True, False):
        r = Renderer(cam)
        r.add(Mesh("box", V, F, mode="vertex", colors=col, cull_back=cull))
        out[cull] = [r.composite(T, img, real_depth=real) for T in
                     (G.make_T(G.rot_axis("x", np.pi), [0.0, 0.0, 0.5]), G.look_at([0.15, -0.35, 0.25], [0, 0, 0]))]
        r.release()
    for a, b in zip(out[True], out[False]):
        assert (a != img).any(axis=2).mean() > 0.05
        np.testing.assert_array_equal(a, b)
    strip = OverlayCompositor(cam, {"beam": ObjectOverlay(beam_model(), np.eye(4))}, colorbar=False)
    assert not strip.renderer.meshes["beam"].cull_back  # an open strip: both faces drawn
    strip.release()


def test_several_contacts_are_drawn_summed():
    """A collision's message with two contacts (the second's parameters as name@2): the drawn deformation is the sum
    of both (a linear model), coloured by the summed displacement; with one contact, the one state's."""
    m = strip_load_model()
    ob = ObjectOverlay(m, np.eye(4), "displacement", modes=m.fields["displacement"].n_modes)
    cam, view = CAMS["pinhole"], _view(1.0)
    V, col, _ = ob.geometry(["s", "load_scale", "s@2", "load_scale@2"], [0.1, 0.5, 0.25, 0.3], view, cam)
    u = 0.5 * m.displacement([0.1], ob.nodes) + 0.3 * m.displacement([0.25], ob.nodes)
    np.testing.assert_allclose(V, m.points[ob.nodes] + u, atol=1e-12)
    V1, _, _ = ob.geometry(["s", "load_scale"], [0.1, 0.5], view, cam)
    np.testing.assert_allclose(V1, m.points[ob.nodes] + 0.5 * m.displacement([0.1], ob.nodes), atol=1e-12)
    assert not np.allclose(col, ob.geometry(["s", "load_scale"], [0.1, 0.5], view, cam)[1])
