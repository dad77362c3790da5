"""The overlay's lens-distortion map (issue 18): ``CameraModel.ideal_pixel_map`` exact at every ``step``-th pixel and
bilinear between, against every pixel exact (step 1): the largest error in pixels and the time to build it, per step,
on a mild and a strong barrel distortion at 640 x 480 and 1280 x 720. The overlay builds it when the camera's
intrinsics come, which is when its first frame waits; it takes ``IDEAL_MAP_STEP``.

    ./run bench ideal_map
"""

from __future__ import annotations

import time

import numpy as np

from benchmarks.common import save
from simreal_nodes.camera import IDEAL_MAP_STEP, CameraModel

DISTORTIONS = {"mild (k1 -0.04)": [-0.04, 0.01, 0.0, 0.0, 0.0],
               "strong (k1 -0.35)": [-0.35, 0.15, 0.001, -0.001, -0.03]}
SIZES = ((640, 480), (1280, 720))
STEPS = (1, 2, 4, 8, 16, 32)
REPEAT = 3


def main():
    rows = []
    for (w, h) in SIZES:
        for name, D in DISTORTIONS.items():
            cam = CameraModel.from_intrinsics(w, h, 0.9 * w, 0.9 * w, w / 2 - 0.5, h / 2 - 0.5, D=D)
            exact = cam.ideal_pixel_map(step=1)
            for step in STEPS:
                times = []
                for _ in range(REPEAT):
                    t0 = time.perf_counter()
                    m = cam.ideal_pixel_map(step=step)
                    times.append(time.perf_counter() - t0)
                err = np.abs(m - exact).max()
                rows.append(dict(resolution=f"{w}x{h}", distortion=name, step=step, max_err_px=float(err),
                                 ms=1e3 * float(np.median(times)), default=step == IDEAL_MAP_STEP))
                print(rows[-1], flush=True)

    def plot(plt):
        fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
        for res in dict.fromkeys(r["resolution"] for r in rows):
            for name in DISTORTIONS:
                rs = [r for r in rows if r["resolution"] == res and r["distortion"] == name]
                ax[0].plot([r["step"] for r in rs[1:]], [r["max_err_px"] for r in rs[1:]], "o-", label=f"{res} {name}")
                ax[1].plot([r["step"] for r in rs], [r["ms"] for r in rs], "o-", label=f"{res} {name}")
        for a in ax:
            a.set_xscale("log", base=2)
            a.axvline(IDEAL_MAP_STEP, color="k", ls=":", lw=0.8)
            a.set_xlabel("step (pixels between exact values)")
        ax[0].set_yscale("log")
        ax[0].set_ylabel("largest error against every pixel exact (px)")
        ax[1].set_ylabel("time to build (ms, median of 3)")
        ax[0].legend(fontsize=6)
        fig.tight_layout()
        return fig

    cols = [("resolution", "resolution", "{}"), ("distortion", "distortion", "{}"), ("step", "step", "{}"),
            ("max_err_px", "largest error (px)", "{:.2g}"), ("ms", "time (ms)", "{:.1f}"),
            ("default", "the overlay's", "{}")]
    save("ideal_map", rows, cols, "The overlay's distortion map: step between exact values against error and time",
         "Step 1: every pixel undistorted by OpenCV (`cv2.undistortPoints`, 50 iterations to 1e-10), the reference "
         "and what the synthetic renders use; a larger step: those exact values on a grid, bilinear between "
         "(`CameraModel.ideal_pixel_map`). The error is the largest over the image. The overlay takes step "
         f"{IDEAL_MAP_STEP} (the 'the overlay's' rows): it builds the map when the camera's intrinsics come, with "
         "its first frame waiting. Focal length 0.9 x the width.", plot=plot)


if __name__ == "__main__":
    main()
