"""Which nodes a scene needs, what each is called, and which topics connect them (ROS-free).

The launcher starts exactly :func:`required_nodes`; the player in lossless mode waits for a
progress report from every one of them. Topic names follow ROS conventions; the inputs are the
scene's ``camera.*`` topics (defaults ``/camera/image_raw``, ``/camera/camera_info``,
``/camera/depth/image_raw``), everything simreal publishes lives under ``/simreal`` except TF.
"""

from __future__ import annotations

from dataclasses import dataclass, field

# Topics between nodes (the ingest node's validated outputs and the products of each stage).
CAM_IMAGE = "/simreal/camera/image"
CAM_INFO = "/simreal/camera/camera_info"
CAM_DEPTH = "/simreal/camera/depth"
CAM_RIGHT_IMAGE = "/simreal/camera/right/image"
CAM_RIGHT_INFO = "/simreal/camera/right/camera_info"
POSE = "/simreal/localization/pose"
LOC_STATUS = "/simreal/localization/status"
LOC_MAP = "/simreal/localization/map"
LOC_OBS = "/simreal/localization/observations"
LOC_DEFORMABLE = "/simreal/localization/deformable_points"  # tracker -> localization: PointCloud2 x, y, z, id, drop
LOC_FOCUS = "/simreal/localization/focus"  # tracker -> localization: an object's image region (PolygonInstanceStamped)
LOC_CAPTURE = "/simreal/localization/capture_cloud"  # aero scenes: the map's points + keyframe depth (PointCloud2)
TRACKER_STATUS = "/simreal/tracker/status"
AERO_FLOW = "/simreal/aero/flow"  # the captured body and its streamlines, map frame (MarkerArray)
OVERLAY_IMAGE = "/simreal/overlay/image_raw"
OVERLAY_MARKERS = "/simreal/overlay/markers"
PROGRESS = "/simreal/progress"
DIAGNOSTICS = "/diagnostics"
TF = "/tf"
TF_STATIC = "/tf_static"


def image_topic(camera: dict, right: bool = False) -> str | None:
    """The image topic as it travels: <image>/compressed when the scene says the images are compressed."""
    t = camera["right_image"] if right else camera["image"]
    if t and camera.get("compressed"):
        return t + "/compressed"
    return t


def ingest_work(scene: dict, source: str | None = None) -> list[str]:
    """What the ingest node would do that no other node does ([] = nothing: the nodes read the camera topics
    themselves). ``source``: where the frames come from when not the scene's ``camera.source`` (a replay's player
    publishes them on the camera topics: ``"topic"``). Every node that reads the camera checks its CameraInfo and
    its images' format and size itself; what only the ingest does is reading files, decompressing, undistorting,
    rectifying a raw stereo pair, taking the intrinsics from a calibration file, and, with ``camera.ingest:
    always``, everything."""
    cam = scene["camera"]
    src = source or cam["source"]
    why = []
    if cam.get("ingest", "auto") == "always":
        why.append("camera.ingest: always")
    if src != "topic":
        why.append(f"reads frames from a {src} file")
    if cam["compressed"]:
        why.append("decompresses the images")
    if cam["undistort"]:
        why.append("undistorts the images")
    if cam.get("depth_camera_info") and cam.get("depth"):
        why.append("registers the depth images to the colour camera")
    if cam.get("stereo_input") == "raw" and cam.get("right_image"):
        why.append("rectifies the raw stereo pair")
    if cam.get("stereo_input") == "image_rect" and cam.get("right_image"):
        why.append("publishes the image_rect pair's rectified cameras")
    if cam["calibration"]:
        why.append("publishes the calibration file's intrinsics")
    return why


def ingest_note(scene: dict, nodes: list[NodeSpec], source: str | None = None) -> str:
    """One line for the user: why the graph ``nodes`` of ``scene`` has an ingest node, or which topics its nodes
    read instead."""
    if any(n.name == "ingest" for n in nodes):
        return "ingest: " + (", ".join(ingest_work(scene, source)) or "the scene's only node")
    return f"no ingest: the nodes read {image_topic(scene['camera'])} and its CameraInfo themselves"


