"""Dense photometric measurement (assimilation/dense.py): a textured plate stretched in its plane by a known
amount, rendered by inverse mapping of its texture (exact, independent of the aligner's sampling), seen from a
camera that moved since the reference view."""

import cv2
import numpy as np
import pytest

from simreal_nodes import geometry as G
from simreal_nodes.assimilation.dense import DenseAligner, DenseSettings, pyramid, sample_surface
from simreal_nodes.assimilation.tracker import DeformableTracker, TrackerConfig
from simreal_nodes.camera import CameraModel
from simreal_nodes.rom.model import ReducedModel
from simreal_nodes.rom.separated import Axis, SeparatedField
from simreal_nodes.states import EstimateState
from tests.modelkit import plate_points

SIZE = 0.2
STRETCH = 0.004  # metres at the far edge for s = 1: u_x = STRETCH s (x / SIZE)^2


def quadratic_model(component: int, amplitude: float, name: str, description: str, n: int = 11) -> ReducedModel:
    """u(x; s) = s * amplitude (x / SIZE)^2 along ``component`` on a square plate (z = 0), s in [0, 1]."""
    P, tris = plate_points(n, SIZE)
    space = np.zeros((1, len(P), 3))
    space[0, :, component] = amplitude * (P[:, 0] / SIZE) ** 2
    s = np.linspace(0, 1, 11)
    axes = [Axis("s", s, "")]
    fld = SeparatedField("displacement", space, [s[None, :]], axes, "m", ["x", "y", "z"])
    return ReducedModel(name, P, tris, "tri3", axes, {"displacement": fld}, tris, description,
                        {"law": "linear_elastic"})


def stretch_model(n: int = 11) -> ReducedModel:
    """u(x; s) = s * (STRETCH (x / SIZE)^2, 0, 0) on a square plate (z = 0), s in [0, 1]."""
    return quadratic_model(0, STRETCH, "plate", "stretched plate", n)


CAM = CameraModel.from_intrinsics(320, 240, 300.0, 300.0, 159.5, 119.5)


def texture(contrast: float, seed: int = 0) -> np.ndarray:
    """Smooth speckle over [-0.05, 0.25]^2 m at 0.25 mm per texel, mean 128, amplitude ~ contrast * 100."""
    rng = np.random.default_rng(seed)
    t = cv2.GaussianBlur(rng.standard_normal((1200, 1200)).astype(np.float32), (0, 0), 4.0)
    return (128 + contrast * 100 * t / t.std()).astype(np.float32)


def _stretch_u(x: np.ndarray, s: float) -> np.ndarray:
    """u_x of :func:`stretch_model`."""
    return s * STRETCH * (np.clip(x, 0, None) / SIZE) ** 2


def render(tex: np.ndarray, T_wc: np.ndarray, s: float, noise: float = 0.0, seed: int = 1,
           u_x=_stretch_u, iterations: int = 20) -> np.ndarray:
    """The plate (z = 0) deformed by s in its plane (u_x(x, s), :func:`stretch_model`'s by default): each pixel's
    ray meets the plane at X; its material point x solves x + u(x) = X (fixed point: u is small and smooth); the
    texture is read at x."""
    v, u = np.mgrid[0 : CAM.height, 0 : CAM.width].astype(np.float64)
    d = np.stack([(u - CAM.cx) / CAM.fx, (v - CAM.cy) / CAM.fy, np.ones_like(u)], -1) @ T_wc[:3, :3].T
    lam = -T_wc[2, 3] / d[..., 2]
    X = T_wc[:3, 3] + lam[..., None] * d
    x = X[..., 0].copy()
    for _ in range(iterations):
        x = X[..., 0] - u_x(x, s)
    texel = 0.25e-3
    mx = ((x + 0.05) / texel).astype(np.float32)
    my = ((X[..., 1] + 0.05) / texel).astype(np.float32)
    img = cv2.remap(tex, mx, my, cv2.INTER_LINEAR)
    if noise:
        img = img + np.random.default_rng(seed).normal(0, noise, img.shape).astype(np.float32)
    return np.clip(img, 0, 255).astype(np.uint8)


def pose(dx: float = 0.0) -> np.ndarray:
    return G.look_at([0.1 + dx, 0.1, 0.35], [0.1, 0.1, 0.0], up=(0, 1, 0))


@pytest.fixture(scope="module")
def model():
    return stretch_model()


def _aligner(model, **kw) -> DenseAligner:
    return DenseAligner(model, np.eye(4), CAM, None, DenseSettings(**kw))


@pytest.mark.parametrize("contrast,noise,tol", [(1.0, 1.0, 0.01), (0.06, 1.5, 0.04)])
def test_stretch_recovered_from_texture_after_camera_motion(model, contrast, noise, tol):
    tex = texture(contrast)
    al = _aligner(model)
    assert al.set_reference(render(tex, pose(), 0.0, noise, seed=1), G.inv(pose()))
    lo, hi = np.zeros(1), np.ones(1)
    T = pose(0.03)
    for s_true in (0.6, 0.25, 0.9):  # the load jumps: the coarse search finds the basin
        r = al.solve(render(tex, T, s_true, noise, seed=2), G.inv(T), np.array([0.5]), lo, hi)
        assert abs(r.mu[0] - s_true) < tol, (contrast, s_true, r.mu)
        assert r.rest_rms > r.debug["rms_at_rest_level"]  # the deformation explains the image better than none
        assert np.isfinite(r.cov_mu[0, 0]) and r.cov_mu[0, 0] > 0


def test_without_rigid_correction_a_camera_error_biases_the_estimate(model):
    """The camera pose given to the aligner is 1.5 mm off: the rigid correction absorbs it, without it the load
    takes the blame."""
    tex = texture(1.0)
    T_err = G.make_T(t=[0.0015, 0.0, 0.0]) @ pose(0.03)
    errs = {}
    for rigid in (True, False):
        al = _aligner(model, rigid=rigid)
        al.set_reference(render(tex, pose(), 0.0), G.inv(pose()))
        r = al.solve(render(tex, pose(0.03), 0.6), G.inv(T_err), np.array([0.5]), np.zeros(1), np.ones(1))
        errs[rigid] = abs(r.mu[0] - 0.6)
    assert errs[True] < 0.02 < errs[False]


def test_no_reference_when_the_object_is_out_of_view(model):
    away = G.look_at([2.0, 2.0, 0.35], [2.0, 2.5, 0.0], up=(0, 0, 1))
    al = _aligner(model)
    assert not al.set_reference(render(texture(1.0), pose(), 0.0), G.inv(away))
    assert not al.has_template


def test_samples_cover_the_surface_evenly(model):
    smp = sample_surface(model, 0.002, 100000)
    assert abs(len(smp.x) - SIZE**2 / 0.002**2) < 0.05 * SIZE**2 / 0.002**2
    np.testing.assert_allclose(np.sum(smp.weights, axis=1), 1.0)
    assert np.all(smp.weights >= 0)
    # the cap holds: the spacing grows
    assert len(sample_surface(model, 0.0005, 5000).x) <= 5500


def test_tracker_dense_mode_takes_a_reference_then_measures(model):
    tex = texture(0.5)
    tr = DeformableTracker(model, np.eye(4), {"s": {"mode": "tracked", "initial": 0.5}}, CAM,
                           TrackerConfig(measurements="dense"))
    bgr = lambda img: cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)  # noqa: E731
    e0 = tr.update(pose(), image_bgr=bgr(render(tex, pose(), 0.0)))
    assert e0.state == EstimateState.INITIALIZING and "reference" in e0.reason
    e1 = tr.update(pose(0.02), image_bgr=bgr(render(tex, pose(0.02), 0.7)))
    assert e1.state == EstimateState.OK, e1.reason
    assert abs(e1.values[0] - 0.7) < 0.02
    e2 = tr.update(pose(0.02), image_bgr=None)
    assert e2.state == EstimateState.LOST and "image" in e2.reason


