"""Scene commands: check-scene (validate a scene file; builds no model) and make-bag (render a synthetic scene)."""

from __future__ import annotations

import argparse

from simreal_nodes.cli.progress import TqdmProgress
from simreal_nodes.errors import SimrealError


def cmd_check_scene(a: argparse.Namespace) -> int:
    from simreal_nodes.scene.graph import ingest_note, required_nodes, unestimated_notes
    from simreal_nodes.scene.schema import load_scene

    scene = load_scene(a.scene)  # spec:NAME models are named, not built
    nodes = required_nodes(scene)
    print(f"{a.scene}: valid scene '{scene['name']}' with {len(scene['objects'])} object(s); "
          f"nodes: {', '.join(n.name for n in nodes)} ({ingest_note(scene, nodes)})")
    for n in nodes:
        print(f"  {n.name}: in {', '.join(n.inputs) or '-'}; out {', '.join(n.outputs)}")
    for note in unestimated_notes(scene):
        print(note)
    return 0


def cmd_make_bag(a: argparse.Namespace) -> int:
    from simreal_nodes.synth.makebag import make_bag

    w, h = (int(x) for x in a.resolution.lower().split("x"))
    progress = TqdmProgress() if not a.quiet else None
    try:
        name = a.scene
        if a.scene == "family":  # the family's scene is drawn from the seed
            if a.object == "boot" and a.sensor != "rgbd":
                raise SimrealError(f"--object boot --sensor {a.sensor}: the boot's family scenes are RGB-D only")
            name = {"plate": "family-plate-", "boot": "family-boot-"}.get(a.object, "family-") + str(a.seed) + (
                "-stereo" if a.sensor == "stereo" else "")
        elif a.sensor != "rgbd" or a.object != "beam":
            raise SimrealError(f"--sensor {a.sensor} --object {a.object}: only the 'family' scenes are drawn for "
                               f"another camera or object; '{a.scene}' has its own")
        info = make_bag(name, a.output, w, h, a.duration, a.fps, a.storage, a.seed, a.scene_out, a.ssaa, progress,
                        image_format=a.image_format, jpeg_quality=a.jpeg_quality, lens=a.lens)
    finally:
        if progress:
            progress.close()
    print(f"wrote {info['path']}: {info['frames']} frames {info['resolution']}, {info['bytes'] / 1e6:.1f} MB, "
          f"rendered in {info['seconds']:.1f} s" + (f"; scene file {a.scene_out}" if a.scene_out else ""))
    return 0


def add_check_scene(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("check-scene", help="validate a scene file")
    s.add_argument("scene")
    s.set_defaults(fn=cmd_check_scene)


def add_make_bag(sub: argparse._SubParsersAction) -> None:
    from simreal_nodes.synth.scenes import SCENES

    s = sub.add_parser("make-bag", help="render a synthetic seed scene with ground truth into a bag")
    s.add_argument("scene", choices=[*sorted(SCENES), "family", "car_aero", "car_aero-mono"],
                   help="a seed scene, or 'family': one scene of the held-out family drawn from --seed, or 'car_aero': "
                        "a held-out car of the aero database circled once (RGB-D; '-mono': colour only)")
    s.add_argument("-o", "--output", required=True)
    s.add_argument("--resolution", default="640x480")
    s.add_argument("--duration", type=float, help="seconds (default: the scene's)")
    s.add_argument("--fps", type=float, default=30.0)
    s.add_argument("--storage", choices=("mcap", "sqlite3"), default="mcap")
    s.add_argument("--seed", type=int, default=0, help="noise seed; for 'family' also the scene drawn (development "
                   "seeds 0-49 for tuning, held-out 1000-1099 for reporting)")
    s.add_argument("--sensor", choices=("rgbd", "stereo"), default="rgbd",
                   help="'family' only: the camera it is seen through (stereo: a rectified pair, no depth topic)")
    s.add_argument("--object", choices=("beam", "plate", "boot"), default="beam",
                   help="'family' only: a beam loaded along its top (s), a plate loaded anywhere on it (s_x, s_y), or "
                        "the joint boot bent by its lever (theta; its turn alpha_z unknown)")
    s.add_argument("--ssaa", type=int, default=2, help="supersampling factor (anti-aliasing)")
    s.add_argument("--lens", choices=("scene", "fisheye", "raw"), default="scene",
                   help="the scene's own camera, an equidistant (fisheye) lens whose image corners look 70 degrees "
                        "off the axis, or (stereo scenes) the pair as a driver's raw images: each camera its own "
                        "lens and turn, rectified by the ingest from the CameraInfos' R and P")
    s.add_argument("--scene-out", help="also write the scene YAML that runs the graph on this bag")
    s.add_argument("--image-format", choices=("raw", "jpeg", "png"), default="raw",
                   help="raw sensor_msgs/Image, or CompressedImage on <topic>/compressed (image_transport convention)")
    s.add_argument("--jpeg-quality", type=int, default=90)
    s.add_argument("-q", "--quiet", action="store_true")
    s.set_defaults(fn=cmd_make_bag)
