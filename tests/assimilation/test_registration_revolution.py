"""Registration of a body of revolution (the joint boot's bellows): its turn about its own axis is not in the depth, so
a fit turned any way about that axis is the same fit, only the axis's tilt from the guess tells another basin, and
the fit keeps the guess's turn; a guess that sinks the object under the plane it stands on is lifted onto it. On a
depth cloud made from the boot model's own surface (the faces three cameras see, 0.5 mm noise), a floor under it and
two boxes of clutter beside it: no rendering, so the tests run in seconds."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from simreal_nodes import geometry as G
from simreal_nodes.assimilation.objects import ObjectTrackers
from simreal_nodes.assimilation.registration import (
    Registration,
    RegistrationConfig,
    _n_samples,
    icp_point_to_plane,
    lifted_onto,
    register_loaded,
    register_rgbd,
    revolves_about_z,
    sample_surface,
    turned_about_axis,
    turned_like,
)
from simreal_nodes.camera import CameraModel
from simreal_nodes.rom.build import cached_model
from simreal_nodes.rom.model_file import load_model
from simreal_nodes.scene.schema import validate_scene

# the boot's axis frame in the map: turned about its axis and tilted as a camera frame would see a table
# the boot scene file's polish (anchor.polish_mm: 4): the fine stage alone can stop a pleat away on the bellows
CFG = RegistrationConfig(polish=0.004)
T_TRUE = G.make_T(G.rot_axis("x", np.deg2rad(-110.0)) @ G.rot_axis("z", np.deg2rad(35.0)), [0.05, 0.12, 0.65])


@pytest.fixture(scope="module")
def boot():
    return load_model(cached_model("joint_boot"), fields=["displacement"])


@pytest.fixture(scope="module")
def beam():
    return load_model(cached_model("aluminium_beam"), fields=["displacement"])


def _faces(rng, centre, size, n: int) -> np.ndarray:
    """``n`` points on the faces of a box (object frame)."""
    u = rng.uniform(-0.5, 0.5, (n, 3))
    k = rng.integers(0, 3, n)
    u[np.arange(n), k] = rng.choice([-0.5, 0.5], n)
    return u * np.asarray(size) + np.asarray(centre)


def _cloud(model, floor_z: float, V: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(points in the map, camera centres in the map): the model surface (its nodes at ``V``, object frame, where
    given: a deformed shape) facing three cameras about 0.6 m away, a floor at height ``floor_z`` of the object
    frame around it and two boxes of clutter a few centimetres from it (which a fit of the bellows alone may turn
    towards), all with 0.5 mm noise."""
    rng = np.random.default_rng(3)
    c = model.points.mean(axis=0)
    cams = np.array([c + 0.6 * np.array([np.cos(a), np.sin(a), 0.7]) for a in np.deg2rad([-20.0, 0.0, 20.0])])
    S, N = sample_surface(model.points if V is None else V, model.surface, 40000, seed=1)
    seen = np.zeros(len(S), bool)
    for cam in cams:
        seen |= np.einsum("ij,ij->i", N, cam - S) > 0
    xy = rng.uniform(-0.25, 0.25, (20000, 2))
    xy = xy[np.linalg.norm(xy - c[:2], axis=1) > 0.06]  # the floor around the object's footprint
    rng = np.random.default_rng(5)
    clutter = np.vstack([_faces(rng, [0.11, 0.03, 0.03], [0.04, 0.05, 0.14], 3000),
                         _faces(rng, [-0.06, 0.1, 0.02], [0.05, 0.04, 0.1], 3000)])
    P = np.vstack([S[seen], np.c_[xy, np.full(len(xy), floor_z)], clutter])
    return G.transform(T_TRUE, P + rng.normal(0.0, 0.0005, P.shape)), G.transform(T_TRUE, cams)


def _error(T):
    D = G.inv(T_TRUE) @ T
    return 1e3 * np.linalg.norm(D[:3, 3]), np.rad2deg(np.arccos(np.clip(D[2, 2], -1.0, 1.0)))


