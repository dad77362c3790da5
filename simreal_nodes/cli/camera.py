"""Camera command: calibrate (intrinsics from chessboard images)."""

from __future__ import annotations

import argparse

from simreal_nodes.camera import CALIBRATION_MODELS
from simreal_nodes.errors import SimrealError


def cmd_calibrate(a: argparse.Namespace) -> int:
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


def add_calibrate(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("calibrate", help="camera intrinsics from chessboard images")
    s.add_argument("images", nargs="+", help="image files or folders")
    s.add_argument("--board", required=True, help="inner corners COLSxROWS, e.g. 9x6")
    s.add_argument("--square", type=float, required=True, help="square size, metres")
    s.add_argument("--model", choices=CALIBRATION_MODELS, default="plumb_bob",
                   help="lens model (CameraInfo's distortion_model); equidistant: a fisheye lens")
    s.add_argument("--camera-name", default="camera")
    s.add_argument("-o", "--output", required=True)
    s.set_defaults(fn=cmd_calibrate)
