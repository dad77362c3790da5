"""The `simreal` command line.

    simreal demo                                 the end-to-end demo on the embedded default scene
    simreal launch SCENE.yaml                    start the nodes the scene requires (Ctrl-C stops)
    simreal replay BAG --scene SCENE.yaml        play a bag into the graph (--lossless, --rate, --record OUT)
    simreal record -o OUT [TOPIC ...]            record live topics to a bag
    simreal bag-info BAG                         topics, counts and problems of a bag
    simreal check-scene SCENE.yaml               validate a scene file
    simreal calibrate IMAGES... --board 9x6 --square 0.025 -o calib.yaml
    simreal build-model SPEC.yaml -o MODEL.h5    build a reduced-order model
    simreal make-bag SCENE -o BAG                render a synthetic scene with ground truth
    simreal eval-trajectory EST --truth REF      ATE / RPE of a camera trajectory
    simreal eval-tracking OUT_BAG --truth BAG    parameter errors (thesis Table 4.1 layout)

Errors that come from bad input print one line that says what was wrong (exit code 2).
"""

from __future__ import annotations

import argparse
import sys

from simreal_nodes.errors import SimrealError


def _remaps(items):
    out = {}
    for it in items or []:
        a, sep, b = it.partition(":=")
        if not sep or not a or not b:
            raise SimrealError(f"--remap expects FROM:=TO, got '{it}'")
        out[a] = b
    return out


def cmd_launch(a) -> int:
    from simreal_nodes.launch import Launcher, run_until_signal
    from simreal_nodes.scene.graph import required_nodes
    from simreal_nodes.scene.schema import build_spec_models, load_scene

    scene = build_spec_models(load_scene(a.scene))  # before the nodes start: they load the built models
    nodes = required_nodes(scene, lossless=a.lossless)
    print(f"[launch] scene '{scene['name']}': starting {', '.join(n.name for n in nodes)}")
    return run_until_signal(Launcher(nodes, remaps=_remaps(a.remap), respawn=a.respawn))


def cmd_replay(a) -> int:
    from simreal_nodes.ros.commands import replay

    stats, report, _ = replay(a.bag, a.scene, rate=a.rate, lossless=a.lossless, record=a.record,
                              storage=a.storage, launch=not a.no_launch, frame_timeout_s=a.frame_timeout,
                              metrics_json=a.metrics)
    return 0 if stats is not None else 1


def cmd_record(a) -> int:
    from simreal_nodes.ros.commands import record

    record(a.output, a.topics, a.storage, duration_s=a.duration)
    return 0


def cmd_bag_info(a) -> int:
    from simreal_nodes.io import bags

    rep = bags.BagReport()
    for _ in bags.read_bag(a.bag, rep):
        pass
    print(rep.summary())
    return 0 if rep.problems == 0 else 1


def cmd_check_scene(a) -> int:
    from simreal_nodes.scene.graph import required_nodes
    from simreal_nodes.scene.schema import load_scene

    scene = load_scene(a.scene)
    nodes = required_nodes(scene)
    print(f"{a.scene}: valid scene '{scene['name']}' with {len(scene['objects'])} object(s); "
          f"nodes: {', '.join(n.name for n in nodes)}")
    for n in nodes:
        print(f"  {n.name}: in {', '.join(n.inputs) or '-'}; out {', '.join(n.outputs)}")
    return 0


def cmd_calibrate(a) -> int:
    from simreal_nodes.vision.calibration import calibrate, load_images

    try:
        cols, rows = (int(x) for x in a.board.lower().split("x"))
    except ValueError:
        raise SimrealError(f"--board expects COLSxROWS inner corners, e.g. 9x6; got '{a.board}'") from None
    res = calibrate(load_images(a.images), cols, rows, a.square, a.model)
    res.camera.to_calibration_yaml(a.output, a.camera_name)
    c = res.camera
    print(f"calibrated from {len(res.used)} views (rejected {len(res.rejected)}): RMS {res.rms_px:.3f} px; "
          f"fx {c.fx:.2f} fy {c.fy:.2f} cx {c.cx:.2f} cy {c.cy:.2f} D {[round(x, 5) for x in c.D]}")
    for k, v in res.rejected.items():
        print(f"  rejected {k}: {v}")
    print(f"wrote {a.output}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="simreal", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True)

    s = sub.add_parser("launch", help="start the nodes a scene requires")
    s.add_argument("scene")
    s.add_argument("--remap", action="append", metavar="FROM:=TO", help="remap a topic in every node")
    s.add_argument("--lossless", action="store_true", help="reliable QoS everywhere")
    s.add_argument("--respawn", type=int, default=2, help="restarts allowed per node (default 2)")
    s.set_defaults(fn=cmd_launch)

    s = sub.add_parser("replay", help="play a bag into the graph")
    s.add_argument("bag")
    s.add_argument("--scene", required=True)
    g = s.add_mutually_exclusive_group()
    g.add_argument("--rate", type=float, default=1.0, help="playback rate (1 = recorded rate)")
    g.add_argument("--lossless", action="store_true", help="every frame processed exactly once, in order")
    s.add_argument("--record", metavar="OUT", help="record every output topic to this bag")
    s.add_argument("--storage", choices=("mcap", "sqlite3"), default="mcap")
    s.add_argument("--no-launch", action="store_true", help="the graph is already running")
    s.add_argument("--frame-timeout", type=float, default=30.0, help="lossless: seconds to wait per frame")
    s.add_argument("--metrics", metavar="JSON", help="write replay statistics here")
    s.set_defaults(fn=cmd_replay)

    s = sub.add_parser("record", help="record live topics")
    s.add_argument("topics", nargs="*", help="topics (default: all)")
    s.add_argument("-o", "--output", required=True)
    s.add_argument("--storage", choices=("mcap", "sqlite3"), default="mcap")
    s.add_argument("--duration", type=float, help="stop after this many seconds")
    s.set_defaults(fn=cmd_record)

    s = sub.add_parser("bag-info", help="topics, counts and problems of a bag")
    s.add_argument("bag")
    s.set_defaults(fn=cmd_bag_info)

    s = sub.add_parser("check-scene", help="validate a scene file")
    s.add_argument("scene")
    s.set_defaults(fn=cmd_check_scene)

    s = sub.add_parser("calibrate", help="camera intrinsics from chessboard images")
    s.add_argument("images", nargs="+", help="image files or folders")
    s.add_argument("--board", required=True, help="inner corners COLSxROWS, e.g. 9x6")
    s.add_argument("--square", type=float, required=True, help="square size, metres")
    s.add_argument("--model", choices=("plumb_bob", "rational_polynomial"), default="plumb_bob")
    s.add_argument("--camera-name", default="camera")
    s.add_argument("-o", "--output", required=True)
    s.set_defaults(fn=cmd_calibrate)

    _add_later_commands(sub)
    return p


def _add_later_commands(sub) -> None:
    """Commands whose implementation lives in the physics / synthesis / evaluation modules."""
    from simreal_nodes import cli_more

    cli_more.add_commands(sub)


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.fn(args) or 0)
    except SimrealError as e:
        print(f"simreal {args.cmd}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