def test_the_boot_is_a_body_of_revolution_a_beam_is_not(boot, beam):
    for model, expected in ((boot, True), (beam, False)):
        S, N = sample_surface(model.points, model.surface, _n_samples(model, 0.0025), 0)
        assert revolves_about_z(S, N, cKDTree(S), model.points.mean(axis=0), 0.002) is expected
    empty = np.zeros((0, 3))
    assert revolves_about_z(empty, empty, cKDTree(empty), np.zeros(3), 0.002) is False


@pytest.mark.parametrize("turn_deg", [0.0, 70.0, -120.0, 180.0])
def test_a_guess_turned_any_way_about_the_boot_axis_places_it(boot, turn_deg):
    """The guess only knows the axis; the boot's turn about it is a tracked constant (alpha_z). Before the turn
    about the axis was set free, fits the coarse stage turned more than 30 degrees about it were taken for another
    basin and the registration refused (development seeds 19, 25, 34 and 38 of the boot's family; here the guesses
    turned -120 and 180 degrees)."""
    P, cams = _cloud(boot, floor_z=-0.04)  # the boot stands on a 40 mm base, as in its scenes
    guess = T_TRUE @ G.make_T(G.rot_axis("z", np.deg2rad(turn_deg)) @ G.rot_axis("x", np.deg2rad(4.0)),
                              [0.02, -0.025, 0.01])
    reg = register_rgbd(P, boot, guess, cams, CFG)
    mm, tilt = _error(reg.T_map_obj)
    assert mm < 1.0 and tilt < 0.3, (mm, tilt)
    # and it keeps the guess's turn about the axis (the depth does not say it; alpha_z is measured from it)
    assert abs(np.rad2deg(G.turn_about_z(guess[:3, :3].T @ reg.T_map_obj[:3, :3]))) < 0.5


def test_the_boot_icp_holds_its_turn_about_the_axis_and_places_the_axis(boot):
    """With ``hold_turn_about`` (the registration's setting for a body of revolution) the point-to-plane ICP does not
    turn the boot about its axis, which its surface does not fix: from a start 2-3 mm off, tilted 1 degree and turned
    5 degrees about the axis, the fit keeps that turn (free, the same ICP turns it by more than a degree) and places
    the axis (its point at the model's centre within 0.3 mm, its tilt within 0.1 degree), in fewer steps than the
    free one takes."""
    P, _ = _cloud(boot, floor_z=-0.04)
    c = boot.points.mean(axis=0)
    P_obj = G.transform(G.inv(T_TRUE), P)
    lo, hi = boot.points.min(axis=0) - 0.005, boot.points.max(axis=0) + 0.005
    P = P[np.all((P_obj > lo) & (P_obj < hi), axis=1)]  # the boot's box: no clutter, little floor
    S, N = sample_surface(boot.points, boot.surface, _n_samples(boot, 0.0025), 0)
    turn = G.make_T(t=c) @ G.make_T(G.rot_axis("z", np.deg2rad(5.0))) @ G.make_T(t=-c)
    T0 = G.make_T(G.rot_axis("x", np.deg2rad(1.0)), [0.002, -0.002, 0.001]) @ turn @ G.inv(T_TRUE)  # map -> object
    tree = cKDTree(S)

    def icp(hold):
        steps = []
        counting = type("Counting", (), {"data": tree.data,
                                         "query": lambda self, *a, **k: steps.append(1) or tree.query(*a, **k)})()
        T = icp_point_to_plane(P, counting, N, T0, 0.006, hold_turn_about=hold)
        return T, len(steps), np.rad2deg(G.turn_about_z(T[:3, :3] @ T0[:3, :3].T))

    T, n_held, turned = icp(np.array([0.0, 0.0, 1.0]))
    _, n_free, turned_free = icp(None)
    assert abs(turned) < 0.01 and abs(turned_free) > 1.0, (turned, turned_free)
    D = T @ T_TRUE  # object -> object: the fit against the truth
    assert 1e3 * np.linalg.norm(D[:3, :3] @ c + D[:3, 3] - c) < 0.3
    assert np.rad2deg(np.arccos(np.clip(D[2, 2], -1.0, 1.0))) < 0.1
    assert n_held < n_free, (n_held, n_free)


