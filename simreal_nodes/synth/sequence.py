"""Rendered sequences in memory (no bag): for tests and benchmarks; cached per process."""

from __future__ import annotations

import functools
from typing import Any

import numpy as np

from simreal_nodes import geometry as G
from simreal_nodes.render.gl import Renderer
from simreal_nodes.synth import world as W
from simreal_nodes.synth.makebag import load_models, make_scene, render_frame


@functools.cache
def sequence(name: str, width=640, height=480, duration=None, fps=30.0, stereo=False, seed=0, ssaa=2, frames=None):
    """dict(cam, gray[], rgb[], depth[] (noisy metres, NaN invalid), right[], T_map_cam[], truth[], scene).
    ``frames``: render only the first so many frames of the scene (its timing unchanged)."""
    import cv2

    sc = make_scene(name, width, height, duration, fps)
    models = load_models(sc)
    sc.state["models"] = models
    if "prepare" in sc.state:
        sc.state["prepare"](sc, models)
    cam = sc.camera
    if sc.stereo_baseline:
        from simreal_nodes.camera import CameraModel
        cam = sc.camera = CameraModel(cam.width, cam.height, cam.K.copy(), np.zeros(5))
    r = Renderer(cam, ssaa=ssaa)
    sc.build(sc, r, models)
    rng = np.random.default_rng(seed)
    out: dict[str, Any] = {"cam": cam, "gray": [], "rgb": [], "depth": [], "right": [], "T": [], "truth": [],
                           "scene": sc}
    T_mw = sc.T_map_world()
    n = round(sc.duration * sc.fps)
    for i in range(n if frames is None else min(n, int(frames))):
        t = i / sc.fps
        truth = sc.update(sc, r, t)
        T = sc.camera_pose(t)
        rgb, d = render_frame(sc, r, t, T)
        rgb = W.pixel_noise(rgb, sc.pixel_sigma, rng)
        out["rgb"].append(rgb)
        out["gray"].append(cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY))
        dn = W.kinect_depth(d, rng) if sc.depth else d
        out["depth"].append(np.where(dn > 0, dn, np.nan).astype(np.float32))
        if stereo and sc.stereo_baseline:
            rr, _ = render_frame(sc, r, t, T, G.make_T(t=[sc.stereo_baseline, 0, 0]))
            out["right"].append(cv2.cvtColor(W.pixel_noise(rr, sc.pixel_sigma, rng), cv2.COLOR_RGB2GRAY))
        out["T"].append(T_mw @ T)
        out["truth"].append(truth)
    r.release()
    return out