def test_hostile_frames_are_flagged_and_the_tracker_recovers(model):
    """A black, a saturated and a pure-noise frame give a flagged estimate, a view without the object gives LOST
    with its reason (it once crashed on zero visible samples), and the next good frame is measured again."""
    tex = texture(0.5)
    bgr = lambda img: cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)  # noqa: E731
    tr = DeformableTracker(model, np.eye(4), {"s": {"mode": "tracked", "initial": 0.5}}, CAM,
                           TrackerConfig(measurements="dense"))
    tr.update(pose(), image_bgr=bgr(render(tex, pose(), 0.0)))
    noise = np.random.default_rng(0).integers(0, 255, (CAM.height, CAM.width, 3)).astype(np.uint8)
    for img in (np.zeros_like(noise), np.full_like(noise, 255), noise):
        e = tr.update(pose(0.02), image_bgr=img)
        assert e.state == EstimateState.LOW_CONFIDENCE and np.all(np.isfinite(e.values)), e.reason
    away = G.look_at([2.0, 2.0, 0.35], [2.0, 2.5, 0.0], up=(0, 0, 1))
    e = tr.update(away, image_bgr=bgr(render(tex, pose(), 0.0)))
    assert e.state == EstimateState.LOST and "samples visible" in e.reason
    e = tr.update(pose(0.02), image_bgr=bgr(render(tex, pose(0.02), 0.6)))
    assert e.state == EstimateState.OK and abs(e.values[0] - 0.6) < 0.02


def shift_model(n: int = 11) -> ReducedModel:
    """u(x; s) = s * (STRETCH, 0, 0): a deformation that looks exactly like a rigid shift of the plate (as a
    cantilever's bending looks much like a small rotation of the beam)."""
    P, tris = plate_points(n, SIZE)
    space = np.zeros((1, len(P), 3))
    space[0, :, 0] = STRETCH
    s = np.linspace(0, 1, 11)
    fld = SeparatedField("displacement", space, [s[None, :]], [Axis("s", s, "")], "m", ["x", "y", "z"])
    return ReducedModel("plate", P, tris, "tri3", [Axis("s", s, "")], {"displacement": fld}, tris, "shifted plate",
                        {"law": "linear_elastic"})


def render_on_background(tex: np.ndarray, bg: np.ndarray, T_wc: np.ndarray, shift: float,
                         z_bg: float = -0.03) -> tuple[np.ndarray, np.ndarray]:
    """The plate (z = 0, material shifted by ``shift`` along x) over a static textured plane at ``z_bg``: the
    image and its depth (metres along the optical axis), ray by ray."""
    v, u = np.mgrid[0 : CAM.height, 0 : CAM.width].astype(np.float64)
    d = np.stack([(u - CAM.cx) / CAM.fx, (v - CAM.cy) / CAM.fy, np.ones_like(u)], -1) @ T_wc[:3, :3].T
    o = T_wc[:3, 3]
    X = o + (-o[2] / d[..., 2])[..., None] * d
    Xb = o + ((z_bg - o[2]) / d[..., 2])[..., None] * d
    x = X[..., 0] - shift
    on = (x >= 0) & (x <= SIZE) & (X[..., 1] >= 0) & (X[..., 1] <= SIZE)
    texel = 0.25e-3

    def read(t: np.ndarray, px: np.ndarray, py: np.ndarray) -> np.ndarray:
        return cv2.remap(t, ((px + 0.05) / texel).astype(np.float32), ((py + 0.05) / texel).astype(np.float32),
                         cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)

    img = np.where(on, read(tex, x, X[..., 1]), read(bg, Xb[..., 0], Xb[..., 1]))
    hit = np.where(on[..., None], X, Xb)
    depth = ((hit - o) @ T_wc[:3, 2]).astype(np.float32)
    return np.clip(img, 0, 255).astype(np.uint8), depth


def shifted_over_background() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The shifted plate over its static background: the reference view (image, depth), a second view with the
    plate shifted by 0.6 of its range, and that view's camera pose given 1.5 mm off."""
    tex, bg = texture(1.0), texture(1.0, seed=5)
    T1 = pose(0.03)
    img0, depth0 = render_on_background(tex, bg, pose(), 0.0)
    img1, _ = render_on_background(tex, bg, T1, 0.6 * STRETCH)
    return img0, depth0, img1, G.make_T(t=[0.0015, 0.0, 0.0]) @ T1


@pytest.mark.parametrize("camera_first", [True, False])
def test_surroundings_tell_the_cameras_error_from_a_deformation_that_looks_rigid(camera_first):
    """The camera pose given is 1.5 mm off. On the object alone, that error and a deformation shaped like a rigid
    shift cannot be told apart and the load takes the blame; with the static surroundings in the fit (their
    depth from the reference view) the error is measured there and the load comes out right, whether the
    surroundings measure it first and alone (the default) or in one fit with the object."""
    model = shift_model()
    img0, depth0, img1, T_err = shifted_over_background()
    errs = {}
    for ring in (32.0, 0.0):
        al = _aligner(model, static_ring_px=ring, placement_measured=True, camera_first=camera_first)
        assert al.set_reference(img0, G.inv(pose()), depth0)
        assert bool(al.static) == (ring > 0)
        r = al.solve(img1, G.inv(T_err), np.array([0.5]), np.zeros(1), np.ones(1))
        errs[ring] = abs(r.mu[0] - 0.6)
        if ring:
            assert abs(r.debug["camera_trans_mm"] - 1.5) < 0.3, r.debug
            assert r.debug["rigid_trans_mm"] == 0.0  # the placement was measured: not refitted
    assert errs[32.0] < 0.03 and errs[0.0] > 0.2, errs


def test_surroundings_need_valid_depth(model):
    """No template of the surroundings where the depth is missing (NaN, zero) or the wrong size."""
    tex, bg = texture(1.0), texture(1.0, seed=5)
    img0, depth0 = render_on_background(tex, bg, pose(), 0.0)
    for bad in (np.full_like(depth0, np.nan), np.zeros_like(depth0), depth0[:100]):
        al = _aligner(model)
        assert al.set_reference(img0, G.inv(pose()), bad)
        assert not al.static


def test_the_profile_search_finds_the_cost_minimum_gauss_newton_stopped_short_of(model):
    """On a faint, noisy texture Gauss-Newton's image gradients are mostly noise and its steps come out short: the
    search of the cost over mu (``refine``) from a solution 10 % of the range off lands on the minimum, and the
    whole solve with it is closer to the truth than without."""
    tex = texture(0.06)
    al = _aligner(model)
    assert al.set_reference(render(tex, pose(), 0.0, 1.5, seed=1), G.inv(pose()))
    T = pose(0.03)
    img = render(tex, T, 0.6, 1.5, seed=2)
    r = al.solve(img, G.inv(T), np.array([0.5]), np.zeros(1), np.ones(1))
    assert abs(r.mu[0] - 0.6) < 0.03, r.mu
    # the search alone, from 0.1 off, with the nuisances of the solve
    pyr = pyramid(al.ideal(img), len(al.levels))
    L = al.levels[0]
    rows = al._visible_rows(L, r.mu, al.rigid + al.cam_corr, G.inv(T))
    from simreal_nodes.assimilation.dense import _Fit

    f = _Fit(np.array([0.7]), np.array([True]), al.rigid, al.cam_corr, al.photo, al.photo_s,
             (np.zeros(6), al._wide()), False, False)
    mu = al._refine(0, pyr[0], rows, f, G.inv(T), np.zeros(1), np.ones(1), r.rms)
    assert abs(mu[0] - 0.6) < 0.03 and abs(mu[0] - 0.6) < abs(0.7 - 0.6) / 3, mu
    c = [al._profile_cost(0, pyr[0], rows, f, np.array([x]), G.inv(T), r.rms) for x in (mu[0], 0.7, 0.5)]
    assert c[0] < c[1] and c[0] < c[2], c


