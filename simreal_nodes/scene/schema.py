"""The scene file: which camera inputs exist, how the camera is localized, which objects are
modelled and what each of them does (tracked parameters, collision, overlay).

``load_scene(path)`` validates the YAML and returns a plain dict with every default filled in.
docs/scene-format.md is the reference for users; this module is the executable version of it.

A model given as ``spec:NAME`` is not built by validation (checking a scene stays cheap): the spec is read and
``objects[].model`` becomes the path its model has in the cache. Whatever starts nodes or runs a pipeline on the
scene calls :func:`build_spec_models` first; the nodes, which validate the same file again, then find the file.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import yaml

from simreal_nodes.errors import SceneError
from simreal_nodes.spec import Bool, Context, Enum, FilePath, ListOf, MapOf, Number, Record, Str, Topic, Vector

SPEC_PREFIX = "spec:"


class ModelRef(FilePath):
    """A model file path, or ``spec:NAME`` (a built-in spec, or a spec file), kept as written here:
    :func:`_resolve_model_ref` turns it into the model's cache path once the object record is complete."""

    def check(self, v: object, path: str, ctx: Context) -> Any:
        if isinstance(v, str) and v.startswith(SPEC_PREFIX):
            return v
        return super().check(v, path, ctx)


SCENE_FORMAT = 1
# keyword arguments of a Str that holds an identifier (Any: Str takes each with its own type)
IDENT: dict[str, Any] = dict(pattern=lambda s: s.replace("_", "a").isalnum() and s[:1].isalpha(),
                             what="an identifier (letters, digits, '_', starting with a letter)")
POSE7 = "a pose [x, y, z, qx, qy, qz, qw] (metres, unit quaternion)"

CAMERA = Record({
    "image": Topic("colour or grey image topic", default="/camera/image_raw"),
    "camera_info": Topic("CameraInfo of the image", default="/camera/camera_info"),
    "depth": Topic("depth image (16UC1 mm or 32FC1 m), registered to the colour image unless "
                   "depth_camera_info says otherwise", nullable=True),
    "depth_camera_info": Topic("CameraInfo of the depth images' own camera, when they are not registered to the "
                               "colour image (a depth camera beside the colour one, e.g. RealSense without "
                               "align_depth): with depth_to_color the ingest registers them", nullable=True),
    "depth_to_color": Vector(7, what=POSE7, doc="the depth camera's optical frame in the colour camera's optical "
                             "frame (what a driver publishes on /tf_static between the two)", nullable=True),
    "right_image": Topic("right image of a stereo pair (see stereo_input)", nullable=True),
    "right_camera_info": Topic("CameraInfo of the right camera", nullable=True),
    "stereo_input": Enum(("rectified", "raw", "image_rect"), "rectified: the pair's images are rectified and "
                         "each CameraInfo describes them (R the identity, no distortion, K = P's 3 x 3; a raw one is "
                         "refused with its reason). raw: a driver's raw images, rectified in the ingest node from "
                         "their CameraInfos' lens, R and P, as ROS's stereo_image_proc does. image_rect: rectified "
                         "images beside the raw cameras' CameraInfo (ROS's image_rect topics): the ingest publishes "
                         "the rectified cameras, read from P", default="rectified"),
    "stereo_min_depth_m": Number("stereo: the nearest depth the dense matching (SGBM) searches, metres; a nearer "
                                 "limit widens the disparity range and costs time", lo=0.05, default=0.4),
    "calibration": FilePath("ROS calibration YAML that overrides CameraInfo", nullable=True),
    "undistort": Bool("undistort images in the ingest node", default=False),
    "compressed": Bool("images arrive as sensor_msgs/CompressedImage on <image>/compressed (image_transport)",
                       default=False),
    "source": Enum(("topic", "bag", "video", "images"), "where the ingest node reads frames", default="topic"),
    "path": FilePath("bag, video file or image folder for non-topic sources", nullable=True),
    "rate_hz": Number("publishing rate for video / image-folder sources", lo=0, lo_open=True, default=30.0),
    "loop": Bool("restart a bag / video / folder source at its end", default=False),
    "ingest": Enum(("auto", "always"), "auto: the ingest node starts only when it has work (a file source, "
                   "compressed images, undistortion, a stereo pair read through its R and P, depth to register, a "
                   "calibration file) or is the scene's only node; otherwise the nodes read the camera topics "
                   "themselves, one hop less per frame. always: every frame goes through the ingest (its "
                   "/diagnostics name each frame it refuses)", default="auto"),
})

