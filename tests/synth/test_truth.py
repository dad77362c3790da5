"""The independent truth of the scene family: a full-order solve checked against beam theory, and the family's
seed discipline (same seed, same scene; development and held-out seeds disjoint)."""

import numpy as np
import pytest

from simreal_nodes.physics import materials
from simreal_nodes.rom.build import SPECS
from simreal_nodes.spec import Context
from simreal_nodes.synth import family
from simreal_nodes.synth.truth import beam_load_truth, model_error
from tests.modelkit import beam_model

L, W, H, E, F = 0.4, 0.02, 0.02, 2.0e9, 5.0
I = W * H ** 3 / 12


@pytest.fixture(scope="module")
def cantilever():
    m = materials.make_material("linear_elastic", E, 0.3)
    return beam_load_truth(L, W, H, m, [{"region": "xmin", "kind": "clamped"}], F, 0.006, (0.1, 0.39), step=0.029,
                           cells=(30, 2, 2))


def tip_deflection(tr, s):
    u = tr.at(s, np.array([[L, W / 2, H / 2]]))
    return -u[0, 2]


def test_cantilever_matches_euler_bernoulli(cantilever):
    # a slender (L/h = 20) cantilever: tip deflection F a^2 (3L - a) / (6 E I) within 3 % (shear, the footprint,
    # the clamp's full fixity and the coarse mesh all stay below that)
    for a in (0.2, 0.3, 0.39):
        eb = F * a ** 2 * (3 * L - a) / (6 * E * I)
        assert tip_deflection(cantilever, a) == pytest.approx(eb, rel=0.03)


def test_a_hyperelastic_truth_follows_the_weight_and_bends_like_the_linear_one_when_the_load_is_small(cantilever):
    """Saint Venant-Kirchhoff by Newton at each position (the weight sliding along): at a tip deflection of 1/100 of
    the length it is the linear solution (0.5 %); at about a third of the length it is not (the turned beam carries
    the vertical load with a shorter lever: 10 % less), the continuation along the positions ends where a direct
    solve at the last position does, and a nonlinear truth refuses to be scaled like a linear one."""
    def svk(force):
        m = materials.make_material("saint_venant_kirchhoff", E, 0.3)
        return beam_load_truth(L, W, H, m, [{"region": "xmin", "kind": "clamped"}], force, 0.006, (0.3, 0.39),
                               step=0.045, cells=(30, 2, 2))

    small = svk(F)
    assert small.info["linear"] is False and len(small.s) >= 3
    assert tip_deflection(small, 0.39) == pytest.approx(tip_deflection(cantilever, 0.39), rel=0.005)
    large = svk(F * 40)  # tip about 140 mm, a third of the length
    lin = 40 * tip_deflection(cantilever, 0.39)
    assert 0.05 < 1 - tip_deflection(large, 0.39) / lin < 0.2
    m = materials.make_material("saint_venant_kirchhoff", E, 0.3)
    direct = beam_load_truth(L, W, H, m, [{"region": "xmin", "kind": "clamped"}], F * 40, 0.006, (0.39, 0.4),
                             step=1.0, cells=(30, 2, 2))  # its first position is solved by load stepping alone
    np.testing.assert_allclose(large.displacement(0.39), direct.U[0], atol=1e-9)
    with pytest.raises(ValueError, match="does not scale"):
        small.scaled(2.0)


def test_interpolates_linearly_between_tabulated_positions(cantilever):
    s0, s1 = cantilever.s[3], cantilever.s[4]
    mid = cantilever.displacement(0.5 * (s0 + s1))
    assert np.allclose(mid, 0.5 * (cantilever.U[3] + cantilever.U[4]))
    assert np.array_equal(cantilever.displacement(-1.0), cantilever.U[0])  # clipped to the tabulated range
    assert np.allclose(cantilever.scaled(2.0).displacement(0.25), 2.0 * cantilever.displacement(0.25))


def test_model_error_finds_the_bias_of_a_shifted_model(cantilever):
    # a "model" that is the truth itself, tabulated at shifted load positions: the best fit sits exactly that
    # shift away, and the error measure reports it (what a perfect tracker would still be off by)
    from simreal_nodes.rom.model import ReducedModel
    from simreal_nodes.rom.separated import Axis, SeparatedField

    shift = cantilever.s[1] - cantilever.s[0]
    s_axis = cantilever.s[1:] - shift  # the model says s where the truth had s + shift
    space = cantilever.U[1:]  # one mode per tabulated position, indicator parameter modes
    fld = SeparatedField("displacement", space, [np.eye(len(s_axis))], [Axis("s", s_axis, "m", interpolation="linear")])
    m = ReducedModel("shifted", cantilever.points, cantilever.tets, "tet4", [Axis("s", s_axis, "m")],
                     {"displacement": fld}, cantilever.surface)
    err = model_error(m, cantilever, n_fit=len(s_axis), every=1)
    inside = (err.s > s_axis[0]) & (err.s < s_axis[-1])
    assert np.allclose(err.bias[inside], -shift, atol=1e-9)


def test_model_error_of_a_model_with_another_shape_is_large(cantilever):
    err = model_error(beam_model(), cantilever, every=2)
    assert np.all(err.rel_l2 > 0.05)