def test_surroundings_that_disagree_with_the_object_about_the_camera_are_reported():
    """The check after the joint fit: the surroundings alone, refitted from the joint fit's camera correction,
    must not move it. Where they agree with the object (the camera 1.5 mm off, the template true) they move it by
    a few hundredths of a sigma; where the surroundings' template is 10 mm off (what a joint fit that traded the
    camera against the deformation looks like: a camera 5 degrees above the floor, docs/stability.md) the load is
    pushed to its bound and the gap exceeds the tracker's limit, which reports the estimate low-confidence."""
    model = shift_model()
    img0, depth0, img1, T_err = shifted_over_background()
    limit = DenseSettings().max_camera_gap
    for off in (0.0, 0.01):
        al = _aligner(model, static_ring_px=32.0, placement_measured=True)
        assert al.set_reference(img0, G.inv(pose()), depth0)
        for S in al.static:
            S.X[:, 0] += off
        r = al.solve(img1, G.inv(T_err), np.array([0.5]), np.zeros(1), np.ones(1))
        if off:
            assert abs(r.mu[0] - 0.6) > 0.2 and r.debug["camera_gap_sigma"] > limit, (r.mu, r.debug)
        else:
            assert abs(r.mu[0] - 0.6) < 0.03 and r.debug["camera_gap_sigma"] < 0.1 * limit, (r.mu, r.debug)
    off_check = _aligner(model, static_ring_px=32.0, placement_measured=True, camera_check=False)
    assert off_check.set_reference(img0, G.inv(pose()), depth0)
    assert np.isnan(off_check.solve(img1, G.inv(T_err), np.array([0.5]), np.zeros(1), np.ones(1))
                    .debug["camera_gap_sigma"])


def _dense_tracker_with_reference(model, tex):
    """A dense tracker that took its reference view of the plate at rest, and its aligner's own solve (a test
    wraps it to report what a failing fit would)."""
    tr = DeformableTracker(model, np.eye(4), {"s": {"mode": "tracked", "initial": 0.5}}, CAM,
                           TrackerConfig(measurements="dense"))
    tr.update(pose(), image_bgr=cv2.cvtColor(render(tex, pose(), 0.0), cv2.COLOR_GRAY2BGR))
    assert tr.dense is not None
    return tr, tr.dense.solve


def test_the_tracker_reports_a_fit_whose_camera_the_surroundings_dispute(model):
    """The tracker's side of the check: an estimate it would call OK is reported low-confidence, saying why, when
    the aligner's camera gap exceeds the limit; under it the estimate stays OK."""
    tex = texture(0.5)
    bgr = lambda img: cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)  # noqa: E731
    limit = DenseSettings().max_camera_gap
    for gap, state in ((0.5 * limit, EstimateState.OK), (2.0 * limit, EstimateState.LOW_CONFIDENCE)):
        tr, solve = _dense_tracker_with_reference(model, tex)

        def disputed(*a, solve=solve, gap=gap, **k):
            r = solve(*a, **k)
            r.debug["camera_gap_sigma"] = gap  # as the refit on the surroundings would report it
            return r

        tr.dense.solve = disputed
        e = tr.update(pose(0.02), image_bgr=bgr(render(tex, pose(0.02), 0.7)))
        assert e.state == state and abs(e.values[0] - 0.7) < 0.02, (e.state, e.reason)
        if state != EstimateState.OK:
            assert "surroundings alone" in e.reason, e.reason


def test_the_tracker_reports_a_fit_that_sees_the_texture_decorrelated(model):
    """A fit whose brightness gain fell under ``min_gain`` (a misaligned fit explains the image by its mean) is
    reported low-confidence, saying why; at a gain near one the estimate stays OK."""
    tex = texture(0.5)
    bgr = lambda img: cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)  # noqa: E731
    limit = DenseSettings().min_gain
    assert 0.0 < limit < 1.0
    for gain, state in ((None, EstimateState.OK), (0.5 * limit, EstimateState.LOW_CONFIDENCE),
                        (float("nan"), EstimateState.LOW_CONFIDENCE)):
        tr, solve = _dense_tracker_with_reference(model, tex)

        def decorrelated(*a, solve=solve, gain=gain, **k):
            r = solve(*a, **k)
            if gain is not None:
                r.debug["gain"] = gain  # as a fit that lost the texture would report it
            return r

        tr.dense.solve = decorrelated
        e = tr.update(pose(0.02), image_bgr=bgr(render(tex, pose(0.02), 0.7)))
        assert e.state == state and abs(e.values[0] - 0.7) < 0.02, (e.state, e.reason)
        if gain is None:
            assert abs(e.debug["gain"] - 1.0) < 0.1, e.debug
        else:
            assert "reference view's contrast" in e.reason, e.reason


def test_the_tracker_reports_a_load_the_images_hold_too_loosely(model):
    """A fit whose load parameter has a standard deviation over ``max_std_frac`` of its range (the normal equations
    of a view that barely sees it) is reported low-confidence, saying which parameter and how loosely; the estimate
    itself is the one the unflagged fit gives (the flag changes the state only)."""
    tex = texture(0.5)
    bgr = lambda img: cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)  # noqa: E731
    limit = DenseSettings().max_std_frac
    assert 0.0 < limit < 0.05  # under the 5 % past which a parameter already counts as barely observable
    values = {}
    for inflate, state in ((None, EstimateState.OK), (2.0, EstimateState.LOW_CONFIDENCE)):
        tr, solve = _dense_tracker_with_reference(model, tex)

        def loose(*a, solve=solve, inflate=inflate, **k):
            r = solve(*a, **k)
            if inflate is not None:  # as a view that barely sees s would report it: std = inflate x the limit
                r.cov_mu = np.array([[(inflate * limit * 1.0) ** 2]])
            return r

        tr.dense.solve = loose
        e = tr.update(pose(0.02), image_bgr=bgr(render(tex, pose(0.02), 0.7)))
        assert e.state == state, (e.state, e.reason)
        values[inflate] = e.values.copy()
        if inflate is None:
            assert np.sqrt(e.cov[0, 0]) < 0.2 * limit, e.cov  # a clear view holds s far tighter than the limit
        else:
            assert f"s loosely held by the images (std {200 * limit:.1f} % of its range" in e.reason, e.reason
    assert np.array_equal(values[None], values[2.0]) and abs(values[None][0] - 0.7) < 0.02


def test_loosely_held_reads_only_free_tracked_parameters():
    """Only a free parameter is judged, against its own range; a fixed or frozen one (std 0 or not estimated) and
    a missing covariance say nothing."""
    from simreal_nodes.assimilation.tracker import Estimate, loosely_held

    est = Estimate(["s_x", "s_y"], ["", ""], np.array([0.3, 0.1]), np.zeros(2, bool),
                   np.diag([0.004**2, 0.006**2]))
    ranges = np.array([0.5, 0.2])  # std: 0.8 % and 3 % of the ranges
    assert loosely_held(est, np.array([True, True]), ranges, 0.015) == \
        "s_y loosely held by the images (std 3.0 % of its range, at most 1.5 %)"
    assert loosely_held(est, np.array([True, False]), ranges, 0.015) == ""
    assert "s_x" in loosely_held(est, np.array([True, True]), ranges, 0.005)
    assert loosely_held(est, np.array([True, True]), ranges, 0.0) == ""
    est.cov = np.zeros(0)
    assert loosely_held(est, np.array([True, True]), ranges, 0.015) == ""


BEND = 0.01  # metres at the far edge for s = 1: u_z = BEND s (x / SIZE)^2 (a slope of 0.1 there)
LIGHT = np.array([-0.8, 0.0, 0.6])


def bend_model(n: int = 11) -> ReducedModel:
    """u(x; s) = s * (0, 0, BEND (x / SIZE)^2) on the square plate: it bends out of its plane, its normal turns."""
    return quadratic_model(2, BEND, "bent", "bent plate", n)