MARKERS = Record({
    "dictionary": Str("OpenCV ArUco / AprilTag dictionary name, e.g. DICT_4X4_50", default="DICT_4X4_50"),
    "size_m": Number("marker side length, metres", lo=0, lo_open=True, default=0.05),
    "poses": MapOf(Vector(7, what=POSE7), key=Number(integer=True, lo=0),
                   doc="marker id -> pose of its centre in the map frame", default={}),
    "max_std_pct": Number("refuse a pose whose camera position the markers hold more loosely than this share of the "
                          "distance to them (standard deviation at the corners' reprojection rms, at least 0.5 px; "
                          "%; 0: never refuse). One or two small markers in a blurred image read centimetres off "
                          "without it (benchmarks/marker_quality.py)", lo=0, default=2.5),
    "corner_refinement": Enum(("edges", "subpix"), "edges: each corner where lines fitted to the marker's sides' "
                              "edges meet (holds under blur); subpix: OpenCV's corner search, which blur pulls "
                              "inward (benchmarks/marker_quality.py)", default="edges"),
    "detect_scale": Number("share of the image's size the marker detector runs on with the edges' refinement (area "
                           "averaged; the corners are refined in the full image, and a marker of the layout the pose "
                           "puts in view but the reduced image missed is looked for in the full image round where it "
                           "should be); 1: the full image; subpix always detects in the full image "
                           "(benchmarks/marker_quality.py)", lo=0, lo_open=True, hi=1, default=0.5),
})

LOCALIZATION = Record({
    "mode": Enum(("markers", "mono", "rgbd", "stereo", "static"), "how the camera pose is found", default="static"),
    "features": Number("ORB features per frame", integer=True, lo=50, hi=20000, default=1000),
    "pyramid_levels": Number("ORB scale pyramid levels", integer=True, lo=1, hi=16, default=8),
    "scale_factor": Number("ORB pyramid scale factor", lo=1.0, lo_open=True, hi=2.0, default=1.2),
    "markers": MARKERS,
    "static_pose": Vector(7, what=POSE7, doc="camera pose in the map for mode 'static'", nullable=True),
    "map_file": FilePath("load a saved map (HDF5) at start", nullable=True),
    "localization_only": Bool("start with mapping frozen", default=False),
    "freeze_map_on_deformation": Bool("stop mapping once a tracked object deforms (thesis §4.4.1). Off: mapping goes "
                                      "on, points on the object never vote for the pose and new ones are linked in the "
                                      "estimated deformed shape (measured more accurate: docs/tracking.md)",
                                      default=False),
    "known_scale_m": Number("monocular: distance between the first two keyframes, metres", lo=0, lo_open=True,
                            nullable=True),
    "loop_closing": Bool("SLAM: search each new keyframe for a loop and correct the map (Sim3, essential graph, "
                         "global BA; docs/localization.md). Off by default: measured on one rendered scene only",
                         default=False),
})

PARAMETER = Record({
    "mode": Enum(("tracked", "constant", "fixed"), "tracked: estimated every frame; constant: estimated over the "
                 "first deformed frames then frozen; fixed: held at 'value'", default="tracked"),
    "initial": Number("starting value (model units)", nullable=True),
    "value": Number("value for mode 'fixed' (model units)", nullable=True),
})

ANCHOR = Record({
    "kind": Enum(("pose", "registration"), "pose: given below; registration: found from the first depth images "
                 "(support plane by RANSAC, then ICP of the model surface), starting from 'guess'", default="pose"),
    "pose": Vector(7, what=POSE7, doc="object frame in the map frame", default=[0, 0, 0, 0, 0, 0, 1]),
    "guess": Vector(7, what=POSE7, doc="registration: the object frame in the map frame (the first camera frame) "
                    "as judged by eye, centimetres and some degrees off; it picks between mirror-image fits of a "
                    "symmetric object", nullable=True),
    "fine": Enum(("auto", "full", "upright"), "registration: the fine stage's freedom: full (6 degrees), upright "
                 "(translation and a turn about the object's z axis; roll and pitch from the support plane: an object "
                 "standing on it) or auto (upright for depth from a stereo pair, else full)", default="auto"),
    "polish_mm": Number("registration: > 0: the fit is also refined from starts this far away along each object "
                        "axis and the one most faces meet within 2 mm kept (a ridged surface, the joint boot's "
                        "bellows, can hold the fine stage a ridge away; the fit of an object registered loaded "
                        "too; 0: off)", lo=0, hi=50, default=0),
})