def test_a_guess_under_the_support_plane_is_lifted_onto_it(boot):
    """A guess whose model dips under the plane is lifted along its normal just onto it (development seed 36 of the
    boot's family: 113 mm off, its base 42 mm under the table, refused before); one above it stays."""
    plane = np.r_[T_TRUE[:3, 2], -T_TRUE[:3, 2] @ T_TRUE[:3, 3]]  # the plane of the boot's base
    under = T_TRUE @ G.make_T(G.rot_axis("z", 0.3), [0.03, -0.02, -0.042])
    lifted = lifted_onto(under, boot.points, plane)
    assert np.allclose(lifted[:3, :3], under[:3, :3])
    assert np.allclose(G.inv(T_TRUE) @ lifted[:, 3], [0.03, -0.02, 0.0, 1.0], atol=1e-9)
    above = T_TRUE @ G.make_T(t=[0.0, 0.0, 0.01])
    assert np.array_equal(lifted_onto(above, boot.points, plane), above)
    P, cams = _cloud(boot, floor_z=0.0)
    reg = register_rgbd(P, boot, T_TRUE @ G.make_T(G.rot_axis("z", np.deg2rad(20.0)), [-0.066, 0.042, -0.081]),
                        cams, CFG)
    mm, tilt = _error(reg.T_map_obj)
    assert mm < 1.0 and tilt < 0.3, (mm, tilt)


def _bent(boot, theta_deg: float, turn_deg: float) -> np.ndarray:
    """The boot's nodes (object frame) with its lever at ``theta_deg`` and the whole bent boot turned ``turn_deg``
    about its axis: the bellows bent that way (alpha_z ``turn_deg`` on the true pose)."""
    c = boot.points.mean(axis=0)
    u = boot.deformation_view(None).field.evaluate(np.array([np.deg2rad(theta_deg)]))
    return (boot.points + u - c) @ G.rot_axis("z", np.deg2rad(turn_deg)).T + c


def test_a_boot_registered_bent_keeps_the_guess_turn_and_gives_the_bend_its_direction(boot):
    """Registered while its lever is bent 20 degrees, the bellows bending 25 degrees about its axis from where alpha_z
    0 points on the true pose, the boot keeps the guess's turn about its axis (as at rest) and the turn its deformed
    fit needed is the load's direction, given apart (``Registration.turn``), from which the tracker starts alpha_z,
    and the deformed fit is placed as well as a rigid one.
    Until stop 104 that turn stayed in the pose: the boot registered bent was turned by the bend's direction (14-27
    degrees on the 8 s boot clip's depth), and alpha_z, measured from that pose, read as far off (this test's first
    assertion fails on that code: checked)."""
    P, cams = _cloud(boot, floor_z=-0.04, V=_bent(boot, 20.0, 25.0))
    guess = T_TRUE @ G.make_T(G.rot_axis("x", np.deg2rad(4.0)), [0.02, -0.025, 0.01])
    reg = register_loaded(P, boot, guess, cams, np.array([0.0]), np.array([np.deg2rad(52.0)]), CFG)
    assert abs(np.rad2deg(G.turn_about_z(guess[:3, :3].T @ reg.T_map_obj[:3, :3]))) < 0.5
    assert reg.revolves and reg.state is not None
    assert abs(np.rad2deg(reg.state[0]) - 20.0) < 0.5, np.rad2deg(reg.state)
    assert abs(np.rad2deg(reg.turn) - 25.0) < 1.0, np.rad2deg(reg.turn)
    # the deformed fit polished (``RegistrationConfig.polish``, the boot scene's 4 mm): without it the fit stopped a
    # pleat away, 4.6 mm off with the lever read 19.7 degrees (checked)
    mm, tilt = _error(reg.T_map_obj)
    assert mm < 0.5 and tilt < 0.2, (mm, tilt)
    # at rest there is no bend to give a direction: the turn is 0 and the pose the rigid fit's
    rest = register_loaded(_cloud(boot, floor_z=-0.04)[0], boot, guess, cams, np.array([0.0]),
                           np.array([np.deg2rad(52.0)]), CFG)
    assert rest.state is None and rest.turn == 0.0 and rest.revolves


