"""Pinhole camera with OpenCV distortion: the one camera model every part of simreal uses.

Two lens models, as sensor_msgs/CameraInfo names them: ``plumb_bob`` / ``rational_polynomial`` (OpenCV's radial
and tangential model, 4-14 coefficients) and ``equidistant`` (the fisheye model of OpenCV's ``cv::fisheye`` and ROS's
image_geometry, 4 coefficients k1..k4: a ray at angle theta off the optical axis lands at the radius
f * theta * (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8)). Everything past the lens works in the ideal
pinhole image of the same K, so a fisheye serves rays up to under 90 degrees off the axis; a pixel beyond (a
circular fisheye's dark corners) has no ideal pixel: NaN.

Conventions (REP-103 optical frame): x right, y down, z forward. Pixel (u, v) with the centre of
the top-left pixel at (0, 0), as in OpenCV and sensor_msgs/CameraInfo.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from simreal_nodes.errors import CameraInfoError, ImageFormatError

DISTORTION_MODELS = ("plumb_bob", "rational_polynomial", "equidistant", "none", "")
CALIBRATION_MODELS = ("plumb_bob", "rational_polynomial", "equidistant")  # `simreal calibrate --model`
# the overlay's distortion map: exact every 4th pixel, bilinear between (CameraModel.ideal_pixel_map)
IDEAL_MAP_STEP = 4
MAX_IMAGE_SIDE = 16384  # pixels: above any camera the graph serves (and OpenGL's usual texture limit)
# a pinhole lens's coefficients must map the image's border back onto itself this closely (CameraModel.validate)
BORDER_ROUND_TRIP_PX = 0.01
_ROUND_TRIPS: dict[tuple, float] = {}  # each lens's border round trip (px), keyed by its size, K, D and model
LENS_TABLE_SIZE = 20001  # samples of a fisheye's lens curve over 0-90 degrees (CameraModel.stretch): 8e-5 rad apart


@dataclass
class CameraModel:
    """Intrinsics of one camera: image size, K (3x3), distortion D (OpenCV order)."""

    width: int
    height: int
    K: np.ndarray
    D: np.ndarray = field(default_factory=lambda: np.zeros(5))
    distortion_model: str = "plumb_bob"
    frame_id: str = "camera_optical_frame"

    def __post_init__(self):
        self.K = np.asarray(self.K, dtype=np.float64).reshape(3, 3)
        self.D = np.asarray(self.D, dtype=np.float64).ravel()
        self.validate()

    # -- construction -------------------------------------------------------------------
    @classmethod
    def from_intrinsics(cls, width, height, fx, fy, cx, cy, D=None, **kw) -> CameraModel:
        K = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1]], dtype=np.float64)
        return cls(int(width), int(height), K, np.zeros(5) if D is None else np.asarray(D), **kw)

    @classmethod
    def from_camera_info(cls, msg) -> CameraModel:
        """From a sensor_msgs/CameraInfo (rclpy or rosbags message); validates it. A CameraInfo with binning or a
        region of interest (a camera that sends a binned or cropped part of its calibrated sensor) gives the camera of
        the images it sends: K reduced as ROS's image_geometry reduces it (:func:`sensor_reduction`), the size the
        region's divided by the binning; the lens coefficients are the sensor's (they act on normalized
        coordinates, which the reduction keeps)."""
        k = np.asarray(msg.k, dtype=np.float64)
        if k.size != 9:
            raise CameraInfoError(f"CameraInfo.k has {k.size} values, expected 9")
        d = np.asarray(msg.d, dtype=np.float64)
        model = str(msg.distortion_model)
        frame = str(msg.header.frame_id) or "camera_optical_frame"
        S, (w, h) = sensor_reduction(msg)
        return cls(w, h, S @ k.reshape(3, 3), d, model, frame)

    def validate(self) -> None:
        if self.width <= 0 or self.height <= 0:
            raise CameraInfoError(f"camera image size {self.width}x{self.height} is not positive")
        if max(self.width, self.height) > MAX_IMAGE_SIDE:
            raise CameraInfoError(f"camera image size {self.width}x{self.height} is over {MAX_IMAGE_SIDE} pixels a "
                                  "side (a damaged CameraInfo?)")
        K = self.K
        if not np.all(np.isfinite(K)):
            raise CameraInfoError("camera matrix K has NaN or inf entries")
        fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
        if fx <= 0 or fy <= 0:
            raise CameraInfoError(
                f"camera focal lengths must be positive, found fx={fx:g}, fy={fy:g} "
                "(an all-zero CameraInfo means the camera is not calibrated)")
        if abs(K[2, 2] - 1.0) > 1e-9 or abs(K[1, 0]) > 1e-9 or K[2, 0] != 0 or K[2, 1] != 0:
            raise CameraInfoError(f"camera matrix K is not of the form [[fx,s,cx],[0,fy,cy],[0,0,1]]: {K.tolist()}")
        if not (-self.width < cx < 2 * self.width and -self.height < cy < 2 * self.height):
            raise CameraInfoError(
                f"principal point ({cx:g}, {cy:g}) is far outside the {self.width}x{self.height} image")
        if self.distortion_model not in DISTORTION_MODELS:
            raise CameraInfoError(
                f"distortion model '{self.distortion_model}' is not supported "
                f"(expected one of {', '.join(m for m in DISTORTION_MODELS if m)})")
        if not np.all(np.isfinite(self.D)):
            raise CameraInfoError("distortion coefficients have NaN or inf entries")
        if self.fisheye and len(self.D) != 4:
            raise CameraInfoError(f"the equidistant (fisheye) model takes 4 distortion coefficients k1..k4, "
                                  f"found {len(self.D)}")
        if len(self.D) not in (0, 4, 5, 8, 12, 14):
            raise CameraInfoError(f"{len(self.D)} distortion coefficients (OpenCV takes 4, 5, 8, 12 or 14)")
        if self.has_distortion and not self.fisheye:
            # judged once per lens: a node builds its camera from every CameraInfo, which comes with every frame
            key = (self.width, self.height, self.K.tobytes(), self.D.tobytes(), self.distortion_model)
            miss = _ROUND_TRIPS.get(key)
            if miss is None:
                miss = self._border_round_trip()
                if len(_ROUND_TRIPS) >= 64:
                    _ROUND_TRIPS.clear()
                _ROUND_TRIPS[key] = miss
            if not miss < BORDER_ROUND_TRIP_PX:
                raise CameraInfoError(
                    f"the distortion coefficients {np.round(self.D, 6).tolist()} do not invert over the "
                    f"{self.width}x{self.height} image: its border pixels undistorted and distorted again land up to "
                    f"{miss:.3g} px from where they were (the lens curve turns back inside the image, or these are "
                    "not a lens's coefficients: a damaged CameraInfo?)")

    def _border_round_trip(self) -> float:
        """The largest distance (px) between a pixel on the image's border (its corners, edge midpoints and more:
        the pixels farthest from the axis, where distortion is strongest) and where it lands undistorted
        (:meth:`undistort_points`, OpenCV's iteration) and distorted again (:meth:`project`): about 1e-10 px for a
        real lens, far more (or NaN) where the radial curve turns back before the corners (no ideal pixel to find) or
        the iteration does not converge. A fisheye is not judged here: its pixels past the curve's turning point
        are NaN by design (a circular fisheye's dark corners)."""
        t = np.linspace(0.0, 1.0, 9)
        w, h = self.width - 1.0, self.height - 1.0
        uv = np.vstack([np.c_[t * w, np.zeros_like(t)], np.c_[t * w, np.full_like(t, h)],
                        np.c_[np.zeros_like(t), t * h], np.c_[np.full_like(t, w), t * h]])
        ideal = self.undistort_points(uv)
        y = (ideal[:, 1] - self.cy) / self.fy
        x = (ideal[:, 0] - self.cx - self.K[0, 1] * y) / self.fx
        with np.errstate(all="ignore"):
            back = self.project(np.c_[x, y, np.ones(len(x))])
            return float(np.max(np.linalg.norm(back - uv, axis=1)))

    def check_size(self, image: np.ndarray, what: str = "image") -> None:
        """ImageFormatError unless ``image`` (rows x columns [x channels]) has this camera's size: a frame of
        another size than its CameraInfo says cannot be back-projected or matched against this camera."""
        if image.shape[:2] != (self.height, self.width):
            raise ImageFormatError(f"{what} is {image.shape[1]}x{image.shape[0]}, CameraInfo says "
                                   f"{self.width}x{self.height}")

    # -- properties ---------------------------------------------------------------------
    @property
    def fx(self) -> float:
        return float(self.K[0, 0])

    @property
    def fy(self) -> float:
        return float(self.K[1, 1])

    @property
    def cx(self) -> float:
        return float(self.K[0, 2])

    @property
    def cy(self) -> float:
        return float(self.K[1, 2])

    @property
    def fisheye(self) -> bool:
        """The equidistant (fisheye) lens model: OpenCV's ``cv2.fisheye`` functions, not its pinhole ones."""
        return self.distortion_model == "equidistant"

    @property
    def has_distortion(self) -> bool:
        """Whether pixels differ from the ideal pinhole image's. Always so for a fisheye: with k1..k4 all zero it
        still maps a ray at theta to the radius f * theta, not the pinhole's f * tan(theta)."""
        return self.fisheye or (self.distortion_model not in ("none", "") and bool(np.any(self.D != 0)))

    def cv_dist(self) -> np.ndarray:
        """Distortion vector as OpenCV's pinhole functions want it (zeros when none). A fisheye's coefficients
        mean something else to those: use :meth:`project`, :meth:`undistort_points` and :meth:`undistort_maps`."""
        if self.fisheye:
            raise CameraInfoError("an equidistant (fisheye) camera's coefficients are not OpenCV pinhole distortion")
        return self.D.copy() if self.has_distortion else np.zeros(5)

    def same_as(self, other: CameraModel | None) -> bool:
        """The same image size, K, lens model and coefficients (a camera's derived maps can be kept)."""
        return other is not None and (self.width, self.height) == (other.width, other.height) \
            and np.allclose(self.K, other.K) and self.has_distortion == other.has_distortion \
            and (not self.has_distortion or (self.fisheye == other.fisheye and self.D.shape == other.D.shape
                                             and np.allclose(self.D, other.D)))

    def scaled(self, factor: float) -> CameraModel:
        """The same camera at a resolution scaled by ``factor`` (pixel-centre convention kept)."""
        K = self.K.copy()
        K[0, 0] *= factor
        K[1, 1] *= factor
        K[0, 2] = (K[0, 2] + 0.5) * factor - 0.5
        K[1, 2] = (K[1, 2] + 0.5) * factor - 0.5
        return CameraModel(round(self.width * factor), round(self.height * factor), K,
                           self.D.copy(), self.distortion_model, self.frame_id)

    # -- geometry -----------------------------------------------------------------------
    def project(self, points_cam: np.ndarray, distort: bool = True) -> np.ndarray:
        """Project (N, 3) points in the optical frame to (N, 2) pixels. z <= 0 gives NaN."""
        P = np.asarray(points_cam, dtype=np.float64).reshape(-1, 3)
        out = np.full((P.shape[0], 2), np.nan)
        ok = P[:, 2] > 1e-9
        if not np.any(ok):
            return out
        if distort and self.has_distortion:
            import cv2

            if self.fisheye:
                uv, _ = cv2.fisheye.projectPoints(P[ok].reshape(-1, 1, 3), np.zeros(3), np.zeros(3), self.K, self.D)
            else:
                uv, _ = cv2.projectPoints(P[ok], np.zeros(3), np.zeros(3), self.K, self.D)
            out[ok] = uv.reshape(-1, 2)
        else:
            x = P[ok, 0] / P[ok, 2]
            y = P[ok, 1] / P[ok, 2]
            out[ok, 0] = self.fx * x + self.K[0, 1] * y + self.cx
            out[ok, 1] = self.fy * y + self.cy
        return out

    def undistort_points(self, uv: np.ndarray) -> np.ndarray:
        """Distorted pixels -> ideal (undistorted) pixels of the same K. A fisheye pixel whose ray is not in front of
        the camera (90 degrees or more off the axis, or past the lens polynomial's turning point) gives NaN: OpenCV's
        iteration returns a point on the wrong side there, so every result is projected back and kept only where it
        lands within a hundredth of a pixel of where it came from."""
        uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
        if not self.has_distortion or uv.size == 0:
            return uv.copy()
        import cv2

        crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-10)
        if not self.fisheye:
            return cv2.undistortPoints(uv.reshape(-1, 1, 2), self.K, self.D, None, self.K, criteria=crit).reshape(-1, 2)
        und = cv2.fisheye.undistortPoints(uv.reshape(-1, 1, 2), self.K, self.D, None, self.K,
                                          criteria=crit).reshape(-1, 2)
        y = (und[:, 1] - self.cy) / self.fy
        x = (und[:, 0] - self.cx - self.K[0, 1] * y) / self.fx
        with np.errstate(invalid="ignore"):
            back = self.project(np.c_[x, y, np.ones(len(x))])
            und[~(np.linalg.norm(back - uv, axis=1) < 0.01)] = np.nan
        return und

    def stretch(self, uv: np.ndarray) -> np.ndarray:
        """(N,) ideal pixels per image pixel at the distorted pixels ``uv``: the larger singular value of the
        undistortion's Jacobian. A fisheye's periphery is stretched in the ideal image (about 1 / cos^2 theta
        radially: 4 at 60 degrees), so a pixel's measurement error is that many ideal pixels there; 1 without
        distortion, NaN where a pixel has no ideal one. A fisheye's is exact (its lens is radial: the Jacobian in
        closed form from the ray's angle, read off a table of the lens curve built once per camera); other lenses'
        by central differences of half a pixel."""
        uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
        if not self.has_distortion or not len(uv):
            return np.ones(len(uv))
        if self.fisheye:
            return self._fisheye_stretch(uv)
        h = 0.5
        d = [self.undistort_points(uv + s) for s in ((h, 0), (-h, 0), (0, h), (0, -h))]
        a, c = ((d[0] - d[1]) / (2 * h)).T  # d ideal / d u
        b, e = ((d[2] - d[3]) / (2 * h)).T  # d ideal / d v
        return _larger_singular_value(a, b, c, e)

    def _fisheye_stretch(self, uv: np.ndarray) -> np.ndarray:
        """The equidistant lens's stretch. In normalized coordinates a pixel at the lens radius r_d = theta_d (its
        ray theta off the axis, theta_d = theta (1 + k1 theta^2 + ... + k4 theta^8)) goes to the ideal radius
        g = tan(theta): the undistortion's Jacobian is (g / r_d) I + (g' - g / r_d) n n^T (n the radial direction,
        g' = (1 / cos^2 theta) / (d theta_d / d theta)), and in pixels K2 J F^-1 (K2: K's upper-left 2 x 2, F its
        diagonal: OpenCV's fisheye functions read the lens side without K's skew, the ideal side with it)."""
        theta_d, theta = self._lens_table()
        K2 = self.K[:2, :2]
        f = np.array([self.fx, self.fy])
        xn = (uv - self.K[:2, 2]) / f  # distorted normalized coordinates
        rd = np.hypot(xn[:, 0], xn[:, 1])
        # past the table (at or past 90 degrees, or past the lens curve's turning point) or past pi / 2, where
        # OpenCV's undistortion stops (undistort_points: NaN)
        inside = rd < min(theta_d[-1], np.pi / 2)
        t = np.interp(rd, theta_d, theta)
        k1, k2, k3, k4 = self.D
        t2 = t * t
        slope = 1 + t2 * (3 * k1 + t2 * (5 * k2 + t2 * (7 * k3 + t2 * 9 * k4)))  # d theta_d / d theta
        small = rd <= 1e-12
        with np.errstate(divide="ignore", invalid="ignore"):
            radial = 1.0 / (np.cos(t) ** 2 * slope)
            tangential = np.where(small, radial, np.tan(t) / np.where(small, 1.0, rd))  # g / r_d -> g'(0) at 0
            n = xn / np.where(small, 1.0, rd)[:, None]
        # J = K2 (tangential I + (radial - tangential) n n^T) F^-1
        J = (tangential[:, None, None] * (K2 / f)[None]
             + (radial - tangential)[:, None, None] * ((n @ K2.T)[:, :, None] * (n / f)[:, None, :]))
        out = _larger_singular_value(J[:, 0, 0], J[:, 0, 1], J[:, 1, 0], J[:, 1, 1])
        out[~inside] = np.nan
        return out

    def _lens_table(self) -> tuple[np.ndarray, np.ndarray]:
        """The equidistant lens curve theta -> theta_d sampled finely over the rays it serves (from the axis to 90
        degrees or to where the curve turns back, whichever comes first), kept per K and coefficients."""
        key = (self.K.tobytes(), self.D.tobytes())
        cached = getattr(self, "_lens_memo", None)
        if cached is not None and cached[0] == key:
            return cached[1]
        k1, k2, k3, k4 = self.D
        theta = np.linspace(0.0, np.pi / 2, LENS_TABLE_SIZE)
        t2 = theta * theta
        theta_d = theta * (1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))
        rising = np.flatnonzero(np.diff(theta_d) <= 0)
        end = int(rising[0]) + 1 if len(rising) else len(theta)
        table = (theta_d[:end].copy(), theta[:end].copy())
        object.__setattr__(self, "_lens_memo", (key, table))
        return table

    def undistort_maps(self, new_K: np.ndarray, size: tuple[int, int], m1type: int,
                       R: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """OpenCV's remap maps from the ideal pinhole image of ``new_K`` and ``size`` (width, height) to this camera's
        pixels (``cv2.initUndistortRectifyMap``, or its fisheye counterpart for an equidistant lens); ``R``: the
        ideal camera turned by it (a stereo pair's rectification, CameraInfo's R), else the identity."""
        import cv2

        R = np.eye(3) if R is None else np.asarray(R, np.float64)
        if self.fisheye:
            return cv2.fisheye.initUndistortRectifyMap(self.K, self.D, R, new_K, size, m1type)
        return cv2.initUndistortRectifyMap(self.K, self.cv_dist(), R, new_K, size, m1type)

    def ideal_pixel_map(self, step: int = IDEAL_MAP_STEP) -> np.ndarray:
        """(height, width, 2) float64: the ideal (undistorted) pixel of every pixel of the image, as
        :meth:`undistort_points` gives it, computed exactly at every ``step``-th pixel (the grid reaching the first
        multiple of ``step`` at or past the last row and column) and bilinear between. The distortion varies slowly
        over a few pixels: at the default step the map is within 0.02 px of the exact one on a strong barrel
        distortion (tests/test_camera.py) at about a tenth of the time (`./run bench ideal_map`: at 640 x 480 5-8 ms
        against 50-84; the overlay builds it when the camera comes, and its first frame waits for that). ``step`` 1:
        every pixel exactly; else a power of two up to 32, so that every fraction k / step is exact however the
        interpolation holds its weights (OpenCV's fixed-point bilinear remap: multiples of 1/32)."""
        W, H = self.width, self.height
        if step not in (1, 2, 4, 8, 16, 32):
            raise ValueError(f"step {step}: 1 or a power of two up to 32")
        if step == 1:
            xs, ys = np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64))
            return self.undistort_points(np.c_[xs.ravel(), ys.ravel()]).reshape(H, W, 2)
        import cv2

        gx = np.arange(0, W - 1 + step, step, dtype=np.float64)
        gy = np.arange(0, H - 1 + step, step, dtype=np.float64)
        GX, GY = np.meshgrid(gx, gy)
        coarse = self.undistort_points(np.c_[GX.ravel(), GY.ravel()]).reshape(len(gy), len(gx), 2)
        mx, my = np.meshgrid(np.arange(W, dtype=np.float32) / step, np.arange(H, dtype=np.float32) / step)
        # float32 lookups of float32 values: about 1e-4 px at 1 000 px, far under the interpolation's own error
        return np.dstack([cv2.remap(np.ascontiguousarray(coarse[..., k], dtype=np.float32), mx, my, cv2.INTER_LINEAR)
                          for k in range(2)]).astype(np.float64)

    def backproject(self, uv: np.ndarray, depth: np.ndarray) -> np.ndarray:
        """Ideal (undistorted) pixels + z-depth -> (N, 3) points in the optical frame."""
        uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
        z = np.asarray(depth, dtype=np.float64).ravel()
        y = (uv[:, 1] - self.cy) / self.fy
        x = (uv[:, 0] - self.cx - self.K[0, 1] * y) / self.fx
        return np.stack([x * z, y * z, z], axis=1)

    # -- CameraInfo / calibration files -------------------------------------------------
    def camera_info_fields(self) -> dict:
        """Field values for a sensor_msgs/CameraInfo (R = I, P = [K|0])."""
        P = np.zeros((3, 4))
        P[:, :3] = self.K
        return dict(height=self.height, width=self.width,
                    distortion_model=self.distortion_model or "plumb_bob",
                    d=[float(x) for x in self.D], k=[float(x) for x in self.K.ravel()],
                    r=[1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0], p=[float(x) for x in P.ravel()])

    def to_calibration_yaml(self, path: str | Path, camera_name: str = "camera") -> None:
        """Write the ROS camera_calibration YAML format (readable by camera_info_manager)."""
        f = self.camera_info_fields()
        doc = {
            "image_width": self.width, "image_height": self.height, "camera_name": camera_name,
            "camera_matrix": {"rows": 3, "cols": 3, "data": f["k"]},
            "distortion_model": f["distortion_model"],
            "distortion_coefficients": {"rows": 1, "cols": len(f["d"]), "data": f["d"]},
            "rectification_matrix": {"rows": 3, "cols": 3, "data": f["r"]},
            "projection_matrix": {"rows": 3, "cols": 4, "data": f["p"]},
        }
        Path(path).write_text(yaml.safe_dump(doc, sort_keys=False))

    @classmethod
    def from_calibration_yaml(cls, path: str | Path) -> CameraModel:
        """Read the ROS camera_calibration YAML format; errors name the missing or bad key."""
        path = Path(path)
        try:
            doc = yaml.safe_load(path.read_text())
        except FileNotFoundError:
            raise CameraInfoError(f"calibration file not found: {path}") from None
        except yaml.YAMLError as e:
            raise CameraInfoError(f"{path}: not valid YAML: {e}") from None
        if not isinstance(doc, dict):
            raise CameraInfoError(f"{path}: expected a mapping at the top level")

        def get(key):
            if key not in doc:
                raise CameraInfoError(f"{path}: missing key '{key}'")
            return doc[key]

        def matrix(key, n):
            m = get(key)
            data = m.get("data") if isinstance(m, dict) else None
            if not isinstance(data, list) or (n and len(data) != n):
                raise CameraInfoError(f"{path}: '{key}.data' must be a list of {n or 'some'} numbers")
            return np.asarray(data, dtype=np.float64)

        K = matrix("camera_matrix", 9).reshape(3, 3)
        D = matrix("distortion_coefficients", 0) if "distortion_coefficients" in doc else np.zeros(5)
        return cls(int(get("image_width")), int(get("image_height")), K, D,
                   str(doc.get("distortion_model", "plumb_bob")),
                   frame_id=str(doc.get("frame_id", "camera_optical_frame")))