TRACKING = Record({
    "enabled": Bool("estimate the tracked parameters from the images", default=False),
    "measurements": Enum(("map_points", "dots", "homography", "dense"), "what gives the image measurements: map "
                         "points on the object (sparse), glued dots, dots on a face through a homography, or dense "
                         "photometric alignment of the object's own texture against a first view at rest (the "
                         "default: it did best on the development scene family, docs/family.md)",
                         default="dense"),
    "dense_step_px": Number("measurements 'dense': surface sample spacing in the reference view, pixels (smaller: "
                            "more samples, slower)", lo=0.5, hi=16, default=1.5),
    "dense_rigid": Bool("measurements 'dense': also fit a small rigid correction of the object each frame (absorbs "
                        "camera-pose drift and the anchor's error)", default=True),
    "dense_surroundings_px": Number("measurements 'dense' with a depth image: width of the ring of static "
                                    "surroundings around the object's outline (reference view, pixels) that "
                                    "measures the camera's error apart from the object's bending; 0: off",
                                    lo=0, hi=200, default=32.0),
    "dense_refine": Bool("measurements 'dense': after Gauss-Newton, search the cost over each free parameter "
                         "about the solution at full resolution (on a faint texture Gauss-Newton stops short; "
                         "slower)", default=True),
    "dense_shading": Bool("measurements 'dense': model the change of shading as the surface turns (a matte "
                          "surface under one distant light: three brightness parameters more; off: an affine "
                          "brightness change alone)", default=True),
    "dense_shading_frames": Number("measurements 'dense' with the shading: fuse what each frame measures of the "
                                   "shading (a property of the light, the same in every frame) over about this "
                                   "many frames the tracker judged sound into the next frames' prior (about 3 s at "
                                   "15 fps); 0: each frame alone", integer=True, lo=0, hi=100000, default=50),
    "dense_template_frames": Number("measurements 'dense': average the object's texture (and its surroundings') "
                                    "over up to this many views judged at rest before any deformation, the "
                                    "reference view included, so that one image's noise is not in every "
                                    "comparison (the averaging closes at the first view whose fit moves the "
                                    "image beyond the rest state's, a load too small to be called a "
                                    "deformation); 0: the reference view alone", integer=True, lo=0, hi=100000,
                                    default=20),
    "dense_grid_brightness": Enum(("auto", "always", "never"), "measurements 'dense': how the coarse search "
                                  "compares its candidates: always with the object's brightness fitted to each; "
                                  "never at the last frame's brightness (which a misaligned frame drags towards "
                                  "zero gain, flattening the search); auto (the default): fitted only when the last "
                                  "frame's gain is under the low-confidence threshold", default="auto"),
    "dense_camera_first": Bool("measurements 'dense' with the surroundings: measure the camera's error on them "
                               "alone, then fit the object with it held (off, the default: one joint fit)",
                               default=False),
    "dense_camera_check": Bool("measurements 'dense' with the surroundings: refit the camera's error on them "
                               "alone after the joint fit and flag the estimate low-confidence where they disagree "
                               "(the fit traded the camera against the deformation; one more small fit per frame)",
                               default=True),
    "dense_basin_check": Number("measurements 'dense': where the coarse search's best candidate from another "
                                "basin costs less than this share more than its winner, fit from both and keep the "
                                "cheaper at full resolution (a second fit on those frames); 0: off",
                                lo=0.0, hi=10.0, default=0.1),
    "dense_basin_warm": Bool("measurements 'dense' with dense_basin_check: where the fits from the coarse "
                             "search's winner and runner-up both end far from the last frame's estimate, fit from "
                             "that estimate too and keep the cheapest (a third fit on those frames; it helped no "
                             "development scene: docs/family.md)", default=False),
    "reference": Enum(("depth", "rest"), "the object's state in the view that later ones are compared with (the "
                      "dense reference view, a registered object's fit): read from the depth image where there is "
                      "one (the model's deformed surface fitted to it; a scene loaded from its first frame), or "
                      "taken to be the rest shape", default="depth"),
    "depth_fit": Bool("measurements 'map_points' with a depth image (RGB-D or stereo): read the tracked parameters "
                      "from every frame's depth (the model's deformed surface fitted to it, warm-started from the "
                      "image fit; about 58 ms a frame on the joint boot, 2 cores); the images still give the "
                      "constants (alpha_z) and whether a deformation is seen", default=False),
    "depth_stride": Number("with depth_fit: one depth pixel in this many along each axis is matched to the model "
                           "(2: a quarter of the pixels); larger is faster and matches fewer points", integer=True,
                           lo=1, hi=8, default=2),
    "depth_alone": Bool("with depth_fit: a frame whose images give too few measurements on the object (its map "
                        "points lost) is read from its depth alone, the constants (alpha_z) held, and reported "
                        "low-confidence instead of lost (docs/family.md, stop 88)", default=True),
    "depth_turn": Bool("with depth_fit, on a body of revolution about its z axis (the joint boot): alpha_z reported "
                       "with the depth fit's turn about that axis: the median over the frames whose depth held it "
                       "(the last 300; the bent shape holds the turn at least twice as well as the round rest "
                       "shape); not with alpha_z 'fixed'", default=False),
    "huber_px": Number("Huber threshold of the robust loss, pixels", lo=0, lo_open=True, default=2.0),
    "modes": Number("number of PGD modes used (0 = all)", integer=True, lo=0, default=0),
    "max_iterations": Number("Levenberg-Marquardt iterations per frame", integer=True, lo=1, hi=500, default=20),
    "outlier_refits": Number("measurements 'map_points' and 'dots': after each frame's Huber fit, refit with only the "
                             "measurements then within 3 x huber_px, re-classified before each of at most this many "
                             "rounds (ORB-SLAM2's pose optimisation; 0: Huber alone)", integer=True, lo=0, hi=10,
                             default=0),
    "constant_frames": Number("deformed frames used to estimate 'constant' parameters before freezing", integer=True,
                              lo=1, default=15),
    "constant_std_frac": Number("a frame informs a 'constant' parameter only if its standard deviation is below this "
                                "fraction of its range", lo=0, lo_open=True, hi=1, default=0.0025),
    "constant_search": Number("> 0: until a 'constant' parameter (alpha_z) has its first informative frame, also fit "
                              "each frame with it held at this many values over its range and keep the best (0: "
                              "off)", integer=True, lo=0, hi=360, default=0),
    "constant_search_until": Enum(("seen", "frozen"), "how long constant_search runs: until the constant's first "
                                  "informative frame (seen), or every frame until it is fixed (frozen: a win moves it "
                                  "to another basin and restarts its informative frames)", default="seen"),
    "min_measurements": Number("fewer inlier measurements than this -> lost", integer=True, lo=1, default=6),
    "points": Number("most model-linked points used per frame (0 = all)", integer=True, lo=0, default=0),
    "object_shift_m": Number("> 0: also fit a translation of the whole object, bounded by this (metres), each frame: "
                             "absorbs camera-pose drift against the map; for objects whose unmoving parts stay in "
                             "view (a beam's supports), not for a turning part (it absorbs the rotation)",
                             lo=0, hi=0.1, default=0.0),
    "rest_frames": Number("measurements 'dots' or 'homography': > 0 when the object is at rest in the first so many "
                          "frames with a camera pose: its pose is corrected from its dots in them (a small rigid "
                          "motion, then held; refused, with the reason, when the frames show a deformation): absorbs "
                          "a pose measured by hand a few mm and a degree off. 0: the pose is taken as given",
                          integer=True, lo=0, hi=300, default=0),
    "anchor": Enum(("ray", "foot"), "where a map point sits on its model triangle: where its pixel's viewing ray "
                   "crosses it (ray) or the mapped point's foot on it (foot; keeps the depth error's tangential part)",
                   default="ray"),
    "dots": ListOf(Vector(3, what="[x, y, z] in the object frame"),
                   "measurements 'dots': reference positions of glued dots", default=[]),
    "dot_color": Vector(3, what="[r, g, b] in 0..1", default=[0.1, 0.25, 0.95]),
})

