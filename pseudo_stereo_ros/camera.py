# Copyright 2026 The pseudo_stereo_ros Authors
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""
A calibrated camera: projection, undistortion and viewing rays.

Pixel coordinates are raw (distorted) pixels as a detector produces them.
"Ideal" pixels are the undistorted pinhole pixels ``K @ [x, y, 1]`` and
"normalized" coordinates are ``(x, y) = (X / Z, Y / Z)`` in the camera frame.

Degenerate geometry policy (the same in every module of the package): a
result that does not exist (a point on or behind the camera plane, parallel
rays) is NaN, never an exception; callers test with ``np.isfinite``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import TypeAlias

import cv2
import numpy as np

from .calibration import CameraCalibration, load_calibration, PathLike
from .records import Point3

__all__ = ['Camera']

# Undistortion is iterative; OpenCV's default 5 iterations leave tenths of a pixel on strongly
# distorted lenses (the real table-tennis rig has k3 = -7.7), so iterate to convergence.
_UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-14)

# f(points (N, 1, 2) raw pixels, K, D) -> (N, 1, 2) normalized coordinates
_Undistort: TypeAlias = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]


def _undistort_function() -> _Undistort:
    """Return f(points (N,1,2), K, D) -> normalized (N,1,2) for OpenCV 4.6 to 5."""
    iterative = getattr(cv2, 'undistortPointsIter', None)  # OpenCV 4.x
    if iterative is not None:
        return lambda pts, k, d: iterative(pts, k, d, None, None, _UNDISTORT_CRITERIA)
    return lambda pts, k, d: cv2.undistortPoints(pts, k, d, None, None,
                                                 criteria=_UNDISTORT_CRITERIA)


def _fisheye_undistort(pts: np.ndarray, k: np.ndarray, d: np.ndarray) -> np.ndarray:
    try:
        return cv2.fisheye.undistortPoints(pts, k, d, criteria=_UNDISTORT_CRITERIA)
    except TypeError:  # OpenCV < 4.7 has no criteria argument
        return cv2.fisheye.undistortPoints(pts, k, d)


_UNDISTORT = _undistort_function()


def _camera(calibration: CameraCalibration, name: str) -> Camera:
    """Rebuild a pickled :class:`Camera`."""
    return Camera(calibration, name=name)


def _point3(values: Iterable[float]) -> Point3:
    """Return three numbers as a plain-float (x, y, z) tuple."""
    x, y, z = values
    return float(x), float(y), float(z)


