"""Evaluation commands: eval-tracking (estimated vs true parameters, thesis Table 4.1) and eval-trajectory
(ATE / RPE of a camera trajectory)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from simreal_nodes.errors import SimrealError


def _load_trajectory(path: str, topic: str) -> tuple[np.ndarray, list[np.ndarray]]:
    from simreal_nodes.vision.trajectory import read_bag_poses, read_tum

    p = Path(path)
    if p.is_dir() or p.suffix in (".mcap", ".db3"):
        return read_bag_poses(p, topic)
    return read_tum(p)


def cmd_eval_trajectory(a: argparse.Namespace) -> int:
    from simreal_nodes.vision.trajectory import associate, ate, rpe, write_tum

    te, Te = _load_trajectory(a.estimate, a.topic)
    tr, Tr = _load_trajectory(a.truth or a.estimate, a.truth_topic)
    ie, ir = associate(te, tr, a.max_dt)
    if len(ie) < 3:
        raise SimrealError(f"only {len(ie)} estimated poses have a reference within {a.max_dt} s (need 3)")
    E = np.array([Te[i][:3, 3] for i in ie])
    R = np.array([Tr[i][:3, 3] for i in ir])
    res = ate(E, R, with_scale=a.scale)
    rp = rpe([Te[i] for i in ie], [Tr[i] for i in ir], delta=a.delta, scale=res["scale"])
    print(f"poses: {len(ie)} associated of {len(te)} estimated / {len(tr)} reference; "
          f"trajectory length {res['length']:.3f} m")
    print(f"ATE  rmse {res['rmse'] * 1e3:.2f} mm ({res['rmse_pct_length']:.3f} % of length), "
          f"mean {res['mean'] * 1e3:.2f}, median {res['median'] * 1e3:.2f}, max {res['max'] * 1e3:.2f} mm"
          + (f"; scale {res['scale']:.5f}" if a.scale else ""))
    print(f"RPE  ({a.delta} frames) translation rmse {rp['trans_rmse'] * 1e3:.2f} mm, "
          f"rotation rmse {rp['rot_rmse_deg']:.3f} deg")
    if a.json:
        numbers = {k: v for k, v in res.items() if k not in ("R", "t", "errors")} | {"rpe": rp}
        Path(a.json).write_text(json.dumps(numbers, indent=2))
    if a.save_tum:
        write_tum(a.save_tum, te, Te)
    return 0


def cmd_eval_tracking(a: argparse.Namespace) -> int:
    from simreal_nodes.assimilation.evaluate import compare, format_table41, read_parameters

    truth_bag = a.truth or a.output_bag
    out = {}
    for oid in a.object:
        est = read_parameters(a.output_bag, f"/simreal/objects/{oid}/parameters")
        tru = read_parameters(truth_bag, f"/ground_truth/objects/{oid}/parameters")
        ranges = None
        if a.scene:
            from simreal_nodes.demo import model_ranges
            from simreal_nodes.scene.schema import build_spec_models, load_scene

            objs = {o["id"]: o for o in build_spec_models(load_scene(a.scene))["objects"]}
            ranges = model_ranges(objs[oid]["model"]) if oid in objs else None
        reports = compare(est, tru, ranges)
        for r in reports:
            deg = r.unit == "rad"
            scale, unit = (180 / np.pi, "deg") if deg else ((1e3, "mm") if r.unit == "m" else (1.0, r.unit))
            print(format_table41(r, scale, unit))
            print(f"{oid}/{r.name}: {r.n} frames; median |error| {r.median_abs * scale:.3f} {unit} "
                  f"({100 * r.median_abs / r.span if r.span else float('nan'):.2f} % of the range), "
                  f"mean {r.mean_abs * scale:.3f}, max {r.max_abs * scale:.3f} {unit}; "
                  f"{r.outside_range} estimates outside the range; states {r.states}\n")
            out[f"{oid}/{r.name}"] = {"median_abs": r.median_abs, "mean_abs": r.mean_abs, "max_abs": r.max_abs,
                                      "span": r.span, "outside_range": r.outside_range, "n": r.n, "states": r.states,
                                      "table": r.table, "unit": r.unit}
    if a.json:
        Path(a.json).write_text(json.dumps(out, indent=2))
    return 0


def add_eval_tracking(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("eval-tracking", help="estimated vs true parameters of a replayed synthetic bag (Table 4.1)")
    s.add_argument("output_bag", help="bag recorded by `simreal replay --record`")
    s.add_argument("--truth", help="the synthetic input bag (ground truth)")
    s.add_argument("--object", action="append", required=True, help="object id (repeatable)")
    s.add_argument("--scene", help="scene YAML: report errors as %% of the model's parameter ranges "
                   "(default: of the true range)")
    s.add_argument("--json", help="write the numbers here")
    s.set_defaults(fn=cmd_eval_tracking)


def add_eval_trajectory(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("eval-trajectory", help="ATE / RPE of a camera trajectory (TUM files or bags)")
    s.add_argument("estimate", help="TUM file or bag with the estimated poses")
    s.add_argument("--truth", help="TUM file or bag with the reference (default: the estimate bag)")
    s.add_argument("--topic", default="/simreal/localization/pose", help="estimate topic in a bag")
    s.add_argument("--truth-topic", default="/ground_truth/camera_pose", help="reference topic in a bag")
    s.add_argument("--scale", action="store_true", help="align with scale (monocular)")
    s.add_argument("--delta", type=int, default=1, help="RPE frame step")
    s.add_argument("--max-dt", type=float, default=0.005, help="stamp association tolerance, s")
    s.add_argument("--json", help="write the numbers here")
    s.add_argument("--save-tum", help="write the estimate as TUM")
    s.set_defaults(fn=cmd_eval_trajectory)