COLLISION = Record({
    "enabled": Bool("real points in depth (or other objects) push this object", default=False),
    "threshold_m": Number("contact distance delta to the real points seen in depth, metres (a pushing virtual "
                          "object touches at a gap of zero)", lo=0, lo_open=True, default=0.01),
    "decimation": Number("use every N-th depth pixel in each direction", integer=True, lo=1, hi=64, default=4),
    "step": Number("pseudo-time increment per frame while in contact (and decrement after)", lo=0, lo_open=True, hi=1,
                   default=0.05),
    "pushes": ListOf(Str(**IDENT), "ids of objects this object can press when deformed (virtual-virtual contact)",
                     default=[]),
    "max_depth_m": Number("ignore depth beyond this, metres", lo=0, lo_open=True, default=5.0),
    "anywhere": Bool("the load sits where the real object touches, between the model's load points (models with "
                     "load-position axes: the linear beams), instead of at the nearest load point", default=False),
    "max_contacts": Number("contacts at once, their deformations added (linear models whose contact scales the load: "
                           "the beams; a probe model of a non-linear law takes 1)", integer=True, lo=1, hi=8,
                           default=1),
    "separation_m": Number("two touching load points farther apart than this are two contacts, metres (0: 2.5 "
                           "load-point spacings)", lo=0, default=0.0),
})

