"""Overlay speed and the live mode choice: time per composed frame (deformed mesh from the PGD model,
colour map, occlusion against real depth, colour bar, over a camera image) versus resolution and mesh
size, and the number of modes the overlay picks to keep the on-screen truncation error below 0.5 px
versus viewing distance.

    ./run bench overlay
"""

from __future__ import annotations

import time

import numpy as np

from benchmarks.common import save
from simreal_nodes import geometry as G
from simreal_nodes.render.overlay import ObjectOverlay, OverlayCompositor
from simreal_nodes.rom.build import cached_model
from simreal_nodes.rom.model_file import load_model
from simreal_nodes.synth.scenes import default_camera


def _view(d):
    return G.make_T(G.rot_axis("x", np.pi), [0.25, 0.0, 0.1 + d])


def _framing_view(m, T_obj, cam, fill=0.6):
    """A view from above and in front in which the object spans ``fill`` of the image width."""
    lo, hi = m.points.min(axis=0), m.points.max(axis=0)
    c = G.transform(T_obj, (lo + hi)[None] / 2)[0]
    d = float(np.max(hi - lo)) * cam.fx / (fill * cam.width)
    return G.look_at(c + d * np.array([0.3, -0.55, 0.78]) / np.linalg.norm([0.3, -0.55, 0.78]), c)


HISTORY = ("History of the aluminium beam, displacement, p50 at 640x480 / 1280x720: 17.2 / 41.2 ms with CPU remaps "
           "of the whole frame; 17.3 / 37.9 ms with the whole frame composited on the GPU; 7.5 / 15.5 ms drawing "
           "and reading back only the screen box; about 5.3 / 12.8 ms with back faces culled and the mode "
           "choice vectorised (run-to-run spread on this shared 2-core machine: about +-1.5 ms). ")
LABELS = {"aluminium_beam": "aluminium beam", "crossed_beams": "crossed beam", "bunny": "bunny", "dragon": "dragon",
          "joint_boot": "joint boot"}


def main():
    import argparse

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--models", default="crossed_beams,bunny,dragon",
                    help="models besides the aluminium beam, comma-separated (the bunny and the dragon are built on "
                         "first use: minutes)")
    ap.add_argument("--out", default="overlay", help="the result's name (e.g. overlay_gpu for a run on a GPU)")
    a = ap.parse_args()
    rows = []
    beam = load_model(cached_model("aluminium_beam"), fields=["displacement", "stress"])
    models = [("aluminium beam", beam)]
    # meshes from 624 to ~10^4 surface triangles
    for spec in filter(None, a.models.split(",")):
        label = LABELS.get(spec, spec)
        try:
            models.append((label, load_model(cached_model(spec), fields=["displacement", "stress"])))
        except Exception as e:  # noqa: BLE001
            print(f"{label} model unavailable: {e}")
    gl = ""
    for res in ((640, 480), (1280, 720)):
        cam = default_camera(*res)
        rng = np.random.default_rng(0)
        img = rng.integers(0, 255, (cam.height, cam.width, 3), dtype=np.uint8)
        depth = np.full((cam.height, cam.width), 0.55, np.float32)
        depth[:, : cam.width // 3] = 0.4  # a closer real object hides a third of the view
        for label, m in models:
            for field in ("displacement", "von_mises"):
                is_beam = "beam" in label
                T_obj = G.make_T(t=[0, 0, 0.1])
                ob = ObjectOverlay(m, T_obj, field, magnify=10.0 if is_beam else 1.0)
                view = _view(0.45) if is_beam else _framing_view(m, T_obj, cam)
                comp = OverlayCompositor(cam, {"o": ob})
                gl = comp.renderer.gl_renderer
                mu_names = [a.name for a in m.axes]
                ts, modes = [], []
                for k in range(40):
                    vals = [a.values[(k * 7) % len(a.values)] for a in m.axes]
                    t0 = time.perf_counter()
                    _, st = comp.compose(img, view, {"o": (mu_names, vals)}, depth)
                    ts.append((time.perf_counter() - t0) * 1e3)
                    modes.append(st["o"].modes)
                comp.release()
                ts = np.asarray(ts[5:])
                rows.append({"resolution": f"{res[0]}x{res[1]}", "object": label, "triangles": len(m.surface),
                             "field": field, "p50_ms": float(np.median(ts)), "p95_ms": float(np.percentile(ts, 95)),
                             "modes_median": float(np.median(modes)), "model_modes": m.field("displacement").n_modes})
    # live mode choice versus distance (aluminium beam, 640x480)
    cam = default_camera()
    ob = ObjectOverlay(beam, G.make_T(t=[0, 0, 0.1]), "displacement", magnify=1.0)
    dist_rows = []
    for d in (0.2, 0.35, 0.5, 1.0, 2.0, 4.0):
        ms = [ob.geometry(["s"], [s], _view(d), cam)[2].modes for s in np.linspace(0.05, 0.48, 12)]
        dist_rows.append({"distance_m": d, "modes_mean": float(np.mean(ms)), "modes_max": int(np.max(ms))})

    def plot(plt):
        fig, axs = plt.subplots(1, 2, figsize=(11, 4))
        for res in ("640x480", "1280x720"):
            sel = [r for r in rows if r["resolution"] == res and r["field"] == "displacement"]
            axs[0].plot([r["triangles"] for r in sel], [r["p50_ms"] for r in sel], "o-", label=res)
        axs[0].axhline(5.0, color="k", ls="--", lw=0.8, label="target 5 ms")
        axs[0].set_xlabel("surface triangles")
        axs[0].set_ylabel("overlay p50 [ms/frame]")
        axs[0].legend()
        axs[0].set_title(gl[:40])
        axs[1].plot([r["distance_m"] for r in dist_rows], [r["modes_mean"] for r in dist_rows], "o-")
        axs[1].set_xscale("log")
        axs[1].set_xlabel("camera distance [m]")
        axs[1].set_ylabel("modes drawn (mean over s), 0.5 px bound")
        return fig

    notes = (f"OpenGL: {gl}. Each frame: PGD evaluation on the surface nodes with the live mode choice, colour map, "
             "upload (indexed, per-vertex attributes), draw with occlusion against a real depth image (a third of the "
             "view hidden by a closer surface), blend over the camera image, colour bar. Only the object's screen box "
             "is drawn, read back and blended (the projection of its vertices; with lens distortion its camera pixels "
             "look the patch up through the distortion map), and the closed surface is drawn without its back faces. "
             + HISTORY * (a.out == "overlay") +
             "Modes drawn versus distance (aluminium beam, magnification 1, 640x480): " +
             ", ".join(f"{r['distance_m']} m: {r['modes_mean']:.1f} (max {r['modes_max']})" for r in dist_rows) + ".")
    save(a.out, rows, [("resolution", "resolution", "{}"), ("object", "object", "{}"),
                       ("triangles", "triangles", "{}"), ("field", "colour", "{}"), ("p50_ms", "p50 ms", "{:.2f}"),
                       ("p95_ms", "p95 ms", "{:.2f}"),
                       ("modes_median", "modes drawn", "{:.0f}"), ("model_modes", "model modes", "{}")],
         "Overlay time per frame and modes drawn", notes, plot, extra={"distance": dist_rows})


if __name__ == "__main__":
    main()
