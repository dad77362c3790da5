"""CLI commands of the physics, synthesis and evaluation parts (registered by simreal_nodes.cli)."""

from __future__ import annotations

import sys
from pathlib import Path


class TqdmProgress:
    """progress(stage, done, total, message) -> one tqdm bar per stage."""

    def __init__(self):
        from tqdm import tqdm

        self._tqdm = tqdm
        self._bars = {}

    def __call__(self, stage: str, done: int, total: int, message: str = "") -> None:
        bar = self._bars.get(stage)
        if bar is None:
            bar = self._tqdm(total=total, desc=f"{stage:>18}", unit="", leave=True, file=sys.stderr, dynamic_ncols=True)
            self._bars[stage] = bar
        bar.n = done
        bar.set_postfix_str(message[:60], refresh=False)
        bar.refresh()

    def close(self):
        for b in self._bars.values():
            b.close()


def cmd_build_model(a) -> int:
    from simreal_nodes.rom.build import build_model, load_spec
    from simreal_nodes.rom.model_file import save_model

    spec = load_spec(a.spec)
    progress = TqdmProgress() if not a.quiet else None
    try:
        model = build_model(spec, progress)
    finally:
        if progress:
            progress.close()
    mid = save_model(model, a.output)
    print(model.summary())
    print(f"wrote {a.output} ({Path(a.output).stat().st_size / 1e6:.2f} MB, id {mid}) in "
          f"{model.provenance.get('build_time_s', 0):.1f} s")
    return 0


def cmd_model_info(a) -> int:
    from simreal_nodes.rom.model_file import load_model

    m = load_model(a.model)
    print(m.summary())
    if a.provenance:
        for k, v in m.provenance.items():
            if k != "spec":
                print(f"  {k}: {v}")
    return 0


def cmd_make_bag(a) -> int:
    from simreal_nodes.synth.makebag import make_bag

    w, h = (int(x) for x in a.resolution.lower().split("x"))
    progress = TqdmProgress() if not a.quiet else None
    try:
        info = make_bag(a.scene, a.output, w, h, a.duration, a.fps, a.storage, a.seed, a.scene_out, a.ssaa, progress,
                        image_format=a.image_format, jpeg_quality=a.jpeg_quality)
    finally:
        if progress:
            progress.close()
    print(f"wrote {info['path']}: {info['frames']} frames {info['resolution']}, {info['bytes'] / 1e6:.1f} MB, "
          f"rendered in {info['seconds']:.1f} s" + (f"; scene file {a.scene_out}" if a.scene_out else ""))
    return 0


def _load_trajectory(path: str, topic: str):
    from simreal_nodes.vision.trajectory import read_bag_poses, read_tum

    p = Path(path)
    if p.is_dir() or p.suffix in (".mcap", ".db3"):
        return read_bag_poses(p, topic)
    return read_tum(p)


def cmd_eval_trajectory(a) -> int:
    import json

    import numpy as np

    from simreal_nodes.vision.trajectory import associate, ate, rpe, write_tum

    te, Te = _load_trajectory(a.estimate, a.topic)
    tr, Tr = _load_trajectory(a.truth or a.estimate, a.truth_topic)
    ie, ir = associate(te, tr, a.max_dt)
    if len(ie) < 3:
        from simreal_nodes.errors import SimrealError
        raise SimrealError(f"only {len(ie)} estimated poses have a reference within {a.max_dt} s (need 3)")
    E = np.array([Te[i][:3, 3] for i in ie])
    R = np.array([Tr[i][:3, 3] for i in ir])
    res = ate(E, R, with_scale=a.scale)
    rp = rpe([Te[i] for i in ie], [Tr[i] for i in ir], delta=a.delta, scale=res["scale"])
    print(f"poses: {len(ie)} associated of {len(te)} estimated / {len(tr)} reference; trajectory length {res['length']:.3f} m")
    print(f"ATE  rmse {res['rmse'] * 1e3:.2f} mm ({res['rmse_pct_length']:.3f} % of length), mean {res['mean'] * 1e3:.2f}, "
          f"median {res['median'] * 1e3:.2f}, max {res['max'] * 1e3:.2f} mm" + (f"; scale {res['scale']:.5f}" if a.scale else ""))
    print(f"RPE  ({a.delta} frames) translation rmse {rp['trans_rmse'] * 1e3:.2f} mm, rotation rmse {rp['rot_rmse_deg']:.3f} deg")
    if a.json:
        Path(a.json).write_text(json.dumps({k: v for k, v in res.items() if k not in ("R", "t", "errors")} | {"rpe": rp}, indent=2))
    if a.save_tum:
        write_tum(a.save_tum, te, Te)
    return 0