OBJECT_OVERLAY = Record({
    "field": Enum(("displacement", "von_mises", "none"), "what the colour map shows", default="displacement"),
    "colormap": Enum(("turbo", "viridis", "jet", "inferno"), default="turbo"),
    "modes": Number("PGD modes for drawing (0 = choose live to keep truncation error below max_error_px)", integer=True,
                    lo=0, default=0),
    "max_error_px": Number("truncation error bound on screen, pixels", lo=0, lo_open=True, default=0.5),
    "magnify": Number("displacement magnification for drawing", lo=0, lo_open=True, default=1.0),
    "range": Vector(2, what="[min, max] of the colour bar (model units)", nullable=True),
})

OBJECT = Record({
    "id": Str("object id (also its TF frame name)", required=True, **IDENT),
    "model": ModelRef("HDF5 model file built by `simreal build-model`, or spec:NAME for a built-in spec "
                      "(built once into the cache)", required=True),
    "anchor": ANCHOR,
    "parameters": MapOf(PARAMETER, doc="per model parameter: tracked / constant / fixed", default={}),
    "tracking": TRACKING,
    "collision": COLLISION,
    "overlay": OBJECT_OVERLAY,
})

OVERLAY = Record({
    "enabled": Bool("run the overlay node", default=True),
    "video": FilePath("also write the overlay to this MP4", must_exist=False, nullable=True),
    "occlusion": Bool("hide virtual pixels behind closer real depth", default=True),
    "marker": Bool("publish an RViz Marker mesh per object", default=True),
    "colorbar": Bool("draw a colour bar with units", default=True),
})

AERO = Record({
    "enabled": Bool("capture the car in the SLAM map and draw its flow from the database (thesis ch. 6): starts the "
                    "aero node; needs a SLAM localization (mono, rgbd, stereo)", default=False),
    "database": FilePath("aero database (HDF5) built offline by `simreal build-aero-db SPEC -o DB.h5`", nullable=True,
                         must_exist=False),
    "neighbours": Number("M: database cars in Eq. 6.4 (the benchmark's leave-one-out chose 15, benchmarks/results/"
                         "aero.md)", integer=True, lo=2, hi=1000, default=15),
    "length_m": Number("the car's length, metres: sets a monocular map's scale (required for localization mode "
                       "'mono'; a metric map keeps its own)", lo=0, lo_open=True, nullable=True),
    "keyframe_depth": Bool("RGB-D / stereo: capture from the map points and every keyframe feature with a measured "
                           "depth (off: the map points alone, a sparse car: benchmarks/results/aero_video.md)",
                           default=True),
    "min_points": Number("capture once the cloud holds this many points", integer=True, lo=50, default=2000),
    "recapture_growth": Number("capture again when the cloud has grown by this fraction since the last capture (0: "
                               "only once; a failed capture is tried again at 10 % growth)", lo=0, default=0.2),
    "alpha_m": Number("alpha of the car's alpha shape, metres (Alg. 6.1)", lo=0.05, hi=10, default=1.0),
    "max_points": Number("thin a larger capture cloud to this many points on a voxel grid before Alg. 6.1 (0: never; "
                         "the trade of overlap against time: benchmarks/results/aero_video_dev.md)", integer=True, lo=0,
                         default=5000),
    "streamlines": Number("streamline seeds across the car (a rake of N x N*0.8 upstream of the nose)", integer=True,
                          lo=1, hi=50, default=11),
    "section": Enum(("none", "pressure", "velocity"), "also draw a contour plane on the symmetry plane (thesis Fig. "
                    "6.10b): the pressure coefficient from Eq. 6.4 on the database's pressure, or the speed of Eq. "
                    "6.4's velocity on the streamlines' colour scale", default="none"),
})

