"""A camera circling a car in a car park (thesis §6.3.1: the capture of a car's shape), rendered with its truth.

The car is a :class:`~simreal_nodes.aero.cars.CarShape` standing in the world frame of :mod:`simreal_nodes.aero.grid`
(nose at x = 0, centre plane y = 0, floor z = 0; the body floats at its clearance: the family has no wheels). Around
it: a gravel floor, concrete-like pillars about 9 m out and brick walls about 15 m out (what a car park gives a
feature-based SLAM to hold on to). The camera is hand-held at ``eye_height_m``, ``radius_m`` from the car's centre,
looking at the body, once around (``turns``), easing in and out (a monocular map needs its first frames' parallax to
grow slowly). Colour at ``fps`` with pixel noise; depth (RGB-D) with a structured-light noise model out to 8 m (at 5 m
its sigma is about 4 cm: the car's far side is noisier than its near side).

Nothing here is read by the capture: the estimators see the images (and depth); the truth (the car, the camera path)
is for scoring. The car's body is textured (a painted car's reflections, badges and seams give ORB less than this;
said in docs/aero.md).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from simreal_nodes import geometry as G
from simreal_nodes.aero.cars import CarShape
from simreal_nodes.render.gl import Mesh, Renderer
from simreal_nodes.synth import world as W
from simreal_nodes.synth.scenes import SynthScene, Truth, _camera_yaml, default_camera

SUN = (0.3, 0.0, -1.0)  # the light's direction (world): from above, a little from the front; the sides lit alike
DEPTH_RANGE_M = 8.0  # the depth camera's far limit (Kinect-like noise beyond 5 m is several centimetres)
DEFAULT_DATABASE = Path(__file__).resolve().parents[2] / "cache" / "aero" / "aero_cars.h5"


def car_centre(car: CarShape) -> np.ndarray:
    """The point the camera looks at: mid-length, on the centre plane, at about half the body's height."""
    return np.array([0.5 * car.length, 0.0, car.clearance + 0.5 * (car.height - car.clearance)])


def car_park(r: Renderer, car: CarShape, seed: int = 0) -> None:
    """Floor, pillars, walls and the textured car (mesh ``car``)."""
    cx = 0.5 * car.length
    V, F = W.box((40.0, 40.0, 0.1), (cx, 0.0, -0.05))
    r.add(Mesh("floor", V, F, mode="texture", texture=W.texture("gravel"), tex_scale=0.6, smooth=False))
    for k, (dx, dy) in enumerate(((15.0, 0.0), (-15.0, 0.0), (0.0, 15.0), (0.0, -15.0))):
        size = (0.3, 30.0, 4.0) if dx else (30.0, 0.3, 4.0)
        V, F = W.box(size, (cx + dx, dy, 2.0))
        r.add(Mesh(f"wall{k}", V, F, mode="texture", texture=W.texture("brick"), tex_scale=0.8, smooth=False))
    rng = np.random.default_rng(seed)
    for k in range(10):
        a = 2 * np.pi * (k + rng.uniform(-0.2, 0.2)) / 10
        rad = rng.uniform(8.5, 10.0)
        V, F = W.box((0.5, 0.5, 3.0), (0.0, 0.0, 1.5))
        tex = ["gravel", "probe", "wood", "grass"][k % 4]
        r.add(Mesh(f"pillar{k}", V, F, mode="texture", texture=W.texture(tex), tex_scale=1.5, smooth=False,
                   pose=G.make_T(G.rot_axis("z", rng.uniform(0, np.pi)), (cx + rad * np.cos(a), rad * np.sin(a), 0))))
    V, F = car.surface()
    # the texture's coordinates sheared across the car: without it the two sides (triplanar on x, z) would carry the
    # same pattern at the same place, and a map point of one side matches the other side seen through the body
    ref = V + np.outer(V[:, 1], [1.7, 0.0, 0.0])
    r.add(Mesh("car", V, F, mode="texture", texture=W.texture("lever"), tex_scale=0.7, tint=(0.95, 0.45, 0.35),
               ref=ref, smooth=True))