def cmd_eval_tracking(a) -> int:
    import json

    import numpy as np

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
                  f"({100 * r.median_abs / r.span if r.span else float('nan'):.2f} % of the range), mean {r.mean_abs * scale:.3f}, "
                  f"max {r.max_abs * scale:.3f} {unit}; {r.outside_range} estimates outside the range; states {r.states}\n")
            out[f"{oid}/{r.name}"] = {"median_abs": r.median_abs, "mean_abs": r.mean_abs, "max_abs": r.max_abs,
                                      "span": r.span, "outside_range": r.outside_range, "n": r.n, "states": r.states,
                                      "table": r.table, "unit": r.unit}
    if a.json:
        Path(a.json).write_text(json.dumps(out, indent=2))
    return 0


def cmd_demo(a) -> int:
    from simreal_nodes.demo import run_demo

    m = run_demo(a.scene, a.output, regenerate=a.regenerate, resolution=a.resolution, duration=a.duration)
    bad = [k for k, p in m["parameters"].items() if "error" in p]
    return 1 if bad or m["frames"]["frames_completed"] == 0 else 0


def add_commands(sub) -> None:
    from simreal_nodes.demo import DEFAULT_SCENE

    s = sub.add_parser("demo", help="end-to-end demo on an embedded sample scene (no camera needed)")
    s.add_argument("--scene", default=DEFAULT_SCENE, help=f"synthetic seed scene (default {DEFAULT_SCENE})")
    s.add_argument("-o", "--output", default="out/demo", help="folder for the MP4, plot and metrics")
    s.add_argument("--resolution", default="640x480")
    s.add_argument("--duration", type=float, help="seconds, when the sample bag has to be rendered")
    s.add_argument("--regenerate", action="store_true", help="render the sample bag again")
    s.set_defaults(fn=cmd_demo)

    s = sub.add_parser("eval-tracking", help="estimated vs true parameters of a replayed synthetic bag (Table 4.1)")
    s.add_argument("output_bag", help="bag recorded by `simreal replay --record`")
    s.add_argument("--truth", help="the synthetic input bag (ground truth)")
    s.add_argument("--object", action="append", required=True, help="object id (repeatable)")
    s.add_argument("--scene", help="scene YAML: report errors as %% of the model's parameter ranges (default: of the true range)")
    s.add_argument("--json", help="write the numbers here")
    s.set_defaults(fn=cmd_eval_tracking)

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

    from simreal_nodes.synth.scenes import SCENES

    s = sub.add_parser("make-bag", help="render a synthetic seed scene with ground truth into a bag")
    s.add_argument("scene", choices=sorted(SCENES))
    s.add_argument("-o", "--output", required=True)
    s.add_argument("--resolution", default="640x480")
    s.add_argument("--duration", type=float, help="seconds (default: the scene's)")
    s.add_argument("--fps", type=float, default=30.0)
    s.add_argument("--storage", choices=("mcap", "sqlite3"), default="mcap")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--ssaa", type=int, default=2, help="supersampling factor (anti-aliasing)")
    s.add_argument("--scene-out", help="also write the scene YAML that runs the graph on this bag")
    s.add_argument("--image-format", choices=("raw", "jpeg", "png"), default="raw",
                   help="raw sensor_msgs/Image, or CompressedImage on <topic>/compressed (image_transport convention)")
    s.add_argument("--jpeg-quality", type=int, default=90)
    s.add_argument("-q", "--quiet", action="store_true")
    s.set_defaults(fn=cmd_make_bag)

    s = sub.add_parser("build-model", help="build a reduced-order model file from a spec")
    s.add_argument("spec", help="model spec YAML (or the name of a built-in spec, e.g. aluminium_beam.yaml)")
    s.add_argument("-o", "--output", required=True, help="output .h5")
    s.add_argument("-q", "--quiet", action="store_true", help="no progress bars")
    s.set_defaults(fn=cmd_build_model)

    s = sub.add_parser("model-info", help="summary of a model file")
    s.add_argument("model")
    s.add_argument("--provenance", action="store_true")
    s.set_defaults(fn=cmd_model_info)