class Camera:
    """
    One calibrated camera (see :mod:`pseudo_stereo_ros.calibration` for the conventions).

    :param calibration: intrinsics, distortion and pose
    :param name: the name the data uses for this camera (default: the file's ``camera_name``)
    """

    def __init__(self, calibration: CameraCalibration, *, name: str | None = None) -> None:
        self.calibration = calibration
        self.name = calibration.camera_name if name is None else str(name)
        self.K = np.array(calibration.camera_matrix, dtype=float)
        self.D = np.array(calibration.dist_coeffs, dtype=float)
        self.R = np.array(calibration.rotation, dtype=float)
        self.t = np.array(calibration.translation, dtype=float)
        self.image_size: tuple[int, int] = (calibration.image_width, calibration.image_height)
        self.fisheye = calibration.distortion_model == 'equidistant'
        #: Optical centre in the world frame, (3,) [m].
        self.center = -self.R.T @ self.t
        self._rvec = cv2.Rodrigues(self.R)[0]
        self._undistort: _Undistort = _fisheye_undistort if self.fisheye else _UNDISTORT
        # Plain-float copies for the fuser's per-event path (numpy is slow on 3-vectors).
        self.center_tuple: Point3 = _point3(self.center)
        r_t = self.R.T
        self.rotation_t_rows: tuple[Point3, Point3, Point3] = (
            _point3(r_t[0]), _point3(r_t[1]), _point3(r_t[2]))
        # Without distortion (a pinhole, no skew) undistortion is a closed form, the one OpenCV
        # computes, bit for bit: (u - cx) * (1 / fx), (v - cy) * (1 / fy) (tested).
        self._pinhole: tuple[float, float, float, float] | None = None
        if not self.fisheye and not np.any(self.D) and self.K[0, 1] == 0.0 and \
                np.array_equal(self.K[2], (0.0, 0.0, 1.0)):
            self._pinhole = (float(self.K[0, 2]), 1.0 / float(self.K[0, 0]),
                             float(self.K[1, 2]), 1.0 / float(self.K[1, 1]))

    @classmethod
    def from_file(cls, path: PathLike, *, name: str | None = None) -> Camera:
        """Load a camera from its calibration YAML file (optionally under another name)."""
        return cls(load_calibration(path), name=name)

    def __repr__(self) -> str:
        return f'Camera({self.name!r}, center={np.round(self.center, 3).tolist()})'

    def __reduce__(self):
        """Pickle as the calibration and the name (to run work in another process)."""
        return _camera, (self.calibration, self.name)

    # -- world -> image -------------------------------------------------------------------------

    def world_to_camera(self, points: np.ndarray) -> np.ndarray:
        """Return (N, 3) camera-frame coordinates of (N, 3) world points [m]."""
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        return points @ self.R.T + self.t

    def project(self, points: np.ndarray) -> np.ndarray:
        """
        Project world points to raw (distorted) pixels.

        :param points: (N, 3) or (3,) world points [m]
        :return: (N, 2) raw pixels; NaN rows for points on or behind the camera plane
        """
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        if len(points) == 0:  # cv2.projectPoints returns None for no points
            return np.empty((0, 2))
        depth = self.world_to_camera(points)[:, 2]
        object_points = points.reshape(-1, 1, 3)
        if self.fisheye:
            pixels = cv2.fisheye.projectPoints(object_points, self._rvec, self.t, self.K,
                                               self.D)[0]
        else:
            pixels = cv2.projectPoints(object_points, self._rvec, self.t, self.K, self.D)[0]
        pixels = pixels.reshape(-1, 2)
        pixels[~(depth > 0)] = np.nan
        return pixels

    # -- image -> world -------------------------------------------------------------------------

    def normalize(self, pixels: np.ndarray) -> np.ndarray:
        """
        Undistort raw pixels to normalized camera coordinates.

        :param pixels: (N, 2) or (2,) raw pixels
        :return: (N, 2) normalized coordinates (X/Z, Y/Z)
        """
        pixels = np.asarray(pixels, dtype=float).reshape(-1, 1, 2)
        if len(pixels) == 0:
            return np.empty((0, 2))
        return self._undistort(pixels, self.K, self.D).reshape(-1, 2)

    def normalize_one(self, u: float, v: float) -> tuple[float, float]:
        """Undistort one raw pixel to a normalized (x, y) pair of floats."""
        pinhole = self._pinhole
        if pinhole is not None:
            cx, fx_inverse, cy, fy_inverse = pinhole
            return float((u - cx) * fx_inverse), float((v - cy) * fy_inverse)
        xy = self._undistort(np.array(((u, v),), dtype=float).reshape(1, 1, 2), self.K, self.D)
        return float(xy[0, 0, 0]), float(xy[0, 0, 1])

    def ideal_pixels(self, pixels: np.ndarray) -> np.ndarray:
        """Return (N, 2) undistorted pinhole pixels ``K @ [x, y, 1]`` of (N, 2) raw pixels."""
        return self.normalized_to_ideal(self.normalize(pixels))

    def normalized_to_ideal(self, normalized: np.ndarray) -> np.ndarray:
        """Return (N, 2) ideal pixels of (N, 2) normalized coordinates."""
        normalized = np.asarray(normalized, dtype=float).reshape(-1, 2)
        return normalized @ self.K[:2, :2].T + self.K[:2, 2]

    def ideal_to_normalized(self, ideal: np.ndarray) -> np.ndarray:
        """Return (N, 2) normalized coordinates of (N, 2) ideal pixels."""
        ideal = np.asarray(ideal, dtype=float).reshape(-1, 2)
        return np.linalg.solve(self.K[:2, :2], (ideal - self.K[:2, 2]).T).T

    def ray_directions(self, normalized: np.ndarray) -> np.ndarray:
        """
        Return world-frame viewing-ray directions of normalized coordinates.

        :param normalized: (N, 2) normalized coordinates
        :return: (N, 3) directions (not unit length; the camera-frame Z component is 1)
        """
        normalized = np.asarray(normalized, dtype=float).reshape(-1, 2)
        homogeneous = np.hstack((normalized, np.ones((len(normalized), 1))))
        return homogeneous @ self.R

    def rays(self, pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """
        Return the viewing rays of raw pixels.

        :param pixels: (N, 2) raw pixels
        :return: ``(origin, directions)``: the optical centre (3,) [m] and (N, 3) directions
        """
        return self.center, self.ray_directions(self.normalize(pixels))

    def direction_of(self, x: float, y: float) -> Point3:
        """Return the world direction (3 floats) of one normalized point; per-event fast path."""
        r0, r1, r2 = self.rotation_t_rows
        return (r0[0] * x + r0[1] * y + r0[2],
                r1[0] * x + r1[1] * y + r1[2],
                r2[0] * x + r2[1] * y + r2[2])

    def in_image(self, pixels: np.ndarray) -> np.ndarray:
        """Return an (N,) mask of finite pixels inside the image."""
        pixels = np.asarray(pixels, dtype=float).reshape(-1, 2)
        width, height = self.image_size
        with np.errstate(invalid='ignore'):
            return ((pixels[:, 0] >= 0) & (pixels[:, 0] <= width - 1)
                    & (pixels[:, 1] >= 0) & (pixels[:, 1] <= height - 1))