def render_lit(tex: np.ndarray, T_wc: np.ndarray, s: float, noise: float, seed: int) -> np.ndarray:
    """The plate bent by s (z = BEND s (x / SIZE)^2, material points moving vertically), its texture as albedo
    under ambient light and one distant light (a matte surface): each pixel's ray is intersected with the bent
    surface (fixed point on the ray parameter), its brightness is albedo (0.3 + 0.7 max(0, n.l))."""
    v, u = np.mgrid[0 : CAM.height, 0 : CAM.width].astype(np.float64)
    d = np.stack([(u - CAM.cx) / CAM.fx, (v - CAM.cy) / CAM.fy, np.ones_like(u)], -1) @ T_wc[:3, :3].T
    C = T_wc[:3, 3]
    lam = -C[2] / d[..., 2]
    for _ in range(30):
        X = C + lam[..., None] * d
        lam = (s * BEND * (np.clip(X[..., 0], 0, None) / SIZE) ** 2 - C[2]) / d[..., 2]
    X = C + lam[..., None] * d
    slope = 2 * s * BEND * np.clip(X[..., 0], 0, None) / SIZE**2
    n = np.stack([-slope, np.zeros_like(slope), np.ones_like(slope)], -1) / np.sqrt(1 + slope**2)[..., None]
    shade = 0.3 + 0.7 * np.clip(n @ LIGHT, 0, None)
    texel = 0.25e-3
    img = cv2.remap(tex, ((X[..., 0] + 0.05) / texel).astype(np.float32),
                    ((X[..., 1] + 0.05) / texel).astype(np.float32), cv2.INTER_LINEAR) * shade.astype(np.float32)
    img = img + np.random.default_rng(seed).normal(0, noise, img.shape).astype(np.float32)
    return np.clip(img, 0, 255).astype(np.uint8)


def test_a_bending_surfaces_change_of_shading_is_not_taken_for_a_deformation():
    """A plate bends out of its plane under a light from one side (seen from above, noise-free): its far half
    turns towards the light and brightens by up to 3 %, as much as a faint texture's contrast. With the affine
    brightness alone the fit is off by 5 % of the range; with the shading term it holds, and the term's g is the
    light's k_d l / (k_a + k_d n.l) along the plate (the direction the normals turn in)."""
    model = bend_model()
    tex = texture(0.05, seed=3)
    T0, T1 = pose(), pose(0.03)  # from above: the bending moves the image little, its shading changes
    errs = {}
    for shading in (True, False):
        al = _aligner(model, shading=shading)
        assert al.set_reference(render_lit(tex, T0, 0.0, 0.0, seed=1), G.inv(T0))
        r = al.solve(render_lit(tex, T1, 0.6, 0.0, seed=2), G.inv(T1), np.array([0.3]), np.zeros(1), np.ones(1))
        errs[shading] = abs(r.mu[0] - 0.6)
        if shading:
            g_true = 0.7 * LIGHT / (0.3 + 0.7 * LIGHT[2])
            assert abs(al.photo[2] - g_true[0]) < 0.1 * abs(g_true[0]), (al.photo, g_true)
            assert abs(al.photo[3]) < 0.05  # no turn about x: its component stays at the prior's zero
        else:
            assert len(al.photo) == 2
    assert errs[True] < 0.015 < 0.04 < errs[False], errs


def test_smooth_normals_follow_a_bending_surface():
    """The samples' normals of the bent plate against the analytic surface's, (-z'(x), 0, 1) normalised: within
    the slope's change over a triangle (the blend of the corners' normals is linear across it)."""
    from simreal_nodes.assimilation.dense import SmoothNormals

    model = bend_model(n=21)
    smp = sample_surface(model, 0.004, 100000)
    sn = SmoothNormals.build(model, smp.face, smp.weights, smp.x + [0, 0, 1.0], None)
    n = sn.at(np.array([1.0]))
    slope = 2 * BEND * smp.x[:, 0] / SIZE**2
    exact = np.c_[-slope, np.zeros_like(slope), np.ones_like(slope)] / np.sqrt(1 + slope**2)[:, None]
    assert np.all(n[:, 2] > 0)  # turned towards the side it was seen from
    assert np.max(np.linalg.norm(n - exact, axis=1)) < 0.003  # the slope changes by 0.01 across a cell
    assert np.max(np.linalg.norm(sn.at(None) - [0, 0, 1], axis=1)) < 1e-12


def test_smooth_normals_of_many_states_at_once_are_each_states_own():
    """corners_many (the search's candidates in one pass) against corners, one state at a time."""
    from simreal_nodes.assimilation.dense import SmoothNormals

    model = bend_model(n=11)
    smp = sample_surface(model, 0.01, 100000)
    sn = SmoothNormals.build(model, smp.face, smp.weights, smp.x + [0, 0, 1.0], None)
    mus = np.array([[0.0], [0.3], [1.0]])
    many = sn.corners_many(mus)
    assert many.shape == (3, *sn.corners(mus[0]).shape)
    for k, mu in enumerate(mus):
        np.testing.assert_allclose(many[k], sn.corners(mu), rtol=1e-12, atol=1e-14)
    assert np.abs(many[2] - many[0]).max() > 1e-3  # the bent state's normals did turn