@pytest.mark.parametrize("turn_deg", [110.0, -150.0])
def test_a_boot_registered_bent_any_way_finds_the_bend_direction(boot, turn_deg):
    """The bellows bent 30 degrees in a direction far from where alpha_z 0 points on the guess: the deformed fit's turn
    about the axis is searched over the whole circle (``DepthStateConfig.turn_steps``, a body of revolution's
    registration), so the direction is found, and the lever with it. Until stop 105 the fit's Gauss-Newton turned from
    the guess alone, a basin of a few degrees: such a boot was registered at rest (checked: this test fails there)."""
    P, cams = _cloud(boot, floor_z=-0.04, V=_bent(boot, 30.0, turn_deg))
    guess = T_TRUE @ G.make_T(G.rot_axis("x", np.deg2rad(4.0)), [0.02, -0.025, 0.01])
    reg = register_loaded(P, boot, guess, cams, np.array([0.0]), np.array([np.deg2rad(52.0)]), CFG)
    assert reg.state is not None, reg.state_reason
    assert abs(np.rad2deg(reg.state[0]) - 30.0) < 1.0, np.rad2deg(reg.state)
    off = (np.rad2deg(reg.turn) - turn_deg + 180.0) % 360.0 - 180.0
    assert abs(off) < 1.5, np.rad2deg(reg.turn)
    assert abs(np.rad2deg(G.turn_about_z(guess[:3, :3].T @ reg.T_map_obj[:3, :3]))) < 0.5


def _boot_scene(alpha: dict | None, reference: str = "depth") -> dict:
    params = {"theta": {"mode": "tracked"}} | ({"alpha_z": alpha} if alpha is not None else {})
    doc = {"simreal_scene": 1, "name": "boot", "localization": {"mode": "rgbd"},
           "camera": {"depth": "/camera/depth/image_raw"},
           "objects": [{"id": "boot", "model": "spec:joint_boot",
                        "anchor": {"kind": "registration", "guess": [0, 0, 0.6, 0, 0, 0, 1]},
                        "parameters": params,
                        "tracking": {"enabled": True, "measurements": "map_points", "reference": reference}}]}
    return validate_scene(doc, "boot", ".")


# the registered pose of the tests below (map <- object), its deformed fit's turn 0.4 rad and its state (theta 0.3)
T_REG = G.make_T(G.rot_axis("x", -1.9), [0.05, 0.1, 0.6])


def _placed(scene: dict, model) -> tuple[ObjectTrackers, object]:
    """``ObjectTrackers`` for ``scene``'s boot with a registration found (T_REG, turned 0.4 rad, theta 0.3), and the
    boot's tracker as built for a 640 x 480 camera."""
    objs = ObjectTrackers(scene["objects"], {"boot": model}, registration=CFG)
    objs.registrations["boot"] = Registration(T_REG, 0.9, 0.001, 5000, None, state=np.array([0.3]), revolves=True,
                                              turn=0.4)
    objs.set_camera(CameraModel.from_intrinsics(640, 480, 525.0, 525.0, 320.0, 240.0))
    return objs, objs.trackers["boot"]


