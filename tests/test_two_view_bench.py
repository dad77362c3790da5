"""The two-view benchmark's measures: the relative pose it scores against, and its counting of reconstructed and
common pairs (a refusal is left out of the errors, never counted as zero)."""

import numpy as np

from benchmarks.two_view import METHODS, relative, rows_for
from simreal_nodes import geometry as G


def test_relative_pose_maps_view_0_points_into_view_1():
    T_wc0 = G.make_T(G.rot_axis("z", 0.3), np.array([0.1, 0.2, 0.3]))
    T_wc1 = G.make_T(G.rot_axis("y", -0.2), np.array([0.5, -0.1, 0.0]))
    R, t = relative(T_wc0, T_wc1)
    X_w = np.array([0.4, -0.3, 2.0])
    x0 = np.linalg.inv(T_wc0) @ np.r_[X_w, 1.0]
    x1 = np.linalg.inv(T_wc1) @ np.r_[X_w, 1.0]
    np.testing.assert_allclose(R @ x0[:3] + t, x1[:3], atol=1e-12)


def test_rows_count_refusals_and_the_common_pairs():
    # three pairs: 'essential' reconstructs all, 'fundamental' refuses the second, 'opencv' all
    res = {m: [(0.1, 1.0, "fundamental", 5.0), (0.2, 2.0, "homography", 5.0), (0.3, 3.0, "fundamental", 5.0)]
           for m in METHODS}
    res["fundamental"] = [(1.0, 10.0, "fundamental", 4.0), None, (3.0, 30.0, "fundamental", 4.0)]
    rows = {r["method"]: r for r in rows_for("x", res)}
    assert rows["essential"]["solved"] == 3 and rows["fundamental"]["solved"] == 2
    assert rows["essential"]["dir_med"] == 2.0 and rows["fundamental"]["dir_med"] == 20.0
    assert rows["essential"]["homography_pct"] == 100.0 / 3
    # the pairs every method reconstructed: the first and the third
    assert rows["essential"]["common"] == 2 and rows["essential"]["c_dir_med"] == 2.0
    assert rows["fundamental"]["c_rot_med"] == 2.0


def test_replot_redraws_from_the_saved_rows(tmp_path, monkeypatch):
    """`--replot` draws the PNG from the JSON a run saved (a failed run's missing ATE is a gap, not a zero bar) and
    links it from the table once."""
    import json

    import benchmarks.common as common
    from benchmarks.relocalization import plot_kidnap_rows, plot_reuse_rows
    from benchmarks.two_view import plot_slam_rows

    monkeypatch.setattr(common, "RESULTS", tmp_path)
    slam = [{"data": d, "start": s, "model": m, "ate_mm": None if (s, m) == ("a", "x") else 3.0}
            for d in ("room", "real") for s in ("a", "b") for m in ("x", "y")]
    kid = [{"mode": m, "cut_s": c, "first_err_mm": 2.0, "ate_after_mm": None} for m in ("rgbd", "mono") for c in (2, 4)]
    reuse = [{"mode": "rgbd", "pass2_tracked_pct": 100.0, "pass1_ate_mm": 1.0, "pass2_err_mm": None}]
    for name, rows, fn in (("s", slam, plot_slam_rows), ("k", kid, plot_kidnap_rows), ("r", reuse, plot_reuse_rows)):
        (tmp_path / f"{name}.json").write_text(json.dumps({"title": name, "rows": rows}))
        (tmp_path / f"{name}.md").write_text("# table\n")
        assert common.replot(name, fn).stat().st_size > 1000
        common.replot(name, fn)
        assert (tmp_path / f"{name}.md").read_text().count(f"({name}.png)") == 1
