"""Undistortion with cached maps (computed once per camera model, applied per frame)."""

from __future__ import annotations

import cv2
import numpy as np

from simreal_nodes.camera import CameraModel


class Undistorter:
    """Remaps distorted images to the ideal pinhole image of the same K (distortion zero)."""

    def __init__(self, cam: CameraModel):
        self.cam = cam
        self.ideal = CameraModel(cam.width, cam.height, cam.K.copy(), np.zeros(5), "plumb_bob", cam.frame_id)
        self._maps = cv2.initUndistortRectifyMap(cam.K, cam.cv_dist(), None, cam.K,
                                                 (cam.width, cam.height), cv2.CV_16SC2)

    def matches(self, cam: CameraModel) -> bool:
        return (cam.width, cam.height) == (self.cam.width, self.cam.height) and np.allclose(cam.K, self.cam.K) \
            and np.allclose(cam.cv_dist(), self.cam.cv_dist())

    def image(self, img: np.ndarray) -> np.ndarray:
        return cv2.remap(img, self._maps[0], self._maps[1], cv2.INTER_LINEAR)

    def depth(self, depth: np.ndarray) -> np.ndarray:
        """Depth must not be blended across edges: nearest-neighbour remap."""
        return cv2.remap(depth, self._maps[0], self._maps[1], cv2.INTER_NEAREST)
