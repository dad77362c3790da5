"""ORB features on the object (issue 16, item 4): on development family scenes, how many of the extractor's
keypoints land inside the object's true visible image region, without and with the object's region as a focus
polygon (its convex hull, as the tracker's ``screen_region`` gives it), and the CPU time per frame.

    python -m benchmarks.orb_focus --seeds 0,1,3,4,7,8 [--features 1500] [--frames 6]

CPU time (process time, one OpenCV thread) rather than wall time: the figure then holds on a shared machine.
Writes benchmarks/results/orb_focus.{json,md,png}.
"""

from __future__ import annotations

import argparse
import time

import cv2
import numpy as np

from benchmarks.common import save
from benchmarks.family import parse_seeds
from simreal_nodes.render.gl import Renderer
from simreal_nodes.synth import world as W
from simreal_nodes.synth.family import draw
from simreal_nodes.synth.makebag import load_models, make_scene, render_frame
from simreal_nodes.vision.orb import OrbExtractor


def frames_with_masks(seed: int, n: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """``n`` grey frames spread over the scene's duration, each with the beam's visible pixels (its own depth
    render agrees with the whole scene's)."""
    sc = make_scene(f"family-{seed}", 640, 480, None, 15.0)
    models = load_models(sc)
    sc.state["models"] = models
    r = Renderer(sc.camera, ssaa=2)
    sc.build(sc, r, models)
    rng = np.random.default_rng(0)
    out = []
    for i in np.linspace(0, round(sc.duration * sc.fps) - 1, n).astype(int):
        t = i / sc.fps
        sc.update(sc, r, t)
        T = sc.camera_pose(t)
        rgb, d = render_frame(sc, r, t, T)
        _, d_beam = r.render(T, names=["beam"])
        gray = cv2.cvtColor(W.pixel_noise(rgb, sc.pixel_sigma, rng), cv2.COLOR_RGB2GRAY)
        out.append((gray, (d_beam > 0) & (np.abs(d_beam - d) < 3e-3)))
    r.release()
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", default="0,1,3,4,7,8")
    ap.add_argument("--features", type=int, default=1500)
    ap.add_argument("--frames", type=int, default=6)
    a = ap.parse_args()
    cv2.setNumThreads(1)
    ex = OrbExtractor(a.features)
    rows = []
    for seed in parse_seeds(a.seeds):
        plain, focused, ms_plain, ms_focus = [], [], [], []
        for gray, mask in frames_with_masks(seed, a.frames):
            ys, xs = np.nonzero(mask)
            hull = cv2.convexHull(np.c_[xs, ys].astype(np.int32))[:, 0].astype(np.float64)
            for counts, times, focus in ((plain, ms_plain, []), (focused, ms_focus, [hull])):
                for _ in range(3):
                    t0 = time.process_time()
                    f = ex.extract(gray, focus=focus)
                    times.append(1e3 * (time.process_time() - t0))
                u = np.clip(np.rint(f.uv).astype(int), 0, [gray.shape[1] - 1, gray.shape[0] - 1])
                counts.append(int(mask[u[:, 1], u[:, 0]].sum()))
        print(f"seed {seed}: on-object keypoints of {a.features} {plain} (focus {focused}); "
              f"CPU ms/frame {np.median(ms_plain):.1f} (focus {np.median(ms_focus):.1f})", flush=True)
        rows.append({"seed": seed, "contrast": round(draw(seed).speckle_contrast, 3),
                     "on_object": float(np.median(plain)), "on_object_focus": float(np.median(focused)),
                     "cpu_ms": float(np.median(ms_plain)), "cpu_ms_focus": float(np.median(ms_focus))})

    def plot(plt):
        fig, ax = plt.subplots(figsize=(6, 3.4))
        x = np.arange(len(rows))
        ax.bar(x - 0.2, [r["on_object"] for r in rows], 0.4, label="even spread")
        ax.bar(x + 0.2, [r["on_object_focus"] for r in rows], 0.4, label="+ object focus")
        ax.set_xticks(x, [f"{r['seed']} ({r['contrast']:.2f})" for r in rows])
        ax.set_xlabel("development seed (texture contrast)")
        ax.set_ylabel(f"keypoints on the object (of {a.features})")
        ax.legend()
        fig.tight_layout()
        return fig

    cols = [("seed", "seed", "{}"), ("contrast", "texture contrast", "{:.2f}"),
            ("on_object", "keypoints on the object", "{:.0f}"), ("on_object_focus", "with focus", "{:.0f}"),
            ("cpu_ms", "CPU ms / frame", "{:.1f}"), ("cpu_ms_focus", "with focus", "{:.1f}")]
    save("orb_focus", rows, cols, "ORB keypoints on the object (development family scenes)",
         f"{a.features} features, median of {a.frames} frames per scene; the focus polygon is the convex hull of the "
         "object's true visible pixels (the tracker gives the hull of its projected model). CPU time: process time, "
         "one OpenCV thread, median of 3 calls per frame.", plot)


if __name__ == "__main__":
    main()