def unestimated_notes(scene: dict) -> list[str]:
    """One line for each object that no node estimates (neither ``tracking`` nor ``collision`` enabled): nothing
    publishes its parameters, so the overlay draws it with each at the low end of its range (the rest shape's end;
    ``parameters.*.initial`` and ``fixed`` values are applied only by a tracker). Deliberate in a scene that only
    shows a model, a slip in one whose parameters are meant to be ``tracked`` (the schema's default mode), so the
    commands that read a scene say it, with what would estimate it."""
    notes = []
    for i, o in enumerate(scene["objects"]):
        if o["tracking"]["enabled"] or o["collision"]["enabled"]:
            continue
        shown = ("the overlay draws it with each parameter at the low end of its range (initial and fixed values are "
                 "applied only by a tracker)") if scene["overlay"]["enabled"] else "and no overlay draws it"
        pushers = [f"objects[{j}]" for j, p in enumerate(scene["objects"])
                   if p["collision"]["enabled"] and o["id"] in p["collision"]["pushes"]]
        modes = {p["mode"] for p in o["parameters"].values()}
        if pushers:
            verb = "pushes" if len(pushers) == 1 else "push"
            advice = f"{' and '.join(pushers)} {verb} it: set its collision.enabled: true to take the contact"
        elif modes == {"fixed"}:
            advice = "set tracking.enabled: true to have its fixed values drawn"
        else:
            advice = "set tracking.enabled: true to fit it to the images"
        notes.append(f"note: objects[{i}] '{o['id']}': nothing publishes its parameters (tracking.enabled and "
                     f"collision.enabled are off); {shown}. To estimate it, {advice}")
    return notes


def camera_topics(camera: dict | None, direct: bool) -> dict[str, str]:
    """The camera topics a node reads, those of the streams the camera has (``image``, ``info``; ``depth``;
    ``right``, ``right_info``): the camera's own (``direct``: no ingest in the graph) or the ingest's outputs.
    ``camera``: the scene's ``camera`` block (None: the schema's defaults)."""
    cam = camera or {}
    if direct:
        t = {"image": cam.get("image") or "/camera/image_raw", "info": cam.get("camera_info") or "/camera/camera_info",
             "depth": cam.get("depth"), "right": cam.get("right_image"), "right_info": cam.get("right_camera_info")}
    else:
        t = {"image": CAM_IMAGE, "info": CAM_INFO, "depth": CAM_DEPTH if cam.get("depth") else None,
             "right": CAM_RIGHT_IMAGE, "right_info": CAM_RIGHT_INFO}
    if not cam.get("right_image"):
        t["right"] = t["right_info"] = None
    return {k: v for k, v in t.items() if v}


def params_topic(object_id: str) -> str:
    return f"/simreal/objects/{object_id}/parameters"


def contact_topic(object_id: str) -> str:
    return f"/simreal/objects/{object_id}/contact"


@dataclass
class NodeSpec:
    """One node process: ROS name (its executable is ``simreal-<name>`` in pyproject.toml's ``[project.scripts]``,
    which the launcher reads), parameters, topics."""

    name: str
    parameters: dict = field(default_factory=dict)
    inputs: list[str] = field(default_factory=list)
    outputs: dict[str, str] = field(default_factory=dict)  # topic -> message type
    per_frame: bool = True  # reports progress for every camera frame (the lossless player waits for it)


IMAGE_MEASUREMENTS = ("dots", "homography", "dense")  # tracking.measurements that read the image's pixels


def tracker_inputs(scene: dict) -> tuple[str, ...]:
    """What the tracker node synchronises per frame: the localization's observations, and the image only where it
    is measured (glued dots, homography, dense) or where a static camera paces the tracker."""
    tracked = [o for o in scene["objects"] if o["tracking"]["enabled"]]
    static = scene["localization"]["mode"] == "static"
    if static:
        return ("image",)
    if any(o["tracking"]["measurements"] in IMAGE_MEASUREMENTS for o in tracked):
        return ("obs", "image")
    return ("obs",)