def test_family_draws_are_reproducible_and_the_seed_sets_are_disjoint():
    assert family.draw(7) == family.draw(7)
    assert family.draw(7) != family.draw(8)
    assert not set(family.DEV_SEEDS) & set(family.HELD_OUT_SEEDS)
    draws = [family.draw(s) for s in range(40)]
    assert {d.support for d in draws} == {"cantilever", "two_support"}
    peaks = [d.peak_px for d in draws]
    assert min(peaks) >= 2.0 and max(peaks) <= 40.0 and max(peaks) / min(peaks) > 5
    contrast = [d.speckle_contrast for d in draws]
    assert min(contrast) < 0.1 and max(contrast) > 0.5  # faint to painted
    for d in draws:
        assert d.s_range[0] < min(d.positions) and max(d.positions) <= d.s_range[1]
        assert np.linalg.norm(d.guess_error[:3]) < 0.25  # a guess by eye: centimetres, not metres
    guess_mm = [1e3 * np.linalg.norm(d.guess_error[:3]) for d in draws]
    assert 30 < np.sqrt(np.mean(np.square(guess_mm))) < 80  # about 5 cm rms: no precise truth in the scene file


def test_family_model_spec_is_a_valid_beam_spec():
    d = family.draw(3)
    spec = SPECS["beam_pgd"].validate(family.model_spec(d), "", Context("family", "."))
    assert spec["geometry"]["length"] == pytest.approx(d.length)
    assert spec["load"]["x_range"] == pytest.approx(list(d.s_range))


def test_make_bag_family_renders_a_drawn_scene_whose_scene_file_runs(tmp_path):
    # `simreal make-bag family --seed N`: the bag carries the truth, the scene file names the scene's own model spec
    # (a model a user would build for that set-up) and asks for registration from a guess by eye, not the truth
    import yaml

    from simreal_nodes import geometry as G
    from simreal_nodes.cli import main
    from simreal_nodes.io import bags
    from simreal_nodes.scene.schema import load_scene

    rc = main(["make-bag", "family", "--seed", "2", "-o", str(tmp_path / "fam"), "--resolution", "160x120",
               "--duration", "1.8", "--fps", "5", "--ssaa", "1", "--scene-out", str(tmp_path / "fam.yaml"), "-q"])
    assert rc == 0
    rep = bags.BagReport()
    msgs = list(bags.read_bag(tmp_path / "fam", rep))
    assert rep.problems == 0 and rep.counts["/camera/image_raw"] == 9
    truth = [bags.decode(m).values[0] for m in msgs if m.topic == "/ground_truth/objects/beam/parameters"]
    d = family.draw(2)
    assert np.isnan(truth[0]) and d.s_range[0] <= truth[-1] <= d.s_range[1]  # unloaded first, then the load
    doc = yaml.safe_load((tmp_path / "fam.yaml").read_text())
    obj = doc["objects"][0]
    assert obj["model"].startswith("spec:") and obj["model"].endswith(".yaml")
    scene = load_scene(tmp_path / "fam.yaml")  # validates without building the model
    assert scene["objects"][0]["anchor"]["kind"] == "registration"
    T_pose = G.pose7_to_matrix(scene["objects"][0]["anchor"]["guess"])
    pose = bags.decode(next(m for m in msgs if m.topic == "/ground_truth/objects/beam/pose")).pose
    T_true = G.pose7_to_matrix([pose.position.x, pose.position.y, pose.position.z, pose.orientation.x,
                                pose.orientation.y, pose.orientation.z, pose.orientation.w])
    err_mm = 1e3 * np.linalg.norm(T_pose[:3, 3] - T_true[:3, 3])
    assert 10.0 < err_mm < 250.0  # a guess by eye: off by centimetres, never the truth itself



def test_boot_truth_carries_the_top_ring_on_the_lever_and_matches_its_model_on_the_models_own_mesh():
    """The joint boot's truth solver on the model's own mesh (one layer through the wall) and a coarse angle step: its
    top ring is turned rigidly with the lever, its bottom ring stays, and it is the model's own full-order solution, so
    the reduced model (NI-PGD of that solution) reproduces it to a fraction of a percent; the benchmark's truth is
    the same solver on a finer grid."""
    from simreal_nodes.geometry import rot_axis
    from simreal_nodes.rom.build import cached_model, load_spec
    from simreal_nodes.rom.model_file import load_model
    from simreal_nodes.synth.truth import boot_lever_truth

    spec = dict(load_spec("joint_boot.yaml"))
    ms = spec["mesh"]
    tr = boot_lever_truth(spec, n_profile=ms["n_profile"], n_around=ms["n_around"], n_thick=1, step_deg=13.0)
    assert np.rad2deg(tr.theta).tolist() == pytest.approx([0, 13, 26, 39, 52])
    P, h = tr.points, spec["geometry"]["height"]
    top, bottom = np.abs(P[:, 2] - h) < 1e-9, np.abs(P[:, 2]) < 1e-9
    R = rot_axis("y", tr.theta[-1])
    assert np.abs(tr.U[-1][top] - (P[top] @ R.T - P[top])).max() < 1e-9
    assert np.abs(tr.U[-1][bottom]).max() < 1e-12
    assert np.abs(tr.displacement(0.5 * (tr.theta[1] + tr.theta[2])) - 0.5 * (tr.U[1] + tr.U[2])).max() < 1e-12
    model = load_model(cached_model("joint_boot"), fields=["displacement"])
    nb = model.provenance["lever_nodes"][0]
    assert np.allclose(model.points[:nb], P, atol=1e-12)  # the same mesh, vertex for vertex
    for k in (2, 4):
        um = model.displacement([tr.theta[k]])[:nb]
        assert np.linalg.norm(um - tr.U[k]) / np.linalg.norm(tr.U[k]) < 0.01
