"""Undistortion with cached maps (computed once per camera model, applied per frame), and the camera of an
ingest: the intrinsics it publishes and the check every incoming image goes through."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from simreal_nodes.camera import CameraModel, sensor_reduction
from simreal_nodes.errors import CameraInfoError, ImageFormatError
from simreal_nodes.io import images
from simreal_nodes.io.sources import Frame
from simreal_nodes.vision.rectify import StereoRectification, rectification_of, rectified_problem


class Undistorter:
    """Remaps distorted images to the ideal pinhole image of the same K (distortion zero)."""

    def __init__(self, cam: CameraModel):
        self.cam = cam
        self.ideal = CameraModel(cam.width, cam.height, cam.K.copy(), np.zeros(5), "plumb_bob", cam.frame_id)
        self._maps = cam.undistort_maps(cam.K, (cam.width, cam.height), cv2.CV_16SC2)

    def matches(self, cam: CameraModel) -> bool:
        return cam.same_as(self.cam)

    def image(self, img: np.ndarray) -> np.ndarray:
        return cv2.remap(img, self._maps[0], self._maps[1], cv2.INTER_LINEAR)

    def depth(self, depth: np.ndarray) -> np.ndarray:
        """Depth must not be blended across edges: nearest-neighbour remap."""
        return cv2.remap(depth, self._maps[0], self._maps[1], cv2.INTER_NEAREST)


_STREAM_NAMES = {"image": "image", "depth": "depth image", "right": "right image"}
STEREO_INPUTS = ("rectified", "raw", "image_rect")  # camera.stereo_input (IngestCamera)


@dataclass
class Checked:
    """An incoming image after :meth:`IngestCamera.check`: ``why`` it is left out (''= it is published) and the
    ``pixels`` to publish instead of the message's own (None: the message passes as it is)."""

    why: str = ""
    pixels: np.ndarray | None = None