def tracker_reads_status(scene: dict) -> bool:
    """Whether the tracker node reads the localization's status: with ``localization.freeze_map_on_deformation``,
    to ask a restarted localization again (a static camera has no localization node to ask)."""
    loc = scene["localization"]
    return bool(loc.get("freeze_map_on_deformation", False)) and loc["mode"] != "static"


def tracker_reads_depth(scene: dict) -> bool:
    """Whether the tracker node takes depth (optional in its frame; the depth image of an RGB-D camera, or the
    stereo pair it matches itself, see :func:`tracker_stereo_depth`): an object placed by registration (its depth
    views), or dense measurements (the static surroundings of the reference view), or sparse ones with
    ``tracking.reference: depth`` (the state they start from) or ``tracking.depth_fit`` (the state of every frame),
    the last two where the camera gives depth."""
    tracked = [o for o in scene["objects"] if o["tracking"]["enabled"]]
    cam = scene["camera"]
    return any(o["anchor"]["kind"] == "registration" for o in tracked) or (
        (cam["depth"] is not None or cam["right_image"] is not None) and any(
            o["tracking"]["measurements"] == "dense"
            or (o["tracking"]["measurements"] == "map_points"
                and (o["tracking"]["reference"] == "depth" or o["tracking"]["depth_fit"]))
            for o in tracked))


def tracker_stereo_depth(scene: dict) -> bool:
    """Whether the tracker node makes its depth from the stereo pair (SGBM, ``camera.stereo_min_depth_m``): it
    reads depth and the camera has no depth image but a right one."""
    cam = scene["camera"]
    return tracker_reads_depth(scene) and cam["depth"] is None and cam["right_image"] is not None


SLAM_MODES = ("mono", "rgbd", "stereo")  # localization modes that run the SLAM


SPLIT = "split"  # the launch with the slow nodes apart (``--split``): see :func:`process_groups`


def default_launch(scene: dict, lossless: bool, in_flight: int = 1) -> bool:
    """The launch the CLI picks when told none of ``--one-process``, ``--process-per-node`` and ``--split`` (as
    :func:`process_groups` takes it: True one process, False a process per node): every node in one
    process, but a process per node for a live graph with a node whose work takes longer than a camera frame period
    (:func:`slow_nodes`: a SLAM localization, 33-38 ms a frame at 640 x 480; the dense tracker, 135-140 ms): on one
    executor every other node waits for it, while in its own process it runs beside them on another core. Set on
    ``benchmarks/results/graph.md`` (stop 95): one process faster or level in every lossless case and live for the
    markers demo (96 % of the frames through against 93 %), a process per node live for the RGB-D SLAM scenes (the
    foam beam 60 % against 37 %, family-3 49 % against 34 %); checked on held-out scenes by ``./run bench
    launch_mode``. A lossless replay with more than one frame in flight (``in_flight``, the player's) has the nodes
    work on different frames at once, which one executor cannot: a process per node (stop 97's graph run: ahead in
    every case with frames in flight). Split (:data:`SPLIT`) stays a choice: stop 98 made it the pick with frames in
    flight where a node is slow, on ``graph.md``'s scenes (the foam beam 30.1 fps split against 26.5, family-3 8.9
    against 8.5), and the held-out scenes did not bear it out (``launch_mode.md``: the joint boot 23.9 against 23.7, the
    registered one 15.8 against 18.6); live it put more frames through on two scenes of four (the foam beam 90 %
    against 85 %, the registered boot 67 % against 62 %), fewer on one (family-3 56 % against 62 %), as many on the
    fourth (85 %)."""
    if lossless:
        return in_flight <= 1
    return not slow_nodes(scene)


def slow_nodes(scene: dict) -> set[str]:
    """The nodes whose work a frame outlasts a camera frame period at 640 x 480 on 2 cores: a SLAM localization (33-38
    ms a frame) and a dense tracker (135-140 ms a frame in ``graph.md``'s family-3); those a split launch
    (:func:`process_groups`) runs in processes of their own."""
    slow = set()
    if scene["localization"]["mode"] in SLAM_MODES:
        slow.add("localization")
    if any(o["tracking"]["enabled"] and o["tracking"]["measurements"] == "dense" for o in scene["objects"]):
        slow.add("tracker")
    return slow