@pytest.mark.parametrize("alpha, reference, in_pose, alpha_start", [
    ({"mode": "constant", "initial": 0.0}, "depth", 0.0, 0.4),  # the tracker starts alpha_z at the turn
    ({"mode": "tracked"}, "depth", 0.0, 0.4),
    ({"mode": "fixed", "value": 0.1}, "depth", 0.3, 0.1),  # the user's alpha_z stands: the pose takes the rest
    (None, "depth", 0.4, None),  # no alpha_z to carry it: the pose takes it all
    ({"mode": "constant", "initial": 0.0}, "rest", 0.4, 0.0),  # a tracker that starts at rest takes no state
])
def test_the_registration_turn_starts_alpha_z_or_stays_in_the_pose(boot, alpha, reference, in_pose, alpha_start):
    """Where a body of revolution's registration turn goes (``ObjectTrackers``): the deformed shape in the map is the
    registration's in every case, the turn carried by the tracker's alpha_z where it estimates alpha_z from the
    registration's state, else (in part) by the pose."""
    scene = _boot_scene(alpha, reference)
    o = scene["objects"][0]
    objs, tr = _placed(scene, boot)
    c = boot.points.mean(axis=0)
    assert np.allclose(tr.T_map_obj, turned_about_axis(T_REG, in_pose, c), atol=1e-12)
    alpha = tr.values[tr.layout.alpha_index] if tr.rigid_z else 0.0
    if alpha_start is not None:
        assert alpha == pytest.approx(alpha_start)
    # the model as the tracker draws it (alpha_z turns it about the object's z axis) is the registration's fit
    assert np.allclose(tr.T_map_obj @ G.make_T(G.rot_axis("z", alpha)), turned_about_axis(T_REG, 0.4, c), atol=1e-12)
    assert tr.values[0] == pytest.approx(0.3 if reference == "depth" else tr._initial[0])
    assert np.array_equal(objs._pose(o), tr.T_map_obj)


def test_the_turn_put_back_undoes_the_guess_turn():
    """``turned_about_axis`` with the turn ``turned_like`` took out gives the fit back (the turn measured as
    ``register_loaded`` measures it): the sign the registration's turn is given with."""
    c = np.array([0.0, 0.0, 0.07])
    fit = T_TRUE @ G.make_T(t=c) @ G.make_T(G.rot_axis("z", 0.6)) @ G.make_T(t=-c)
    guess = T_TRUE @ G.make_T(G.rot_axis("x", np.deg2rad(3.0)), [0.01, 0.0, 0.0])
    turn = G.turn_about_z(guess[:3, :3].T @ fit[:3, :3])
    assert turn == pytest.approx(0.6, abs=0.01)
    assert np.allclose(turned_about_axis(turned_like(fit, guess, c), turn, c), fit, atol=1e-12)


def test_the_first_depth_read_draws_the_bend_where_alpha_z_turns_it(boot, monkeypatch):
    """A tracker started from a registration's turn (alpha_z 120 degrees, its pose at the guess's turn) reads the
    lever from its first depth image with the model turned by alpha_z, as every later depth fit does: drawn
    unturned, the bend points 120 degrees away from the depth's and the lever is not read (checked: read at rest).
    The depth image's back-projection is replaced by the cloud it would give."""
    from simreal_nodes.assimilation import tracker as trk

    P, _ = _cloud(boot, floor_z=-0.04, V=_bent(boot, 20.0, 120.0))
    monkeypatch.setattr(trk, "depth_cloud", lambda *a, **k: P)
    params = {"theta": {"mode": "tracked"}, "alpha_z": {"mode": "constant", "initial": 0.0}}
    cam = CameraModel.from_intrinsics(640, 480, 525.0, 525.0, 320.0, 240.0)
    tr = trk.DeformableTracker(boot, T_TRUE, params, cam, trk.TrackerConfig(measurements="map_points"))
    tr.values[tr.layout.alpha_index] = np.deg2rad(120.0)
    mu, state, seen = tr.reference_from_depth(np.eye(4), np.zeros((480, 640), np.float32))
    assert seen and mu is not None, state
    assert abs(np.rad2deg(mu[0]) - 20.0) < 1.0, (np.rad2deg(mu), state)


def test_a_turn_about_another_axis_than_alpha_z_stays_in_the_pose(boot):
    """A model whose alpha_z turns it about an axis 1 cm from the vertical through its centroid (the axis a
    registration turns a body of revolution about): alpha_z and the registration's turn are not the same turn, so the
    pose keeps the whole turn and alpha_z its start."""
    import dataclasses

    rigid = [dict(r, origin=[0.01, 0.0, 0.0]) for r in boot.rigid_parameters]
    model = dataclasses.replace(boot, rigid_parameters=rigid)
    _, tr = _placed(_boot_scene({"mode": "constant", "initial": 0.0}), model)
    assert np.allclose(tr.T_map_obj, turned_about_axis(T_REG, 0.4, model.points.mean(axis=0)), atol=1e-12)
    assert tr.values[tr.layout.alpha_index] == 0.0
