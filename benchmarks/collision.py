"""Collision from depth (issue 7, thesis Alg. 5.1, §5.2.4): contact-detection error and time per frame versus the
depth decimation step, at 640 x 480 and 1280 x 720, on the rendered probe scene (a real probe pushing the virtual
crossed beams; the estimator sees the noisy Kinect-like depth, the truth is Alg. 5.1 on the probe's exact visible
surface).

    ./run bench collision

Per frame: depth_points (decimated back-projection into the map with the true camera pose: the localization's
error is measured elsewhere) + ContactTracker.update (KD-tree nearest real point to the contact nodes,
pseudo-time state machine). Agreement: contact yes/no equal to the truth; same load point: among frames both
call contact; pseudo-time: median |error|.
"""

from __future__ import annotations

import time

import numpy as np

from benchmarks.common import save
from simreal_nodes import geometry as G
from simreal_nodes.collision.contact import ContactTracker
from simreal_nodes.rom.model_file import load_model
from simreal_nodes.scene.schema import build_spec_models, validate_scene
from simreal_nodes.synth.sequence import sequence
from simreal_nodes.vision.depth import depth_points

STEPS = (1, 2, 4, 8, 16)


def run(seq, scene, step: int) -> dict:
    o = scene["objects"][0]
    c = o["collision"]
    m = load_model(o["model"], fields=["displacement"])
    tr = ContactTracker(m, G.pose7_to_matrix(o["anchor"]["pose"]), threshold=c["threshold_m"], step=c["step"])
    agree, both, same, dtau, times, npts = 0, 0, 0, [], [], []
    for i, depth in enumerate(seq["depth"]):
        t0 = time.perf_counter()
        dp = depth_points(depth, seq["cam"], step, seq["T"][i], max_depth=c["max_depth_m"])
        st = tr.update(dp.points)
        times.append(time.perf_counter() - t0)
        npts.append(len(dp.points))
        truth = seq["truth"][i].contacts[o["id"]]
        agree += st.in_contact == truth.in_contact
        if st.in_contact and truth.in_contact:
            both += 1
            same += st.load_point == truth.load_point
        dtau.append(abs(st.pseudo_time - truth.pseudo_time))
    n = len(seq["depth"])
    return dict(step=step, points=int(np.median(npts)), agree_pct=100 * agree / n,
                same_load_point_pct=100 * same / both if both else float("nan"), tau_err=float(np.median(dtau)),
                tau_err_max=float(np.max(dtau)), ms=1e3 * float(np.median(times)),
                p95_ms=1e3 * float(np.percentile(times, 95)))


def main():
    rows = []
    for w, h in ((640, 480), (1280, 720)):
        seq = sequence("crossed_beams_probe", w, h)
        scene = build_spec_models(validate_scene(seq["scene"].scene_yaml(seq["scene"]), "crossed_beams_probe", "."))
        for s in STEPS:
            r = dict(resolution=f"{w}x{h}", **run(seq, scene, s))
            rows.append(r)
            print(r, flush=True)
        del seq

    def plot(plt):
        fig, ax = plt.subplots(1, 2, figsize=(11, 3.8))
        for res, mk in (("640x480", "o-"), ("1280x720", "s--")):
            rr = [r for r in rows if r["resolution"] == res]
            ax[0].plot([r["step"] for r in rr], [r["agree_pct"] for r in rr], mk, label=f"{res} contact agreement")
            ax[0].plot([r["step"] for r in rr], [r["same_load_point_pct"] for r in rr], mk, alpha=0.5,
                       label=f"{res} same load point")
            ax[1].plot([r["step"] for r in rr], [r["ms"] for r in rr], mk, label=res)
        for a in ax:
            a.set_xscale("log", base=2)
            a.set_xlabel("decimation step (every N-th pixel per direction)")
        ax[0].set_ylabel("% of frames")
        ax[1].set_ylabel("depth -> contact per frame (ms)")
        ax[0].legend(fontsize=7)
        ax[1].legend(fontsize=7)
        fig.tight_layout()
        return fig

    save("collision", rows, [("resolution", "resolution", "{}"), ("step", "decimation", "{}"),
                             ("points", "depth points", "{}"), ("agree_pct", "contact agrees (%)", "{:.0f}"),
                             ("same_load_point_pct", "same load point (%)", "{:.0f}"),
                             ("tau_err", "pseudo-time err (median)", "{:.3f}"), ("tau_err_max", "max", "{:.2f}"),
                             ("ms", "time (ms)", "{:.2f}"), ("p95_ms", "p95 (ms)", "{:.2f}")],
         "Collision from depth: contact error and time versus decimation (crossed beams + probe)",
         "Contact against the exact Alg. 5.1 truth; true camera pose. Finer sampling finds the contact on more frames "
         "and tracks the pseudo-time better, but with more than ~20 000 points per frame the first depth point under "
         "delta is a noise point one frame early, at the neighbouring load point (22 mm away), which is then held for "
         "the whole press (one contact at a time, §5.2.4): 'same load point' falls to 0. Every 4th pixel at 640x480 "
         "(8th at 1280x720) gets both right. Time: back-projection of the decimated depth + the KD-tree on the points "
         "inside the object's box grown by delta.", plot)


if __name__ == "__main__":
    main()
