"""Rendered sequences in memory (no bag): for tests and benchmarks; cached per process."""

from __future__ import annotations

import functools
from typing import Any

import numpy as np

from simreal_nodes import geometry as G
from simreal_nodes.render.gl import Renderer
from simreal_nodes.synth import world as W
from simreal_nodes.synth.makebag import load_models, make_scene, render_frame


class FrameStream:
    """The frames of a rendered scene one at a time, for a sequence too long to hold (2 000 frames of 640 x 480 RGB-D
    are about 5 GB): ``cam``, ``scene`` and ``n`` (frames) at once, then iterate for dicts of ``gray``, ``rgb``,
    ``depth`` (noisy metres, NaN invalid), ``right`` (None without ``stereo``), ``T`` (map <- camera), ``truth``.
    The same frames, noise included, as :func:`sequence` with the same arguments. Iterate once."""

    def __init__(self, name: str, width=640, height=480, duration=None, fps=30.0, stereo=False, seed=0, ssaa=2,
                 frames=None):
        sc = make_scene(name, width, height, duration, fps)
        models = load_models(sc)
        sc.state["models"] = models
        if "prepare" in sc.state:
            sc.state["prepare"](sc, models)
        cam = sc.camera
        if sc.stereo_baseline:
            from simreal_nodes.camera import CameraModel
            cam = sc.camera = CameraModel(cam.width, cam.height, cam.K.copy(), np.zeros(5))
        self.cam, self.scene, self.stereo, self.seed, self.ssaa = cam, sc, stereo, seed, ssaa
        n = round(sc.duration * sc.fps)
        self.n = n if frames is None else min(n, int(frames))
        self._models = models
        self._used = False

    def __iter__(self):
        import cv2

        if self._used:  # the scene's state (loads, probe positions) has moved on: render a new stream instead
            raise RuntimeError("a FrameStream is iterated once; make a new one to render the frames again")
        self._used = True
        sc = self.scene
        r = Renderer(self.cam, ssaa=self.ssaa)
        try:
            sc.build(sc, r, self._models)
            rng = np.random.default_rng(self.seed)
            T_mw = sc.T_map_world()
            for i in range(self.n):
                t = i / sc.fps
                truth = sc.update(sc, r, t)
                T = sc.camera_pose(t)
                rgb, d = render_frame(sc, r, t, T)
                rgb = W.pixel_noise(rgb, sc.pixel_sigma, rng)
                dn = W.kinect_depth(d, rng) if sc.depth else d
                right = None
                if self.stereo and sc.stereo_baseline:
                    rr, _ = render_frame(sc, r, t, T, G.make_T(t=[sc.stereo_baseline, 0, 0]))
                    right = cv2.cvtColor(W.pixel_noise(rr, sc.pixel_sigma, rng), cv2.COLOR_RGB2GRAY)
                yield {"rgb": rgb, "gray": cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY),
                       "depth": np.where(dn > 0, dn, np.nan).astype(np.float32), "right": right, "T": T_mw @ T,
                       "truth": truth}
        finally:
            r.release()


@functools.cache
def sequence(name: str, width=640, height=480, duration=None, fps=30.0, stereo=False, seed=0, ssaa=2, frames=None):
    """dict(cam, gray[], rgb[], depth[] (noisy metres, NaN invalid), right[], T_map_cam[], truth[], scene).
    ``frames``: render only the first so many frames of the scene (its timing unchanged)."""
    fs = FrameStream(name, width, height, duration, fps, stereo, seed, ssaa, frames)
    out: dict[str, Any] = {"cam": fs.cam, "gray": [], "rgb": [], "depth": [], "right": [], "T": [], "truth": [],
                           "scene": fs.scene}
    for f in fs:
        for k in ("rgb", "gray", "depth", "T", "truth"):
            out[k].append(f[k])
        if f["right"] is not None:
            out["right"].append(f["right"])
    return out