def test_smooth_normals_do_not_smooth_across_an_edge_and_face_the_camera():
    """A cube whose triangles are wound either way (each face's two apart): samples on its top and on a side keep
    their own face's normal (the neighbouring faces meet at 90 degrees, beyond the crease angle), turned towards the
    camera that sees them, and no turn where nothing deforms."""
    from simreal_nodes.assimilation.dense import SmoothNormals

    V = np.array([[x, y, z] for x in (0.0, 1.0) for y in (0.0, 1.0) for z in (0.0, 1.0)])
    idx = {tuple(v): i for i, v in enumerate(V.astype(int).tolist())}
    quads = {"x0": [(0, 0, 0), (0, 1, 0), (0, 1, 1), (0, 0, 1)], "x1": [(1, 0, 0), (1, 1, 0), (1, 1, 1), (1, 0, 1)],
             "y0": [(0, 0, 0), (1, 0, 0), (1, 0, 1), (0, 0, 1)], "y1": [(0, 1, 0), (1, 1, 0), (1, 1, 1), (0, 1, 1)],
             "z0": [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], "z1": [(0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]}
    F = []
    for k, q in enumerate(quads.values()):
        a, b, c, d = (idx[p] for p in q)
        F += [[a, b, c], [a, d, c]] if k % 2 else [[a, c, b], [a, c, d]]  # each face's two triangles wound apart
    F = np.asarray(F, np.int64)
    space = np.zeros((1, 8, 3))
    s = np.linspace(0, 1, 3)
    axes = [Axis("s", s, "")]
    fld = SeparatedField("displacement", space, [np.ones((1, 3))], axes, "m", ["x", "y", "z"])
    cube = ReducedModel("cube", V, F, "tri3", axes, {"displacement": fld}, F, "cube", {"law": "linear_elastic"})
    top = [10, 11]  # the z1 face's two triangles
    side = [2, 3]  # x1
    face = np.array(top + side, np.int64)
    w = np.full((4, 3), 1.0 / 3.0)
    sn = SmoothNormals.build(cube, face, w, np.tile([3.0, 2.0, 4.0], (4, 1)), None)
    np.testing.assert_allclose(sn.at(None), [[0, 0, 1], [0, 0, 1], [1, 0, 0], [1, 0, 0]], atol=1e-12)
    np.testing.assert_allclose(sn.change(np.array([0.5])), 0.0, atol=1e-12)


def test_the_shading_fused_over_frames_holds_a_barely_bent_frame():
    """The light is the same in every frame: with ``shading_frames`` what the clearly bent frames measured of g
    becomes the weakly bent frames' prior. Noisy frames (pixel noise 1) of the side-lit faint plate, three bent
    far, then four bent a little: frame by frame g takes part of a small bending's signal (the weak frames are
    off by 5 % of the range on average; 7 % before the coarse search fitted each candidate's brightness); fused,
    it is held near the light's value and they are 3 % off."""
    model = bend_model()
    tex = texture(0.05, seed=3)
    T0 = pose()
    loads = [0.9, 0.8, 1.0, 0.15, 0.1, 0.2, 0.3]
    errs, g = {}, {}
    for frames in (0, 20):
        al = _aligner(model, shading_frames=frames)
        assert al.set_reference(render_lit(tex, T0, 0.0, 1.0, seed=1), G.inv(T0))
        e = []
        for k, s in enumerate(loads):
            T = pose(0.03 if k % 2 else 0.025)
            r = al.solve(render_lit(tex, T, s, 1.0, seed=10 + k), G.inv(T), np.array([0.5]), np.zeros(1), np.ones(1))
            e.append(abs(r.mu[0] - s))
            if frames and k == 0:  # a solve alone fuses nothing: the caller accepts a sound frame
                assert al.g_frame is not None and not al.g_info.any()
            al.accept_shading()
        errs[frames] = float(np.mean(e[3:]))
        g[frames] = np.linalg.solve(np.eye(3) + al.g_info, al.g_eta)  # the prior the next frame would get
    g_true = 0.7 * LIGHT / (0.3 + 0.7 * LIGHT[2])
    assert errs[20] < 0.035 and errs[0] > 1.3 * errs[20], errs
    assert abs(g[20][0] - g_true[0]) < 0.15 * abs(g_true[0]), (g[20], g_true)


def test_the_tracker_fuses_the_shading_of_sound_frames_only():
    """A sound frame's measurement of g enters the next frames' prior; a flagged frame (pure noise) measures some g
    as well, which must not (the tracker calls accept_shading on OK frames only)."""
    model = bend_model()
    tex = texture(0.05, seed=3)
    bgr = lambda img: cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)  # noqa: E731
    # this faint texture holds s to 1.3 % of its range, which max_std_frac would flag (after the shading is fused):
    # off here, so that the state says which frames the shading came from
    tr = DeformableTracker(model, np.eye(4), {"s": {"mode": "tracked", "initial": 0.3}}, CAM,
                           TrackerConfig(measurements="dense", dense=DenseSettings(max_std_frac=0.0)))
    tr.update(pose(), image_bgr=bgr(render_lit(tex, pose(), 0.0, 0.0, seed=1)))
    assert tr.dense is not None and tr.dense.s.shading_frames > 0  # on by default
    e = tr.update(pose(0.03), image_bgr=bgr(render_lit(tex, pose(0.03), 0.6, 0.0, seed=2)))
    assert e.state == EstimateState.OK, e.reason
    assert tr.dense.g_info[0, 0] > 0
    fused = tr.dense.g_info.copy(), tr.dense.g_eta.copy()
    noise = np.random.default_rng(0).integers(0, 255, (CAM.height, CAM.width, 3)).astype(np.uint8)
    e = tr.update(pose(0.03), image_bgr=noise)
    assert e.state == EstimateState.LOW_CONFIDENCE
    assert tr.dense.g_frame is not None and tr.dense.g_frame[0].any()  # it measured something ...
    assert np.array_equal(tr.dense.g_info, fused[0]) and np.array_equal(tr.dense.g_eta, fused[1])  # ... not fused


@pytest.mark.parametrize("g", [(-3.0, 0.0, -3.0), (10.0, 0.0, 0.0)])
def test_the_coarse_search_compares_each_candidate_at_its_own_brightness(g):
    """A frame after a misaligned one starts from a brightness gain near zero and a spurious shading: compared at
    that brightness, the coarse search's candidates differ by the shading's change with mu rather than by how the
    texture lines up, and it picks a bound; each at the brightness fitted to it (``grid_brightness`` "always", and
    "auto" since the gain is under ``min_gain``), it lands next to the truth and restores the gain."""
    from simreal_nodes.assimilation.dense import N_RIGID, _Fit

    m = bend_model()
    tex = texture(0.3)
    T0, T1 = pose(), pose(0.02)
    picked = {}
    for mode in ("always", "auto", "never"):
        al = DenseAligner(m, np.eye(4), CAM, None, DenseSettings(grid_brightness=mode))
        assert al.set_reference(render_lit(tex, T0, 0.0, 1.0, 0), G.inv(T0))
        pyr = pyramid(al.ideal(render_lit(tex, T1, 0.8, 1.0, 1)), len(al.levels))
        f = _Fit(np.array([0.1]), np.array([True]), np.zeros(N_RIGID), np.zeros(N_RIGID), np.r_[0.1, 110.0, g],
                 np.array([1.0, 0.0]), (np.zeros(N_RIGID), al._wide()), False, False)
        al._grid_start(pyr, f, G.inv(T1), np.zeros(1), np.ones(1))
        assert f.mu is not None
        picked[mode] = (float(f.mu[0]), float(f.photo[0]))
    for mode in ("always", "auto"):
        assert abs(picked[mode][0] - 0.8) < 0.05 and abs(picked[mode][1] - 1.0) < 0.05, picked
    assert abs(picked["never"][0] - 0.8) > 0.3, picked  # what the search did before stop 48: the test can tell


def test_the_coarse_search_reports_how_far_another_basin_is_behind(model):
    """``grid_margin``: the cheapest coarse candidate more than a quarter of a range from the winner, its cost above
    the winner's as a share of it: well apart where the texture pins the stretch, near zero where the texture is
    too faint to tell one place from another (a diagnostic: ``python -m benchmarks.flag_calibration --margin``)."""
    T0, T1 = pose(), pose(0.02)
    margin = {}
    for contrast in (0.3, 0.005):
        tex = texture(contrast)
        al = _aligner(model)
        assert al.set_reference(render(tex, T0, 0.0, 4.0, 0), G.inv(T0))
        res = al.solve(render(tex, T1, 0.7, 4.0, 1), G.inv(T1), np.array([0.2]), np.zeros(1), np.ones(1))
        margin[contrast] = res.debug["grid_margin"]
    assert margin[0.3] > 0.1 and 0 <= margin[0.005] < 0.03, margin


TWO_A1, TWO_A2, TWO_WAVE = 0.004, 0.0008, SIZE / 20  # the two-basin plate below: metres, metres, wavelength


def _two_basin_u(x: np.ndarray, s: float) -> np.ndarray:
    """u_x of the two-basin plate: a smooth stretch whose size 4 s (1 - s) is the same for s and 1 - s, plus a
    ripple of 10 mm wavelength growing with s (under 1 px, finer than the coarsest pyramid level resolves)."""
    return (TWO_A1 * 4 * s * (1 - s) * (np.clip(x, 0, None) / SIZE) ** 2
            + TWO_A2 * s * np.sin(2 * np.pi * x / TWO_WAVE))


def two_basin_model(n: int = 101, ripple: bool = True) -> ReducedModel:
    """:func:`_two_basin_u` as a two-mode separated model on the square plate (2 mm nodes: 5 per ripple); without
    the ripple, its stretch mode alone (s and 1 - s the same displacement)."""
    P, tris = plate_points(n, SIZE)
    space = np.zeros((2, len(P), 3))
    space[0, :, 0] = TWO_A1 * (P[:, 0] / SIZE) ** 2
    space[1, :, 0] = TWO_A2 * np.sin(2 * np.pi * P[:, 0] / TWO_WAVE)
    s = np.linspace(0, 1, 101)
    axes = [Axis("s", s, "")]
    k = 2 if ripple else 1
    fld = SeparatedField("displacement", space[:k], [np.stack([4 * s * (1 - s), s])[:k]], axes, "m",
                         ["x", "y", "z"])
    return ReducedModel("two_basin", P, tris, "tri3", axes, {"displacement": fld}, tris, "two basins",
                        {"law": "linear_elastic"})


def render_two_basin(tex: np.ndarray, T_wc: np.ndarray, s: float, noise: float, seed: int) -> np.ndarray:
    """The two-basin plate deformed by s (:func:`render`, its ripple resolved by more fixed-point steps)."""
    return render(tex, T_wc, s, noise, seed, u_x=_two_basin_u, iterations=40)