def process_groups(scene: dict, nodes: list[NodeSpec], launch: bool | str) -> list[list[str]]:
    """Which of ``nodes`` share a process: ``launch`` True, all of them (one process, one executor); False, none (a
    process per node); :data:`SPLIT`, each slow node (:func:`slow_nodes`) in a process of its own and the others
    together in one. The split is for 2 cores with frames in flight: the slow node has a core to itself while the
    light ones share the other without the per-process overhead of each (an interpreter, a DDS participant, a
    publication that wakes another process); ``./run bench graph`` measures it beside the other two."""
    names = [n.name for n in nodes]
    if launch is True:
        return [names] if names else []
    if launch is False:
        return [[n] for n in names]
    if launch != SPLIT:
        raise ValueError(f"launch {launch!r}: expected True (one process), False (a process per node) or {SPLIT!r}")
    slow = slow_nodes(scene)
    rest = [n for n in names if n not in slow]
    return [[n] for n in names if n in slow] + ([rest] if rest else [])


def launch_choice(scene: dict, lossless: bool, told: bool | str | None,
                  in_flight: int = 1) -> tuple[bool | str, str]:
    """(the launch, for :func:`process_groups`; how the nodes run, for the launch's first line): ``told`` where the
    user said (``--one-process`` True, ``--process-per-node`` False, ``--split`` :data:`SPLIT`), else
    :func:`default_launch`'s pick."""
    one = default_launch(scene, lossless, in_flight) if told is None else told
    if one == SPLIT:
        apart = sorted(slow_nodes(scene))
        how = (f"split: {', '.join(apart)} in {'a process' if len(apart) == 1 else 'processes'} of "
               f"{'its' if len(apart) == 1 else 'their'} own, any others in one" if apart
               else "split: no node slower than a frame, all in one process")
    else:
        how = "in one process" if one else "a process per node"
    if told is not None:
        return one, how
    why = ("the default" if one else "lossless with frames in flight: the default there" if lossless
           else "live, with a node slower than a frame: the default for such a graph")
    return one, f"{how} ({why}; --one-process / --process-per-node / --split choose)"