def _larger_singular_value(a, b, c, e):
    """The larger singular value of each 2 x 2 matrix [[a, b], [c, e]] (arrays of the entries)."""
    p, q = (a * a + b * b + c * c + e * e) / 2, a * e - b * c
    return np.sqrt(p + np.sqrt(np.maximum(p * p - q * q, 0.0)))


def sensor_reduction(msg) -> tuple[np.ndarray, tuple[int, int]]:
    """The 3 x 3 map S from a CameraInfo's full-sensor pixels to the pixels of the images the camera sends, and their
    size (width, height): its binning (``binning_x`` / ``binning_y``, 0 or 1 for none) and region of interest
    (``roi``, in full-sensor pixels; all zero for the whole sensor), as REP 104 defines them and ROS's image_geometry
    applies them (u' = (u - x_offset) / binning_x: K' = S K, P' = S P). The identity and the CameraInfo's own size
    when it has neither; CameraInfoError for a binning or region that does not fit the sensor."""
    try:
        W, H = int(msg.width), int(msg.height)
        bx, by = int(getattr(msg, "binning_x", 0) or 0), int(getattr(msg, "binning_y", 0) or 0)
        roi = getattr(msg, "roi", None)
        rx, ry, rw, rh = ((int(roi.x_offset), int(roi.y_offset), int(roi.width), int(roi.height)) if roi is not None
                          else (0, 0, 0, 0))
    except (TypeError, ValueError, OverflowError, AttributeError) as e:
        raise CameraInfoError(f"CameraInfo size, binning or region of interest is not whole numbers: {e}") from None
    if W <= 0 or H <= 0:  # (no sensor to reduce: the model's own check says so)
        return np.eye(3), (W, H)
    if bx < 0 or by < 0:
        raise CameraInfoError(f"CameraInfo binning {bx} x {by} is negative")
    bx, by = max(bx, 1), max(by, 1)
    if rw == 0 and rh == 0 and rx == 0 and ry == 0:  # all zero: the whole sensor
        rw, rh = W, H
    if rw <= 0 or rh <= 0 or rx < 0 or ry < 0 or rx + rw > W or ry + rh > H:
        raise CameraInfoError(f"CameraInfo region of interest {rw}x{rh} at ({rx}, {ry}) does not fit its {W}x{H} "
                              "sensor")
    w, h = rw // bx, rh // by
    if w <= 0 or h <= 0:
        raise CameraInfoError(f"CameraInfo binning {bx} x {by} leaves no pixel of the {rw}x{rh} region")
    S = np.array([[1.0 / bx, 0.0, -rx / bx], [0.0, 1.0 / by, -ry / by], [0.0, 0.0, 1.0]])
    return S, (w, h)