SCENE = Record({
    "simreal_scene": Number("scene format version", integer=True, required=True),
    "name": Str("scene name", required=True, **IDENT),
    "description": Str("free text", default=""),
    "frames": Record({
        "map": Str("fixed frame (REP-105)", default="map"),
        "camera": Str("camera optical frame (REP-103: z forward, x right, y down)", default="camera_optical_frame"),
    }),
    "camera": CAMERA,
    "localization": LOCALIZATION,
    "objects": ListOf(OBJECT, "deformable objects", default=[]),
    "overlay": OVERLAY,
    "aero": AERO,
    "ground_truth": Record({
        "topic_prefix": Str("prefix of ground-truth topics in synthetic bags (never read by estimators)",
                            default="/ground_truth"),
    }),
})


def _cross_checks(scene: dict, ctx: Context) -> None:
    src = ctx.source
    if scene["simreal_scene"] != SCENE_FORMAT:
        raise SceneError(f"{src}: simreal_scene: expected format version {SCENE_FORMAT}; "
                         f"found {scene['simreal_scene']}")
    ids = [o["id"] for o in scene["objects"]]
    for i, oid in enumerate(ids):
        if ids.index(oid) != i:
            raise SceneError(f"{src}: objects[{i}].id: expected a unique id; found '{oid}' twice")
    loc, cam = scene["localization"], scene["camera"]
    if loc["mode"] == "static" and loc["static_pose"] is None:
        raise SceneError(f"{src}: localization.static_pose: required when localization.mode is 'static'; found nothing")
    if loc["mode"] == "markers" and not loc["markers"]["poses"]:
        raise SceneError(f"{src}: localization.markers.poses: expected at least one marker pose for mode 'markers'; "
                         "found none")
    if loc["mode"] == "rgbd" and cam["depth"] is None:
        raise SceneError(f"{src}: camera.depth: required for localization.mode 'rgbd'; found nothing")
    if loc["mode"] == "stereo" and (cam["right_image"] is None or cam["right_camera_info"] is None):
        raise SceneError(f"{src}: camera.right_image / camera.right_camera_info: required for localization.mode "
                         "'stereo'")
    if cam["source"] != "topic" and cam["path"] is None:
        raise SceneError(f"{src}: camera.path: required for camera.source '{cam['source']}'; found nothing")
    if cam["depth_to_color"] is not None and math.hypot(*cam["depth_to_color"][3:]) < 1e-6:
        raise SceneError(f"{src}: camera.depth_to_color: its quaternion (the last four values) is zero: no rotation")
    if (cam["depth_camera_info"] is None) != (cam["depth_to_color"] is None) or (
            cam["depth_camera_info"] is not None and (cam["depth"] is None or cam["source"] != "topic")):
        raise SceneError(f"{src}: camera.depth_camera_info / camera.depth_to_color: registering a depth camera's "
                         "images to the colour camera needs both, camera.depth and camera.source 'topic'")
    if cam["stereo_input"] != "rectified" and (cam["right_image"] is None or cam["right_camera_info"] is None
                                               or cam["calibration"] is not None or cam["source"] != "topic"
                                               or cam["depth"] is not None):
        raise SceneError(f"{src}: camera.stereo_input: '{cam['stereo_input']}' reads a stereo pair through the "
                         "CameraInfo topics of both cameras (their R and P): it needs camera.right_image and "
                         "camera.right_camera_info, camera.source 'topic', and no camera.calibration or camera.depth")
    aero = scene["aero"]
    if aero["enabled"]:
        if loc["mode"] not in ("mono", "rgbd", "stereo"):
            raise SceneError(f"{src}: aero.enabled: the car is captured from a SLAM map (localization.mode mono, "
                             f"rgbd or stereo); found mode '{loc['mode']}'")
        if aero["database"] is None or not Path(aero["database"]).is_file():
            raise SceneError(f"{src}: aero.database: the aero database file is needed and was not found"
                             f"{': ' + aero['database'] if aero['database'] else ''} (build it offline: `simreal "
                             "build-aero-db aero_cars.yaml -o DB.h5`, about 50 CPU-minutes on 2 cores)")
        if loc["mode"] == "mono" and aero["length_m"] is None:
            raise SceneError(f"{src}: aero.length_m: a monocular map has no scale; give the car's length in metres")
    for i, o in enumerate(scene["objects"]):
        for j, other in enumerate(o["collision"]["pushes"]):
            if other not in ids or other == o["id"]:
                raise SceneError(f"{src}: objects[{i}].collision.pushes[{j}]: expected the id of another object "
                                 f"({', '.join(x for x in ids if x != o['id']) or 'none defined'}); found '{other}'")
        if o["collision"]["enabled"] and cam["depth"] is None and cam["right_image"] is None and not any(
                o["id"] in p["collision"]["pushes"] for p in scene["objects"]):
            raise SceneError(f"{src}: objects[{i}].collision.enabled: collision needs camera.depth or a stereo pair "
                             "(or another object that pushes it); found neither")
        if o["tracking"]["depth_fit"] and (o["tracking"]["measurements"] != "map_points"
                                           or loc["mode"] not in ("rgbd", "stereo")):
            raise SceneError(f"{src}: objects[{i}].tracking.depth_fit: needs measurements 'map_points' and depth "
                             f"images (localization.mode 'rgbd' or 'stereo'); found measurements "
                             f"'{o['tracking']['measurements']}', mode '{loc['mode']}'")
        if o["tracking"]["depth_turn"] and not o["tracking"]["depth_fit"]:
            raise SceneError(f"{src}: objects[{i}].tracking.depth_turn: takes the turn from the depth fit of every "
                             "frame: needs tracking.depth_fit true; found false")
        # "alpha_z": rom.state.ALPHA_Z, spelt out (importing it would bring scipy into every scene check)
        if o["tracking"]["depth_turn"] and o["parameters"].get("alpha_z", {}).get("mode") == "fixed":
            raise SceneError(f"{src}: objects[{i}].tracking.depth_turn: reports alpha_z with the depth's turn, and "
                             "parameters.alpha_z is 'fixed' (given, not estimated): make alpha_z 'constant' or "
                             "depth_turn false")
        if o["anchor"]["kind"] == "registration" and loc["mode"] not in ("rgbd", "stereo"):
            # registration works on depth images (assimilation.registration.register_rgbd: RGB-D, or SGBM on a
            # stereo pair); a monocular map's sparse points alone do not place a model to millimetres
            raise SceneError(f"{src}: objects[{i}].anchor.kind: 'registration' needs depth images (localization.mode "
                             f"'rgbd' or 'stereo'); found mode '{loc['mode']}' (give kind 'pose')")
        if o["anchor"]["kind"] == "registration" and o["anchor"]["guess"] is None:
            raise SceneError(f"{src}: objects[{i}].anchor.guess: required for kind 'registration' (the object frame "
                             "in the first camera frame, judged by eye); found nothing")
        if o["tracking"]["rest_frames"] > 0 and o["tracking"]["measurements"] not in ("dots", "homography"):
            raise SceneError(f"{src}: objects[{i}].tracking.rest_frames: the pose is corrected at rest from dots "
                             f"(measurements 'dots' or 'homography'); found measurements "
                             f"'{o['tracking']['measurements']}' (set rest_frames: 0)")
        _resolve_model_ref(o, i, src)
        # a spec's model is not built yet: its parameter names are checked by build_spec_models
        _check_parameters(o, i, src, None if o["_model_spec"] else _model_header(o, i, src))


