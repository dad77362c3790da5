"""The joint boot's scenes of the family (synth/boot_family.py): drawn set-ups, a lever schedule within the model's
range, and a scene file that carries no truth. (Rendering needs the boot's full-order truth, minutes to solve: the
benchmark renders, not the tests.)"""

import numpy as np
import pytest

from simreal_nodes import geometry as G
from simreal_nodes.synth.boot_family import THETA_RANGE_DEG, boot_family_scene, draw_boot, lever_angle
from simreal_nodes.synth.family import T_FREE, WALL_CLEARANCE_M
from simreal_nodes.synth.scenes import BOOT_ORIGIN


def test_draws_are_reproducible_varied_and_in_range():
    draws = [draw_boot(s) for s in range(40)]
    assert draw_boot(7) == draws[7]
    for d in draws:
        assert -180 <= d.alpha_z_deg < 180 and 4 <= len(d.holds_deg) <= 6
        assert all(4.0 <= h <= 50.0 for h in d.holds_deg)
        assert 0.4 <= d.distance <= 0.8 and 30 <= d.arc_deg <= 90 and 0.04 <= d.speckle_contrast <= 1.0
    # wide ranges, not one set-up: the turns and views spread around the boot, the contrasts over a decade
    assert np.ptp([d.alpha_z_deg for d in draws]) > 300 and np.ptp([d.arc_mid_deg for d in draws]) > 300
    assert max(d.speckle_contrast for d in draws) / min(d.speckle_contrast for d in draws) > 10


def test_lever_rests_then_visits_every_hold_within_the_model_range():
    d = draw_boot(1003)
    t = np.linspace(0.0, d.duration, 400)
    th = np.rad2deg([lever_angle(d, x) for x in t])
    assert np.all(th[t < T_FREE] == 0.0)
    assert th.min() >= 0.0 and th.max() <= THETA_RANGE_DEG
    for h in d.holds_deg:  # each hold is held (not only passed through)
        assert np.sum(np.abs(th - h) < 1e-6) >= 5, h


def test_scene_file_places_the_boot_by_registration_from_a_guess():
    """The scene file has the user's rough guess of the boot's axis frame (centimetres and degrees off the truth),
    alpha_z starts at 0 whatever the drawn turn, and the room clears the camera's path."""
    sc = boot_family_scene(1005)
    d = sc.state["draw"]
    doc = sc.scene_yaml(sc)
    obj = doc["objects"][0]
    assert obj["anchor"]["kind"] == "registration" and "pose" not in obj["anchor"]
    assert obj["anchor"]["polish_mm"] == 4  # chosen on development seeds 0-9 (docs/family.md)
    assert obj["parameters"]["alpha_z"] == {"mode": "constant", "initial": 0.0}
    T_true = sc.T_map_world() @ G.make_T(t=BOOT_ORIGIN)  # the axis frame in the map (the first camera frame)
    guess = G.pose7_to_matrix(obj["anchor"]["guess"])
    off = np.linalg.norm(guess[:3, 3] - T_true[:3, 3])
    assert 0.005 < off < 0.25
    x = np.array([sc.camera_pose(t)[0, 3] for t in np.linspace(0.0, sc.duration, 97)])
    assert np.all(sc.state["room_half_width"] - 0.025 - np.abs(x - BOOT_ORIGIN[0]) >= WALL_CLEARANCE_M - 1e-3)
    eye = sc.camera_pose(0.0)[:3, 3]
    assert 0.3 < np.linalg.norm(eye - (BOOT_ORIGIN + [0, 0, 0.06])) < 0.9
    assert abs(d.alpha_z_deg) <= 180


def test_scene_name_and_cli_reach_the_boot():
    from simreal_nodes.synth.makebag import make_scene

    sc = make_scene("family-boot-12", 640, 480, 6.0, 15.0)
    d = sc.state["draw"]
    assert sc.name == "family_boot_12" and sc.duration == 6.0
    assert (d.alpha_z_deg, d.holds_deg) == (draw_boot(12).alpha_z_deg, draw_boot(12).holds_deg)
    with pytest.raises(Exception, match="unknown scene"):
        make_scene("family-boot-x", 640, 480, 6.0, 15.0)


def test_boot_truth_cache_key_is_the_spec_content_not_its_path(tmp_path):
    """The boot's truth (minutes to solve) is cached on disk: a copy of the spec read from elsewhere (a clone in
    another folder) must find it, a changed spec must not."""
    from simreal_nodes.rom.build import SPEC_DIR, load_spec
    from simreal_nodes.synth.scenes import boot_truth_key

    text = (SPEC_DIR / "joint_boot.yaml").read_text()
    (tmp_path / "joint_boot.yaml").write_text(text)
    (tmp_path / "softer.yaml").write_text(text.replace("nu: 0.45", "nu: 0.4"))
    here = boot_truth_key(dict(load_spec("joint_boot.yaml")))
    assert boot_truth_key(dict(load_spec(tmp_path / "joint_boot.yaml"))) == here
    assert boot_truth_key(dict(load_spec(tmp_path / "softer.yaml"))) != here


def test_make_bag_family_boot_is_rgbd_only(tmp_path, capsys):
    from simreal_nodes.cli import main

    rc = main(["make-bag", "family", "--seed", "3", "--object", "boot", "--sensor", "stereo",
               "-o", str(tmp_path / "b"), "-q"])
    assert rc != 0 and "RGB-D only" in capsys.readouterr().err
    assert not (tmp_path / "b").exists()
