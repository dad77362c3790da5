"""Renderer speed: time per frame (draw + read back colour and metric depth) versus triangle count and
resolution, for the shading modes the project uses (vertex colours: the overlay; triplanar texture:
synthetic scenes), with and without supersampling.

    ./run bench render
"""

from __future__ import annotations

import time

import numpy as np

from benchmarks.common import save
from simreal_nodes import geometry as G
from simreal_nodes.camera import CameraModel
from simreal_nodes.render.gl import Mesh, Renderer
from simreal_nodes.synth import world as W


def sphere_with(n_tri_target):
    n = max(4, int(np.sqrt(n_tri_target / 4)))
    return W.sphere(0.25, n)


def main():
    rows = []
    gl_name = ""
    for w, h in ((640, 480), (1280, 720)):
        cam = CameraModel.from_intrinsics(w, h, 0.82 * w, 0.82 * w, (w - 1) / 2, (h - 1) / 2)
        for target in (1_000, 10_000, 100_000, 1_000_000):
            V, F = sphere_with(target)
            for mode in ("vertex", "texture"):
                for ssaa in (1, 2):
                    if ssaa == 2 and (w > 640 or mode == "vertex"):
                        continue
                    r = Renderer(cam, ssaa=ssaa)
                    gl_name = r.gl_renderer
                    cols = (V - V.min(0)) / np.ptp(V, axis=0)
                    r.add(Mesh("s", V, F, mode=mode, colors=cols,
                               texture=W.texture("gravel") if mode == "texture" else None,
                               tex_scale=4.0, pose=G.make_T(t=[0, 0, 0.8])))
                    for _ in range(3):
                        r.render(np.eye(4))
                    n = 20 if len(F) < 200_000 else 5
                    t = time.perf_counter()
                    for k in range(n):
                        r.update("s", vertices=V * (1 + 0.01 * np.sin(k)))  # deformable: upload every frame
                        r.render(np.eye(4))
                    ms = (time.perf_counter() - t) / n * 1e3
                    t = time.perf_counter()
                    for _ in range(n):
                        r.render(np.eye(4))
                    ms_static = (time.perf_counter() - t) / n * 1e3
                    rows.append({"resolution": f"{w}x{h}", "triangles": len(F), "mode": mode, "ssaa": ssaa,
                                 "ms_deforming": ms, "ms_static": ms_static})
                    r.release()
    cols = [("resolution", "resolution", "{}"), ("triangles", "triangles", "{}"), ("mode", "shading", "{}"),
            ("ssaa", "supersampling", "{}"), ("ms_static", "ms / frame (static mesh)", "{:.1f}"),
            ("ms_deforming", "ms / frame (vertices uploaded)", "{:.1f}")]

    def plot(plt):
        fig, ax = plt.subplots(figsize=(7, 4.2))
        for res in ("640x480", "1280x720"):
            for mode in ("vertex", "texture"):
                sel = [r for r in rows if r["resolution"] == res and r["mode"] == mode and r["ssaa"] == 1]
                ax.loglog([r["triangles"] for r in sel], [r["ms_deforming"] for r in sel], "o-", label=f"{res} {mode}")
        ax.set_xlabel("triangles")
        ax.set_ylabel("ms per frame (draw + read back colour and depth)")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
        return fig

    save("render", rows, cols, f"Renderer time per frame ({gl_name})",
         "One camera, colour + metric depth render targets, read back to numpy. 'deforming' re-uploads all vertex "
         "attributes every frame (what a deforming object costs).", plot)


if __name__ == "__main__":
    main()