def test_the_other_basin_is_fitted_at_full_detail_where_the_coarse_search_cannot_tell():
    """``basin_check``: s and 1 - s stretch the plate alike and differ by a ripple the coarsest level cannot
    resolve, so the coarse search keeps the warm start's basin and Gauss-Newton only polishes it (what development
    seed 9's load over the wrong support did). Fitted from the runner-up too, the full-resolution cost picks the
    truth; the other basin costs more than its winner by well over the trigger."""
    m = two_basin_model()
    tex = texture(0.3)
    T0, T1 = pose(), pose(0.02)
    for truth, start in ((0.8, 0.2), (0.75, 0.25)):
        out = {}
        for check in (0.0, DenseSettings().basin_check):
            al = DenseAligner(m, np.eye(4), CAM, None, DenseSettings(basin_check=check))
            assert al.set_reference(render_two_basin(tex, T0, 0.0, 1.0, 0), G.inv(T0))
            res = al.solve(render_two_basin(tex, T1, truth, 1.0, 1), G.inv(T1), np.array([start]), np.zeros(1),
                           np.ones(1))
            out[check] = res
        off, on = out[0.0], out[DenseSettings().basin_check]
        assert abs(off.mu[0] - truth) > 0.3 and off.debug["basin_switched"] == 0  # the test can tell
        assert abs(on.mu[0] - truth) < 0.02 and on.debug["basin_switched"] == 1, (truth, on.mu)
        assert on.debug["grid_margin"] < DenseSettings().basin_check and on.debug["basin_gap"] > 0.5
    # where the coarse search already tells the basins apart (its runner-up far behind), no second fit
    al = DenseAligner(m, np.eye(4), CAM, None, DenseSettings())
    assert al.set_reference(render_two_basin(tex, T0, 0.0, 1.0, 0), G.inv(T0))
    res = al.solve(render_two_basin(tex, T1, 0.2, 1.0, 1), G.inv(T1), np.array([0.8]), np.zeros(1), np.ones(1))
    assert abs(res.mu[0] - 0.2) < 0.02 and res.debug["grid_margin"] > DenseSettings().basin_check
    assert np.isnan(res.debug["basin_gap"]) and res.debug["basin_switched"] == 0


def test_the_last_frames_basin_is_fitted_where_the_coarse_search_leads_both_fits_astray(monkeypatch):
    """``basin_warm``: where the coarse search's winner and its runner-up both end in one wrong basin (forced here:
    the search puts the winner at 0.2 and the runner-up at 0.05, whose fit falls to 0.2 as well), the warm start
    (the last frame's estimate, 0.8 and right) is fitted too and, cheaper at full resolution, kept."""
    m = two_basin_model()
    tex = texture(0.3)
    T0, T1 = pose(), pose(0.02)

    def astray(self, pyr, f, T_cw, lo, hi):
        f.mu = np.array([0.2])
        self.grid_margin, self.grid_runner_up = 0.01, np.array([0.05])

    monkeypatch.setattr(DenseAligner, "_grid_start", astray)
    out = {}
    for warm in (False, True):
        al = DenseAligner(m, np.eye(4), CAM, None, DenseSettings(basin_warm=warm))
        assert al.set_reference(render_two_basin(tex, T0, 0.0, 1.0, 0), G.inv(T0))
        out[warm] = al.solve(render_two_basin(tex, T1, 0.8, 1.0, 1), G.inv(T1), np.array([0.8]), np.zeros(1),
                             np.ones(1))
    assert abs(out[False].mu[0] - 0.2) < 0.05 and out[False].debug["basin_warm"] == 0, out[False].mu  # can tell
    on = out[True]
    assert abs(on.mu[0] - 0.8) < 0.02 and on.debug["basin_warm"] == 1 and on.debug["basin_switched"] == 2, on.mu
    assert on.debug["basin_gap"] > 0.5 and abs(on.debug["basin_other_0"] - 0.2) < 0.05, on.debug


def test_a_fit_whose_two_basins_explain_the_image_alike_is_flagged():
    """``max_ambiguity_gap``: without the ripple, s and 1 - s stretch the plate identically, so the other basin's fit
    ends at 1 - s at the same cost: the tracker's :func:`ambiguity` says so (naming the other load); with the
    ripple the full-resolution cost tells them apart and nothing is flagged."""
    from simreal_nodes.assimilation.tracker import ambiguity

    tex = texture(0.3)
    T0, T1 = pose(), pose(0.02)
    why = {}
    for ripple in (False, True):
        m = two_basin_model(ripple=ripple)
        u_x = _two_basin_u if ripple else (lambda x, s: TWO_A1 * 4 * s * (1 - s) * (np.clip(x, 0, None) / SIZE) ** 2)
        al = DenseAligner(m, np.eye(4), CAM, None, DenseSettings())
        assert al.set_reference(render(tex, T0, 0.0, 1.0, 0, u_x=u_x, iterations=40), G.inv(T0))
        res = al.solve(render(tex, T1, 0.8, 1.0, 1, u_x=u_x, iterations=40), G.inv(T1), np.array([0.2]),
                       np.zeros(1), np.ones(1))
        why[ripple] = ambiguity(res.debug, DenseSettings(), ["s"])
        if not ripple:  # either basin may be kept; the other fit ended at the mirror load
            assert min(abs(res.mu[0] - 0.8), abs(res.mu[0] - 0.2)) < 0.02, res.mu
            assert abs(res.debug["basin_other_0"] - (1 - res.mu[0])) < 0.03, res.debug
            assert res.debug["basin_apart"] > 0.5 and abs(res.debug["basin_gap"]) < DenseSettings().max_ambiguity_gap
    assert why[False].startswith("another load (s=") and why[True] == "", why
    # a second fit that fell back into the winner's basin is no ambiguity, however close its cost
    assert ambiguity({"basin_gap": 0.0, "basin_apart": 0.01, "basin_other_0": 0.21}, DenseSettings(), ["s"]) == ""
    assert ambiguity({"basin_gap": 0.0, "basin_apart": 0.6, "basin_other_0": 0.8},
                     DenseSettings(max_ambiguity_gap=0.0), ["s"]) == ""  # 0: no flag


def test_the_coarse_search_keeps_a_sound_brightness_when_auto():
    """"auto": a warm start whose gain is at least ``min_gain`` is trusted, the candidates compared at its
    brightness (what "never" does, its brightness passed on unchanged); "always" refits it."""
    from simreal_nodes.assimilation.dense import N_RIGID, _Fit

    m = bend_model()
    tex = texture(0.3)
    T0, T1 = pose(), pose(0.02)
    start = np.r_[0.9, 5.0, 0.0, 0.0, 0.0]
    out = {}
    for mode in ("always", "auto", "never"):
        al = DenseAligner(m, np.eye(4), CAM, None, DenseSettings(grid_brightness=mode))
        assert al.set_reference(render_lit(tex, T0, 0.0, 1.0, 0), G.inv(T0))
        pyr = pyramid(al.ideal(render_lit(tex, T1, 0.8, 1.0, 1)), len(al.levels))
        f = _Fit(np.array([0.1]), np.array([True]), np.zeros(N_RIGID), np.zeros(N_RIGID), start.copy(),
                 np.array([1.0, 0.0]), (np.zeros(N_RIGID), al._wide()), False, False)
        al._grid_start(pyr, f, G.inv(T1), np.zeros(1), np.ones(1))
        assert f.mu is not None
        out[mode] = (float(f.mu[0]), f.photo.copy())
    assert np.array_equal(out["auto"][1], start) and np.array_equal(out["never"][1], start)
    assert out["auto"][0] == out["never"][0]
    assert not np.allclose(out["always"][1], start)  # the fitted brightness: the test tells the modes apart
    with pytest.raises(ValueError, match="grid_brightness"):
        DenseSettings(grid_brightness="sometimes")


