"""The plate members of the scene family: their independent truth (a load anywhere on the top face) checked against
beam theory and its own interpolation, the two-parameter model error, and the plate draws' discipline."""

import numpy as np
import pytest

from simreal_nodes.physics import materials
from simreal_nodes.rom.build import SPECS
from simreal_nodes.spec import Context
from simreal_nodes.synth import family
from simreal_nodes.synth.truth import plate_load_truth, plate_model_error

L, W, H, E, F = 0.3, 0.1, 0.01, 2.0e9, 2.0


@pytest.fixture(scope="module")
def shelf():
    """A cantilever plate (clamped at x = 0), Poisson's ratio 0 so that a load spread evenly across it bends it as
    a beam."""
    m = materials.make_material("linear_elastic", E, 0.0)
    return plate_load_truth(L, W, H, m, [{"region": "xmin", "kind": "clamped"}], F, 0.008, (0.1, 0.28),
                            (0.01, 0.09), cells=(30, 10, 2), step=0.02)


def test_a_load_spread_across_the_plate_bends_it_like_euler_bernoulli(shelf):
    # the weight at every tabulated position across (superposition: F spread evenly over the width) at x = a: the
    # tip's deflection, averaged across the width, is F a^2 (3L - a) / (6 E I) within 3 %
    inertia = W * H ** 3 / 12
    tip = np.c_[np.full(11, L), np.linspace(0, W, 11), np.full(11, H / 2)]
    for i in (0, len(shelf.s) - 1):
        a = shelf.s[i]
        u = np.mean([shelf.at((a, y), tip)[:, 2].mean() for y in shelf.sy])
        assert -u == pytest.approx(F * a ** 2 * (3 * L - a) / (6 * E * inertia), rel=0.03)


def test_a_load_off_the_centre_twists_the_plate_and_mirrors(shelf):
    # the load near one long edge pushes that edge's tip down more than the other's; its mirror image across the
    # centre line does the opposite by the same amount (to the mesh's symmetry)
    tips = np.array([[L, 0.0, H], [L, W, H]])
    lo = shelf.at((shelf.s[-1], shelf.sy[0]), tips)[:, 2]
    hi = shelf.at((shelf.s[-1], shelf.sy[-1]), tips)[:, 2]
    assert lo[0] < 1.03 * lo[1] < 0  # the near edge goes down further (both down; a narrow plate twists little)
    assert lo == pytest.approx(hi[::-1], rel=0.02)


def test_interpolates_bilinearly_between_tabulated_positions(shelf):
    s, sy, U = shelf.s, shelf.sy, shelf.U
    assert np.array_equal(shelf.displacement((s[2], sy[1])), U[2, 1])
    mid = shelf.displacement((0.5 * (s[2] + s[3]), 0.5 * (sy[1] + sy[2])))
    assert np.allclose(mid, 0.25 * (U[2, 1] + U[3, 1] + U[2, 2] + U[3, 2]))
    assert np.array_equal(shelf.displacement((-1.0, 9.0)), U[0, -1])  # clipped to the tabulated rectangle
    assert np.allclose(shelf.scaled(3.0).displacement((0.2, 0.05)), 3.0 * shelf.displacement((0.2, 0.05)))
    with pytest.raises(ValueError, match="linear"):
        plate_load_truth(L, W, H, materials.make_material("saint_venant_kirchhoff", E, 0.3),
                         [{"region": "xmin", "kind": "clamped"}], F, 0.005, (0.1, 0.28), (0.01, 0.09),
                         cells=(10, 2, 1), step=0.1)


def test_plate_model_error_finds_the_bias_of_a_shifted_model(shelf):
    # the truth itself as a model, tabulated one step along x off: the best fit sits one step (in % of the model's
    # x range) away, the y axis unbiased
    from simreal_nodes.rom.model import ReducedModel
    from simreal_nodes.rom.separated import Axis, SeparatedField

    nx, ny = len(shelf.s), len(shelf.sy)
    shift = shelf.s[1] - shelf.s[0]
    xs = shelf.s[1:] - shift  # the model says s_x where the truth had s_x + shift
    space = shelf.U[1:].reshape(-1, *shelf.U.shape[2:])  # one mode per tabulated position
    gx = np.repeat(np.eye(nx - 1), ny, axis=0)
    gy = np.tile(np.eye(ny), (nx - 1, 1))
    axes = [Axis("s_x", xs, "m", interpolation="linear"), Axis("s_y", shelf.sy, "m", interpolation="linear")]
    fld = SeparatedField("displacement", space, [gx, gy], axes)
    m = ReducedModel("shifted", shelf.points, shelf.tets, "tet4", axes, {"displacement": fld}, shelf.surface)
    err = plate_model_error(m, shelf, every=2)
    # positions inside the model's range whose shifted fit lies inside it too: the bias is one step (except the
    # first row, where the fit is clipped to the range)
    assert err["model_bias_max_pct_span"] == pytest.approx(100 * shift / (xs[-1] - xs[0]), rel=1e-3)


def test_plate_draws_are_reproducible_apart_from_the_beams_and_their_ranges_end_on_model_nodes():
    assert family.draw_plate(5) == family.draw_plate(5) != family.draw_plate(6)
    assert family.draw(5).object == "beam" and family.draw(5).y_range == ()
    draws = [family.draw_plate(s) for s in range(30)]
    assert {d.support for d in draws} == {"cantilever", "clamped_ends"}
    for d in draws:
        assert d.object == "plate" and d.parameters == ["s_x", "s_y"]
        assert 0.4 <= d.width / d.length <= 1.0
        assert 12 - 1e-9 <= d.length / d.height <= 40 + 1e-9 or d.height == 0.004
        nx, ny, _ = family.model_cells(d.beam)
        for (lo, hi), dx in ((d.s_range, d.length / nx), (d.y_range, d.width / ny)):
            assert lo / dx == pytest.approx(round(lo / dx), abs=1e-6) and hi / dx == pytest.approx(round(hi / dx),
                                                                                                     abs=1e-6)
        for x, y in d.positions:
            assert d.s_range[0] < x < d.s_range[1] and d.y_range[0] < y < d.y_range[1]
        spec = SPECS["beam_pgd"].validate(family.model_spec(d), "", Context("family", "."))
        assert spec["load"]["where"] == "top_face" and spec["load"]["y_range"] == pytest.approx(list(d.y_range))


def test_a_plate_scene_file_tracks_both_load_parameters_from_a_guess_by_eye():
    from simreal_nodes import geometry as G
    from simreal_nodes.synth.makebag import make_scene

    sc = make_scene("family-plate-3", 160, 120, duration=2.0, fps=5.0)
    assert sc.name == "family_plate_3" and sc.state["draw"].object == "plate"
    doc = sc.scene_yaml(sc)
    obj = doc["objects"][0]
    assert set(obj["parameters"]) == {"s_x", "s_y"} and obj["anchor"]["kind"] == "registration"
    d = sc.state["draw"]
    assert 10.0 < 1e3 * np.linalg.norm(d.guess_error[:3]) < 250.0
    T_guess = G.pose7_to_matrix(obj["anchor"]["guess"])
    assert np.linalg.norm(T_guess[:3, 3]) > 0.3  # a pose in front of the camera, not the truth's frame


def test_make_bag_draws_a_plate_only_for_the_family(tmp_path, capsys):
    from simreal_nodes.cli import main

    rc = main(["make-bag", "aluminium_beam", "--object", "plate", "-o", str(tmp_path / "b"), "-q"])
    assert rc != 0 and "only the 'family' scenes" in capsys.readouterr().err
    assert not (tmp_path / "b").exists()