def circle_pose(car: CarShape, t: float, duration: float, radius_m: float, eye_height_m: float, turns: float,
                az0: float, seed: int) -> np.ndarray:
    """T_world_cam at ``t``: around the car's centre ``turns`` times from azimuth ``az0``, easing in and out."""
    c = car_centre(car)
    ph = 0.5 - 0.5 * np.cos(np.pi * min(max(t / duration, 0.0), 1.0))
    az = az0 + 2 * np.pi * turns * ph
    jitter = W.smooth_noise(np.array([t]), 0.02, seed)[0]
    eye = np.array([c[0] + radius_m * np.cos(az), radius_m * np.sin(az), eye_height_m]) + jitter
    look = c + W.smooth_noise(np.array([t]), 0.05, seed + 1)[0]
    return G.look_at(eye, look)


def car_scene(car: CarShape, name: str = "car_aero", width: int = 640, height: int = 480, duration: float = 24.0,
              fps: float = 15.0, sensor: str = "rgbd", radius_m: float = 5.5, eye_height_m: float = 2.0,
              turns: float = 1.0, az0: float = -np.pi / 2, seed: int = 0,
              database: str | Path | None = None) -> SynthScene:
    """The scene: ``sensor`` "rgbd" (colour + depth) or "mono" (colour only); ``seed`` picks the pillars and the
    hand's jitter; ``database``: the aero database its scene file names (the graph then captures the car and draws
    its flow; None: a SLAM-only scene file)."""
    if sensor not in ("rgbd", "mono"):
        raise ValueError(f"car scene sensor must be rgbd or mono, not '{sensor}'")

    def build(sc, r, models):
        car_park(r, car, seed)

    def update(sc, r, t):
        return Truth()

    def cam_pose(t):
        return circle_pose(car, t, duration, radius_m, eye_height_m, turns, az0, seed + 11)

    def yaml(sc):
        aero = {"enabled": True, "database": str(database)} if database else {"enabled": False}
        if database and sensor == "mono":
            aero["length_m"] = round(car.length, 3)  # what the user measures (tape or spec sheet): the scale
        return {"simreal_scene": 1, "name": name,
                "description": f"A camera circling a car ({car.group}) in a car park: its shape captured from the "
                               "SLAM map, its flow from the aero database drawn over the video (ch. 6).",
                "camera": _camera_yaml(sc), "localization": {"mode": sensor, "features": 1000},
                "overlay": {"enabled": bool(database)}, "aero": aero}

    return SynthScene(name, f"camera circling the car {car.name}", default_camera(width, height), fps, duration, {},
                      build, update, cam_pose, yaml, depth=sensor == "rgbd",
                      render_kw={"near": 0.1, "far": 60.0, "light": SUN}, depth_range_m=DEPTH_RANGE_M)


def car_aero_scene(sensor: str = "rgbd", width: int = 640, height: int = 480, fps: float = 30.0,
                   duration: float | None = None) -> SynthScene:
    """``simreal make-bag car_aero[-mono]``: the first held-out car of ``aero_cars.yaml`` (its CFD solution, stored in
    the database beside the others, is the flow's truth; the manifold never saw it), circled once in 24 s. The scene
    file names the database at its default place (``cache/aero/aero_cars.h5``: ``./run bench aero`` or
    ``simreal build-aero-db aero_cars.yaml -o cache/aero/aero_cars.h5`` builds it)."""
    from simreal_nodes.aero.database import load_aero_spec

    spec = load_aero_spec("aero_cars.yaml")
    car = spec.cars()[spec.n_database]
    return car_scene(car, "car_aero" if sensor == "rgbd" else "car_aero_mono", width, height,
                     duration=duration or 24.0, fps=fps, sensor=sensor, database=DEFAULT_DATABASE)


def render_car_video(sc: SynthScene, car: CarShape, seed: int = 0, ssaa: int = 2):
    """Yield (t, T_world_cam, rgb uint8, depth metres or None) for every frame: colour with pixel noise, depth (RGB-D
    scenes) with the structured-light noise model out to :data:`DEPTH_RANGE_M`. Deterministic for a seed."""
    r = Renderer(sc.camera, ssaa=ssaa, **sc.render_kw)
    try:
        sc.build(sc, r, {})
        rng = np.random.default_rng(seed)
        for i in range(round(sc.duration * sc.fps)):
            t = i / sc.fps
            T = sc.camera_pose(t)
            rgb, depth = r.render(T)
            rgb = W.pixel_noise(rgb, sc.pixel_sigma, rng)
            d = W.kinect_depth(depth, rng, max_range=sc.depth_range_m) if sc.depth else None
            yield t, T, rgb, d
    finally:
        r.release()