def _resolve_model_ref(obj: dict, i: int, source: str) -> None:
    """``spec:NAME`` -> the model's cache path (the spec is read and validated, nothing is built); the spec name is
    kept in ``_model_spec`` (None for a model file) for :func:`build_spec_models`."""
    ref = obj["model"]
    obj["_model_spec"] = None
    if not ref.startswith(SPEC_PREFIX):
        return
    from simreal_nodes.rom.build import cached_model_path

    try:
        obj["model"] = str(cached_model_path(ref[len(SPEC_PREFIX):]))
    except SceneError as e:
        raise SceneError(f"{source}: objects[{i}].model: {e}") from None
    obj["_model_spec"] = ref[len(SPEC_PREFIX):]


def _model_header(obj: dict, i: int, source: str) -> dict:
    """The model file's header (read lazily: no fields), kept in ``_model_header``."""
    from simreal_nodes.rom.model_file import read_header

    try:
        obj["_model_header"] = read_header(obj["model"])
    except Exception as e:  # noqa: BLE001 - report any failure to read as a scene error
        raise SceneError(f"{source}: objects[{i}].model: {e}") from None
    return obj["_model_header"]


def _check_parameters(obj: dict, i: int, source: str, header: dict | None) -> None:
    """Parameter names in the scene must exist in the model (``header``; None: not known yet, names unchecked) and
    a fixed parameter needs its value."""
    names = [a["name"] for a in header["axes"]] if header is not None else []
    for p, cfg in obj["parameters"].items():
        if header is not None and p not in names and p not in header.get("rigid_parameters", []):
            raise SceneError(f"{source}: objects[{i}].parameters.{p}: the model {Path(obj['model']).name} has no "
                             f"parameter '{p}' (it has: {', '.join(names + header.get('rigid_parameters', []))})")
        if cfg["mode"] == "fixed" and cfg["value"] is None:
            raise SceneError(f"{source}: objects[{i}].parameters.{p}.value: required for mode 'fixed'; found nothing")