def _template_error(al: DenseAligner, clean: DenseAligner) -> float:
    """RMS difference of the finest level's template intensities from another template's (the same samples)."""
    a, b = al.levels[0].values, clean.levels[0].values
    assert a.shape == b.shape
    return float(np.sqrt(np.mean((a - b) ** 2)))


def _rest_views(model, tex: np.ndarray, noise: float, frames: int, views: int = 12) -> tuple[DenseAligner, list]:
    """An aligner whose template is refined with ``views`` views of the plate at rest (``template_frames``
    ``frames``): a camera that moves 4 mm a view, its pose given 1 mm off, the images brighter and of more
    contrast than the reference view. Returns the aligner and what each refinement averaged."""
    al = _aligner(model, template_frames=frames)
    assert al.set_reference(render(tex, pose(), 0.0, noise, seed=1), G.inv(pose()))
    done = []
    for k in range(views):
        T = pose(0.004 * (k + 1))
        img = np.clip(1.1 * render(tex, T, 0.0, noise, seed=10 + k).astype(np.float32) - 8.0, 0, 255).astype(np.uint8)
        T_given = G.make_T(t=[0.001, 0.0, 0.0]) @ T
        al.solve(img, G.inv(T_given), np.array([0.0]), np.zeros(1), np.ones(1))
        done.append(al.refine_template(img, G.inv(T_given)))
    return al, done


def test_views_at_rest_average_the_templates_noise_away(model):
    """The reference view's noise is in every comparison. Views judged at rest averaged into the template (each
    aligned by the fit, brought to the template's brightness): the template's noise, measured against the same
    views rendered without noise, falls with the views averaged, to under half with 9 (1 / sqrt(9) = 0.33 where
    nothing else differs); the averaging stops at ``template_frames`` views; with 0 the template is the reference
    view's."""
    tex = texture(0.1)
    errs = {}
    for frames in (0, 4, 9):
        al, done = _rest_views(model, tex, 2.0, frames)
        clean, _ = _rest_views(model, tex, 0.0, frames)
        assert [d > 0 for d in done] == [k < frames - 1 for k in range(len(done))], done
        assert al.template_views == max(frames, 1)
        errs[frames] = _template_error(al, clean)
    assert errs[0] > 1.0  # the noise of one view, 2 levels, as the samples' bilinear reading sees it
    assert errs[9] < errs[4] < 0.7 * errs[0] and errs[9] < 0.5 * errs[0], errs


def test_a_template_taken_in_a_deformed_state_is_not_averaged(model):
    """The zero-displacement fit does not describe a template taken with the object deformed (its state measured
    from depth): such a template stays the reference view's."""
    tex = texture(0.5)
    al = _aligner(model, template_frames=9)
    assert al.set_reference(render(tex, pose(), 0.4, 1.0, seed=1), G.inv(pose()), mu_ref=np.array([0.4]))
    before = al.levels[0].values.copy()
    img = render(tex, pose(0.01), 0.4, 1.0, seed=2)
    al.solve(img, G.inv(pose(0.01)), np.array([0.4]), np.zeros(1), np.ones(1))
    assert al.refine_template(img, G.inv(pose(0.01))) == 0
    assert np.array_equal(al.levels[0].values, before)


def test_the_tracker_averages_views_at_rest_into_the_template_until_a_deformation(model):
    """The tracker refines its template on the frames it judges at rest before any deformation, and stops at the
    first deformed one."""
    tex = texture(0.5)
    bgr = lambda img: cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)  # noqa: E731
    tr = DeformableTracker(model, np.eye(4), {"s": {"mode": "tracked", "initial": 0.5}}, CAM,
                           TrackerConfig(measurements="dense", dense=DenseSettings(template_frames=20)))
    tr.update(pose(), image_bgr=bgr(render(tex, pose(), 0.0, 1.0, seed=1)))
    assert tr.dense is not None and tr.dense.template_views == 1
    for k, s in enumerate((0.0, 0.0, 0.0, 0.7, 0.0)):
        e = tr.update(pose(0.005 * (k + 1)), image_bgr=bgr(render(tex, pose(0.005 * (k + 1)), s, 1.0, seed=2 + k)))
        assert (e.debug.get("template_samples", 0.0) > 0) == (s == 0.0 and k < 3), (k, e.debug, e.reason)
    assert tr.dense.template_views == 4
    assert abs(e.values[0] - 0.0) < 0.05 or e.state != EstimateState.OK


@pytest.mark.parametrize("small", [0.0, 0.06])
def test_a_load_too_small_to_be_a_deformation_closes_the_templates_averaging(model, small):
    """A load too small to pass as a deformation (s = 0.06: the fit moves the image 0.16 px, the tracker reports
    no measurable deformation) still bends the object: its view would put the bend into the template. The averaging
    closes for good there (:attr:`DenseSettings.template_motion_px`), even for the views at rest after it; without
    that load every view joins."""
    tex = texture(0.5)
    bgr = lambda img: cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)  # noqa: E731
    tr = DeformableTracker(model, np.eye(4), {"s": {"mode": "tracked", "initial": 0.5}}, CAM,
                           TrackerConfig(measurements="dense", dense=DenseSettings(template_frames=20)))
    tr.update(pose(), image_bgr=bgr(render(tex, pose(), 0.0, 1.0, seed=1)))
    joined = []
    for k, s in enumerate((0.0, 0.0, small, 0.0, 0.0)):
        e = tr.update(pose(0.005 * (k + 1)), image_bgr=bgr(render(tex, pose(0.005 * (k + 1)), s, 1.0, seed=2 + k)))
        assert "no measurable deformation" in e.reason, e.reason
        joined.append(e.debug.get("template_samples", 0.0) > 0)
    assert tr.dense is not None
    if small:
        assert joined == [True, True, False, False, False] and tr.dense.template_closed
        assert tr.dense.template_views == 3
    else:
        assert all(joined) and not tr.dense.template_closed and tr.dense.template_views == 6


def test_the_chained_jacobian_matches_finite_differences_of_the_projection(model):
    """The solve's rows d(intensity)/d(mu, omega, t) = g^T d(pixel)/d(.) (built from (n, 3) products, never the
    pixel Jacobian itself) against central differences of the pixels the cost evaluates (the one-affine-map path),
    for the object's samples (with a rigid offset and a load) and the surroundings' points."""
    al = _aligner(model)
    tex = texture(1.0)
    assert al.set_reference(render(tex, pose(), 0.0), G.inv(pose()))
    T_cw = G.inv(pose(0.02))
    L = al.levels[0]
    rows = np.arange(len(L.x))
    mu = np.array([0.4])
    rigid = np.r_[0.0, 0.0, 0.0, 0.002, -0.001, 0.003]
    uv, chain = al._geometry(L, rows, mu, rigid, T_cw, jac=True)
    uv_plain, _ = al._geometry(L, rows, mu, rigid, T_cw, jac=False)
    np.testing.assert_allclose(uv, uv_plain, atol=1e-9)  # the two paths put the samples at the same pixels
    g = np.random.default_rng(0).normal(size=(len(rows), 2))
    sel = np.ones(len(rows), bool)
    sel[::7] = False
    J = chain(g[sel], sel)
    assert J.shape == (sel.sum(), 7)
    h = 1e-6

    def numeric(k: int) -> np.ndarray:
        m, r = mu.copy(), rigid.copy()
        (m if k == 0 else r)[max(k - 1, 0)] += h
        up, _ = al._geometry(L, rows, m, r, T_cw, jac=False)
        (m if k == 0 else r)[max(k - 1, 0)] -= 2 * h
        dn, _ = al._geometry(L, rows, m, r, T_cw, jac=False)
        return np.sum(g * (up - dn) / (2 * h), axis=1)[sel]

    for k in range(7):  # omega at zero: its finite difference is the left increment's derivative
        np.testing.assert_allclose(J[:, k], numeric(k), rtol=1e-5, atol=1e-6 * np.abs(J[:, k]).max())
    X = np.random.default_rng(1).uniform([0.0, 0.0, -0.01], [0.2, 0.2, 0.0], (50, 3))  # surroundings, map frame
    uv_s, chain_s = al._rigid_project(X, rigid, T_cw, jac=True)
    np.testing.assert_allclose(uv_s, al._rigid_project(X, rigid, T_cw, jac=False)[0], atol=1e-9)
    gs = g[:50]
    Js = chain_s(gs, np.ones(50, bool))
    for k in range(6):
        r1, r2 = rigid.copy(), rigid.copy()
        r1[k] += h
        r2[k] -= h
        d = (al._rigid_project(X, r1, T_cw, jac=False)[0] - al._rigid_project(X, r2, T_cw, jac=False)[0]) / (2 * h)
        np.testing.assert_allclose(Js[:, k], np.sum(gs * d, axis=1), rtol=1e-5, atol=1e-6 * np.abs(Js[:, k]).max())