class IngestCamera:
    """The camera an ingest publishes: its intrinsics (a calibration file, if given, wins over CameraInfo), the
    undistortion that goes with them when asked (the published CameraInfo is then the ideal pinhole one), the right
    camera of a stereo pair, and the one check every incoming image of a stream goes through. ``stereo_input``
    (:mod:`~simreal_nodes.vision.rectify`): ``rectified``, a pair whose CameraInfos describe rectified images (a
    right one that describes raw images is refused with its reason: a raw pair matched along rows as if rectified
    gives wrong depths); ``raw``, a driver's raw pair, rectified here from its CameraInfos' lens, R and P;
    ``image_rect``, rectified images beside the raw cameras' CameraInfos (ROS's image_rect topics), their cameras
    read from P. With ``raw`` and ``image_rect`` the published CameraInfos are the rectified cameras'."""

    def __init__(self, undistort: bool, calibration: CameraModel | None = None, stereo_input: str = "rectified",
                 depth_to_color: np.ndarray | None = None, depth_refused: str = ""):
        """``depth_to_color``: the depth images come from a camera of their own, whose optical frame this pose (4 x 4)
        places in the colour camera's: they are registered to the colour camera here (:meth:`depth_info` gives
        their camera; :func:`~simreal_nodes.vision.depth.register_depth`). ``depth_refused``: why depth images
        cannot be registered as asked (a bad pose): each is refused with it rather than passed on unregistered."""
        self.depth_refused = depth_refused
        if stereo_input not in STEREO_INPUTS:
            raise ValueError(f"stereo_input '{stereo_input}': one of {', '.join(STEREO_INPUTS)}")
        self.depth_to_color = None if depth_to_color is None else np.asarray(depth_to_color, np.float64)
        self.depth_cam: CameraModel | None = None
        self.depth_error = ""
        self.undistort = undistort
        self.calibration = calibration
        self.stereo_input = stereo_input
        self.cam: CameraModel | None = calibration
        self.right: CameraModel | None = None
        self.right_P: np.ndarray | None = None  # the right camera's projection: its P[0, 3] = -fx * baseline
        self.info_error = ""  # why the last CameraInfo was unusable ('' = it was not)
        self._und: Undistorter | None = None
        # a pair read through its R and P: each CameraInfo's (R, P), the rectification built from both, why it
        # could not be
        self._left_rp: tuple[np.ndarray, np.ndarray] | None = None
        self._right_rp: tuple[np.ndarray, np.ndarray] | None = None
        self._rect: StereoRectification | None = None
        self.rect_error = ""

    @property
    def _by_p(self) -> bool:
        """The pair's cameras come from the CameraInfos' R and P (raw or image_rect input)."""
        return self.stereo_input != "rectified"

    def set_camera(self, cam: CameraModel) -> None:
        self.cam = cam
        if self.undistort and not self._by_p and cam.has_distortion and (
                self._und is None or not self._und.matches(cam)):
            self._und = Undistorter(cam)

    def camera_info(self, msg) -> str:
        """Take a CameraInfo (ignored when a calibration file gives the intrinsics): '' or why it is unusable
        (then no camera until a usable one comes)."""
        if self.calibration is not None:
            return ""
        try:
            cam = CameraModel.from_camera_info(msg)
            rp = rectification_of(msg) if self._by_p else None
        except CameraInfoError as e:
            self.info_error, self.cam = str(e), None
            self._left_rp, self._rect = None, None
            return self.info_error
        self.info_error = ""
        if not cam.same_as(self.cam):
            self.set_camera(cam)
            self._prepare_registration()
        if rp is not None:
            self._left_rp = rp
            self._rectify()
            return self.rect_error
        return ""

    def right_info(self, msg) -> str:
        """Take the right camera's CameraInfo: '' or why it is unusable (then no right camera)."""
        try:
            right = CameraModel.from_camera_info(msg)
            if self._by_p:
                self._right_rp = rectification_of(msg)
            else:
                why = rectified_problem(msg)
                if self.cam is not None and self.cam.has_distortion:
                    why = "; ".join(w for w in (why, "the left camera's lens has distortion") if w)
                if why:
                    raise CameraInfoError(
                        f"it describes raw images ({why}): the pair is matched along its rows, which needs rectified "
                        "images; set camera.stereo_input to raw for a driver's raw images (rectified here), or to "
                        "image_rect for rectified images beside the raw cameras' CameraInfo (ROS's image_rect)")
        except CameraInfoError as e:
            self.right = self.right_P = None
            self._right_rp, self._rect = None, None
            return str(e)
        self.right = right
        P = np.asarray(msg.p, dtype=np.float64)
        # (of the images the camera sends, as K: a binned or cropped sensor's)
        self.right_P = sensor_reduction(msg)[0] @ P.reshape(3, 4) if P.size == 12 and np.all(np.isfinite(P)) else None
        if self._by_p:
            self._rectify()
            return self.rect_error
        return ""

    def depth_info(self, msg) -> str:
        """Take the depth camera's CameraInfo (depth images registered here): '' or why it is unusable."""
        try:
            depth_cam = CameraModel.from_camera_info(msg)
        except CameraInfoError as e:
            self.depth_cam, self.depth_error = None, str(e)
            return self.depth_error
        if not depth_cam.same_as(self.depth_cam):
            self.depth_cam = depth_cam
            self._prepare_registration()
        self.depth_error = ""
        return ""

    def _prepare_registration(self) -> None:
        """The depth registration's tables, made when both cameras are known (not on the first depth frame)."""
        if self.depth_to_color is not None and self.depth_cam is not None and self.cam is not None:
            from simreal_nodes.vision.depth import prepare_registration

            prepare_registration(self.depth_cam, self.cam)

    def _registered(self, arr: np.ndarray, encoding: str) -> Checked:
        """A depth image of the depth camera registered to the colour camera, in its own encoding (millimetres with
        0 for none, or metres with NaN)."""
        from simreal_nodes.vision.depth import register_depth

        if self.depth_cam is None:
            return Checked(f"unusable depth CameraInfo: {self.depth_error}" if self.depth_error
                           else "waiting for the depth camera's CameraInfo to register the depth image")
        assert self.cam is not None and self.depth_to_color is not None
        if (arr.shape[1], arr.shape[0]) != (self.depth_cam.width, self.depth_cam.height):
            return Checked(f"depth image is {arr.shape[1]}x{arr.shape[0]} but its CameraInfo says "
                           f"{self.depth_cam.width}x{self.depth_cam.height}")
        z = register_depth(images.depth_to_metres(arr, encoding), self.depth_cam, self.cam, self.depth_to_color)
        if encoding == "32FC1":
            return Checked(pixels=z)
        mm = np.rint(np.nan_to_num(z, nan=0.0) * 1e3)
        return Checked(pixels=np.where(mm <= 65535, mm, 0).astype(np.uint16))

    def _rectify(self) -> None:
        """The pair's rectification, (re)built once both CameraInfos are in hand (kept while they stay)."""
        if self.cam is None or self.right is None or self._left_rp is None or self._right_rp is None:
            return
        if self._rect is not None and self._rect.same(self.cam, self._left_rp, self.right, self._right_rp):
            return
        try:
            self._rect, self.rect_error = StereoRectification(self.cam, self._left_rp, self.right, self._right_rp,
                                                              rectified=self.stereo_input == "image_rect"), ""
        except CameraInfoError as e:
            self._rect, self.rect_error = None, str(e)

    @property
    def out_camera(self) -> CameraModel:
        """The camera of the published images: the ideal one when they are undistorted, the rectified one of a raw
        stereo pair."""
        assert self.cam is not None  # asked only once a frame passed check / file_frame, which need the camera
        if self._rect is not None:
            return self._rect.left_camera
        return self._und.ideal if self._und is not None else self.cam

    @property
    def out_right(self) -> tuple[CameraModel | None, np.ndarray | None]:
        """The published right camera and its projection (the baseline in its P[0, 3])."""
        if self._rect is not None:
            return self._rect.right_camera, self._rect.right_P
        return self.right, self.right_P

    def file_frame(self, f: Frame) -> str:
        """Take a frame of a file source (a bag's carries its CameraInfo, unless a calibration file wins): '' or
        why it cannot be published."""
        if f.error:
            return f.error
        if f.camera_info is not None and self.calibration is None:
            try:
                self.set_camera(CameraModel.from_camera_info(f.camera_info))
            except CameraInfoError as e:
                return f"unusable CameraInfo in bag: {e}"
        if self.cam is None:
            assert f.image is not None  # a frame without an error carries its image
            h, w = f.image.shape[:2]
            return f"no intrinsics for {w}x{h} frames: give camera.calibration (see `simreal calibrate`)"
        return ""

    def undistorted(self, kind: str, img: np.ndarray) -> np.ndarray:
        """An ``image`` or ``depth`` (nearest neighbour: depth is not blended across edges) undistorted when asked;
        ``img`` itself otherwise."""
        if self._und is None:
            return img
        return self._und.depth(img) if kind == "depth" else self._und.image(img)

    def check(self, kind: str, msg, arr: np.ndarray | None = None, encoding: str | None = None) -> Checked:
        """One incoming Image (anything with its fields) of stream ``kind``, its pixels ``arr`` and their
        ``encoding`` if already decoded (a decompressed image: its message has no encoding field):
        an ``image`` needs the camera and must be of its size, a ``depth`` must be 16UC1 or 32FC1, a ``right``
        image needs the right camera and passes as it is; every one must be well formed. The image and the depth
        are undistorted when asked."""
        if kind == "image" and self.cam is None:
            return Checked(f"unusable CameraInfo: {self.info_error}" if self.info_error
                           else "waiting for a valid CameraInfo")
        enc = encoding or getattr(msg, "encoding", None)
        if kind == "depth" and enc not in images.DEPTH_ENCODINGS:
            return Checked(f"depth encoding '{enc}' (expected 16UC1 or 32FC1)")
        if kind == "right" and self.right is None:
            return Checked("right image without a valid right CameraInfo")
        if self._by_p and kind == "depth":
            return Checked(f"a depth image beside a stereo pair read through its R and P (stereo_input "
                           f"{self.stereo_input}) is not rectified with it")
        if self._by_p and kind in ("image", "right") and self._rect is None:
            return Checked("waiting for both CameraInfos of the stereo pair to rectify it"
                           + (f" ({self.rect_error})" if self.rect_error else ""))
        if arr is None:
            try:
                arr = images.image_to_array(msg)
            except ImageFormatError as e:
                return Checked(f"malformed {_STREAM_NAMES[kind]}: {e}")
        if kind == "image":
            assert self.cam is not None  # an image without the camera returned above
            if (arr.shape[1], arr.shape[0]) != (self.cam.width, self.cam.height):
                return Checked(f"image is {arr.shape[1]}x{arr.shape[0]} but CameraInfo says "
                               f"{self.cam.width}x{self.cam.height}")
        if kind == "right":
            assert self.right is not None  # a right image without its camera returned above
            if (arr.shape[1], arr.shape[0]) != (self.right.width, self.right.height):
                return Checked(f"right image is {arr.shape[1]}x{arr.shape[0]} but its CameraInfo says "
                               f"{self.right.width}x{self.right.height}")
        if kind == "depth" and self.depth_refused:
            return Checked(self.depth_refused)
        if kind == "depth" and self.depth_to_color is not None:
            if self.cam is None:
                return Checked("waiting for a valid CameraInfo to register the depth image to")
            reg = self._registered(arr, enc or "")
            if reg.why or self._und is None:
                return reg
            assert reg.pixels is not None
            return Checked(pixels=self.undistorted(kind, reg.pixels))
        if self._rect is not None and kind in ("image", "right"):
            return Checked(pixels=self._rect.left(arr) if kind == "image" else self._rect.right(arr))
        return Checked(pixels=self.undistorted(kind, arr) if kind != "right" and self._und is not None else None)