def build_spec_models(scene: dict, progress=None) -> dict:
    """Build the model of every ``spec:NAME`` object into the cache (once; again when its spec or the builders' code
    changed: :func:`~simreal_nodes.rom.build.cached_model`) and check the object's parameter names against it;
    returns ``scene`` (its ``objects[].model`` already name these files).

    Called by what starts nodes (launch, replay, the demo) or uses the models in-process (evaluation, offline
    pipelines, benchmarks) before anything reads a model file; never by validation."""
    from simreal_nodes.rom.build import cached_model

    for i, o in enumerate(scene["objects"]):
        name = o["_model_spec"]
        if name is None:
            continue
        try:
            o["model"] = str(cached_model(name, progress))
        except SceneError as e:
            raise SceneError(f"{scene['_source']}: objects[{i}].model: {e}") from None
        except Exception as e:  # noqa: BLE001 - a failed build is a scene error with its reason
            raise SceneError(f"{scene['_source']}: objects[{i}].model: building {SPEC_PREFIX}{name} failed: "
                             f"{e}") from None
        _check_parameters(o, i, scene["_source"], _model_header(o, i, scene["_source"]))
    return scene


def validate_scene(doc, source: str = "<scene>", base_dir: str | Path = ".") -> dict:
    ctx = Context(source=source, base_dir=Path(base_dir).resolve())
    if not isinstance(doc, dict):
        raise SceneError(f"{source}: expected a mapping at the top level; found {type(doc).__name__}")
    scene = SCENE.validate(doc, "", ctx)
    _cross_checks(scene, ctx)
    scene["_source"] = source
    return scene


def load_scene(path: str | Path) -> dict:
    """Read and validate a scene YAML; raises SceneError naming key, expectation and finding."""
    path = Path(path)
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise SceneError(f"scene file not found: {path}") from None
    except OSError as e:
        raise SceneError(f"{path}: cannot read the scene file: {e.strerror}") from None
    except UnicodeDecodeError as e:
        raise SceneError(f"{path}: not UTF-8 text: {e}") from None
    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError as e:
        raise SceneError(f"{path}: not valid YAML: {e}") from None
    return validate_scene(doc, str(path), path.parent)