def required_nodes(scene: dict, lossless: bool = False, source: str | None = None) -> list[NodeSpec]:
    """The nodes the scene requires, in pipeline order. Only those are started. ``source``: where the frames come
    from when not the scene's ``camera.source`` (see :func:`ingest_work`). The ingest node is among them when it has
    work (:func:`ingest_work`) or is the only node; the others then read its outputs, else the camera's topics
    (their parameter ``camera_direct``)."""
    cam, loc, objs = scene["camera"], scene["localization"], scene["objects"]
    readers = loc["mode"] != "static" or scene["overlay"]["enabled"] or any(
        o["tracking"]["enabled"] or o["collision"]["enabled"] for o in objs)
    with_ingest = bool(ingest_work(scene, source)) or not readers
    common = {"scene_file": scene["_source"], "lossless": lossless,
              "map_frame": scene["frames"]["map"], "camera_frame": scene["frames"]["camera"]}
    t = camera_topics(cam, direct=not with_ingest)
    image, info = t["image"], t["info"]
    stereo = cam["right_image"] is not None
    depth = cam["depth"] is not None
    nodes: list[NodeSpec] = []

    if with_ingest:
        ingest_out = {CAM_IMAGE: "sensor_msgs/msg/Image", CAM_INFO: "sensor_msgs/msg/CameraInfo"}
        if depth:
            ingest_out[CAM_DEPTH] = "sensor_msgs/msg/Image"
        if stereo:
            ingest_out[CAM_RIGHT_IMAGE] = "sensor_msgs/msg/Image"
            ingest_out[CAM_RIGHT_INFO] = "sensor_msgs/msg/CameraInfo"
        ingest_in = [x for x in (image_topic(cam), cam["camera_info"], cam["depth"], cam.get("depth_camera_info"),
                                 image_topic(cam, right=True), cam["right_camera_info"]) if x] \
            if (source or cam["source"]) == "topic" else []
        nodes.append(NodeSpec("ingest", dict(common, **({"source": source} if source else {})), ingest_in,
                              ingest_out))
    else:
        common["camera_direct"] = True

    aero = scene.get("aero", {}).get("enabled", False)
    if loc["mode"] != "static":
        nodes.append(NodeSpec(
            "localization", dict(common),
            [image, info] + ([t["depth"]] if depth else [])
            + ([t["right"], t["right_info"]] if stereo else [])
            + ([LOC_DEFORMABLE, LOC_FOCUS] if any(o["tracking"]["enabled"] for o in objs) else []),
            {POSE: "geometry_msgs/msg/PoseStamped", TF: "tf2_msgs/msg/TFMessage",
             LOC_STATUS: "simreal_msgs/msg/TrackingStatus", LOC_MAP: "sensor_msgs/msg/PointCloud2",
             LOC_OBS: "simreal_msgs/msg/FeatureObservations",
             **({LOC_CAPTURE: "sensor_msgs/msg/PointCloud2"} if aero else {})}))
    if aero:
        # no camera frames: it captures when the localization's cloud has grown (so no per-frame progress)
        nodes.append(NodeSpec("aero", dict(common), [LOC_CAPTURE], {AERO_FLOW: "visualization_msgs/msg/MarkerArray"},
                              per_frame=False))

    tracked = [o for o in objs if o["tracking"]["enabled"]]
    if tracked:
        nodes.append(NodeSpec(
            "tracker", dict(common),
            list(dict.fromkeys([LOC_OBS if k == "obs" else image for k in tracker_inputs(scene)] + [info]
                               + ([t["depth"]] if depth and tracker_reads_depth(scene) else [])
                               + ([image, t["right"], t["right_info"]] if tracker_stereo_depth(scene)
                                  else [])
                               + ([LOC_STATUS] if tracker_reads_status(scene) else []))),
            {**{params_topic(o["id"]): "simreal_msgs/msg/ModelParameters" for o in tracked},
             TRACKER_STATUS: "simreal_msgs/msg/TrackingStatus",
             **({LOC_DEFORMABLE: "sensor_msgs/msg/PointCloud2", LOC_FOCUS: "geometry_msgs/msg/PolygonInstanceStamped"}
                if loc["mode"] != "static" else {})}))

    colliding = [o for o in objs if o["collision"]["enabled"]]
    if colliding:
        out = {}
        for o in colliding:
            out[contact_topic(o["id"])] = "simreal_msgs/msg/ContactState"
            out[params_topic(o["id"])] = "simreal_msgs/msg/ModelParameters"
        depth_in = [t["depth"]] if depth else [image, t["right"], t["right_info"]]  # stereo: SGBM in the node
        nodes.append(NodeSpec("collision", dict(common),
                              depth_in + [info] + ([LOC_OBS] if loc["mode"] != "static" else []), out))

    if scene["overlay"]["enabled"]:
        ins = [image, info] + ([t["depth"]] if depth else []) + ([LOC_OBS] if loc["mode"] != "static" else [])
        ins += [params_topic(o["id"]) for o in objs if o["tracking"]["enabled"] or o["collision"]["enabled"]]
        ins += [AERO_FLOW] if aero else []
        nodes.append(NodeSpec("overlay", dict(common), ins,
                              {OVERLAY_IMAGE: "sensor_msgs/msg/Image",
                               OVERLAY_MARKERS: "visualization_msgs/msg/MarkerArray"}))
    return nodes


def output_topics(nodes: list[NodeSpec]) -> dict[str, str]:
    """Every topic the graph publishes (what `replay --record` records), plus diagnostics."""
    out: dict[str, str] = {}
    for n in nodes:
        out.update(n.outputs)
    out[DIAGNOSTICS] = "diagnostic_msgs/msg/DiagnosticArray"
    return out