def test_bilinear_reads_more_samples_than_an_opencv_map_holds():
    """cv2.remap refuses maps of 2^15 rows or more; a batch of candidates' samples is longer than that."""
    from simreal_nodes.assimilation.dense import bilinear

    img = texture(1.0)[:200, :300].copy()
    uv = np.random.default_rng(0).uniform([-2, -2], [302, 202], (70000, 2))
    v = bilinear(img, uv)
    assert v.shape == (70000,)
    np.testing.assert_array_equal(v[40000:40100], bilinear(img, uv[40000:40100]))
    inside = (uv[:, 0] >= 0) & (uv[:, 1] >= 0) & (uv[:, 0] <= 298) & (uv[:, 1] <= 198)
    assert np.all(np.isfinite(v[inside])) and np.all(np.isnan(v[(uv[:, 0] < -1.5) | (uv[:, 1] > 200.5)]))


def test_candidates_costed_together_cost_what_each_costs_alone():
    """The search's batched costs (the refinement's profile, the coarse search's residuals) against the one-by-one
    evaluations they replace, on a bending plate whose normals turn (the shading's columns differ per candidate)."""
    from simreal_nodes.assimilation.dense import _Fit

    al = DenseAligner(bend_model(), np.eye(4), CAM, None, DenseSettings())
    tex = texture(0.5)
    assert al.set_reference(render_lit(tex, pose(), 0.0, 0.0, 1), G.inv(pose()))
    T = pose(0.02)
    img = np.asarray(render_lit(tex, T, 0.6, 1.0, 3), np.float32)
    T_cw = G.inv(T)
    f = _Fit(np.array([0.5]), np.array([True]), np.zeros(6), np.zeros(6), np.r_[1.02, -1.5, 0.3, -0.2, 0.1],
             np.array([1.0, 0.0]), (np.zeros(6), np.ones(6)), False, False)
    assert al.n_photo == 5
    rows = al._visible_rows(al.levels[0], f.mu, f.total, T_cw)
    mus = np.array([[0.0], [0.35], [0.6], [0.61], [1.0]])
    many = al._profile_many(0, img, rows, f, mus, T_cw, 2.0)
    alone = [al._profile_cost(0, img, rows, f, mu, T_cw, 2.0) for mu in mus]
    np.testing.assert_allclose(many, alone, rtol=1e-10)
    assert int(np.argmin(many)) in (2, 3)  # the load is at 0.6
    lvl = len(al.levels) - 1
    rows_c = al._visible_rows(al.levels[lvl], f.mu, f.total, T_cw)
    r_many = al._residuals_many(lvl, img, rows_c, f, mus, T_cw)
    for k, mu in enumerate(mus):
        t = f.copy()
        t.mu = mu.copy()
        np.testing.assert_allclose(r_many[k], al._residuals(lvl, img, rows_c, t, T_cw), rtol=1e-10, atol=1e-9)
    assert al._profile_many(0, img, rows, f, np.zeros((0, 1)), T_cw, 2.0) == []  # no candidates: no costs
    assert al.levels[0].normals.corners_many(np.zeros((0, 1))).shape[0] == 0


def test_a_refinement_without_width_keeps_the_gauss_newton_solution(model):
    """refine_span 0: every grid point is the solution itself, no candidate is left to cost."""
    tex = texture(1.0)
    al = _aligner(model, refine_span=0.0)
    assert al.set_reference(render(tex, pose(), 0.0, 1.0, seed=1), G.inv(pose()))
    T = pose(0.03)
    r = al.solve(render(tex, T, 0.6, 1.0, seed=2), G.inv(T), np.array([0.5]), np.zeros(1), np.ones(1))
    assert abs(r.mu[0] - 0.6) < 0.05


def test_the_robust_scales_median_is_numpys():
    """``dense._median`` (the robust scale's, without ``np.median``'s overhead): the same value to the bit on odd,
    even and tiny lengths, NaN where a sample is NaN (as numpy), NaN for no samples."""
    from simreal_nodes.assimilation.dense import _median

    rng = np.random.default_rng(0)
    for n in (1, 2, 3, 4, 471, 1800, 7001):
        a = rng.normal(size=n) * 10 ** rng.uniform(-3, 3)
        assert _median(a) == float(np.median(a)), n
        a[n // 2] = np.nan
        assert np.isnan(_median(a)), n
    assert np.isnan(_median(np.zeros(0)))


def test_kept_gathers_and_priors_follow_the_template_and_the_shading(model):
    """What a solve keeps between its iterations (``_take``'s gathers of the samples, ``_g_prior``, ``_wide``)
    is the template's and the shading's as they are now: a view averaged into the template (``_average_in``, in
    place), a frame's shading accepted or a setting changed is seen at once, and what is kept cannot be written to."""
    al = _aligner(bend_model(), shading_frames=20)
    T0 = pose()
    tex = texture(0.5, seed=3)
    assert al.set_reference(render(tex, T0, 0.0), G.inv(T0))
    L = al.levels[0]
    rows = np.arange(0, len(L.values), 2)
    before = al._take(L.values, rows)
    assert al._take(L.values, rows) is before and not before.flags.writeable
    seen = al._take(L.values, rows) + 4.0
    predicted = seen + np.random.default_rng(0).normal(0, 1, len(rows))
    assert al._average_in(L.values, np.ones(len(L.values)), rows, seen, predicted, np.array([1.0, 0.0])) > 100
    assert np.array_equal(al._take(L.values, rows), L.values[rows]) and not np.array_equal(before, L.values[rows])
    P0, m0 = al._g_prior()
    assert not P0.flags.writeable and not m0.flags.writeable and not m0.any()
    al.g_frame = (np.eye(3), np.ones(3))
    al.accept_shading()
    P1, m1 = al._g_prior()
    assert np.array_equal(P1, P0 + np.eye(3)) and np.allclose(m1, np.linalg.solve(P1, np.ones(3)))
    al.s.prior_rot_rad = 0.02
    assert al._wide()[0] == 0.02 and not al._wide().flags.writeable


def test_no_reference_where_the_lens_leaves_no_pixel_of_the_object(model):
    """A CameraInfo's distortion so strong that undistorting sends the object's part of the view outside the image
    (the graph fuzz's hostile CameraInfo, docs/status.md stop 121): no template, not an exception. The fuzz's other
    lens, tangential terms of 1e3, no longer gets this far: since stop 126 its CameraInfo is refused (its coefficients
    do not invert over the image, ``CameraModel.validate``); k1 = 1e6 inverts and reaches the aligner."""
    from simreal_nodes.errors import CameraInfoError

    with pytest.raises(CameraInfoError, match="do not invert"):
        CameraModel.from_intrinsics(320, 240, 300.0, 300.0, 159.5, 119.5, D=[0, 0, 1e3, 0, 0])
    cam = CameraModel.from_intrinsics(320, 240, 300.0, 300.0, 159.5, 119.5, D=[1e6, 0, 0, 0, 0])
    al = DenseAligner(model, np.eye(4), cam, None, DenseSettings())
    assert not al.set_reference(render(texture(1.0), pose(), 0.0), G.inv(pose()))
    assert not al.has_template
