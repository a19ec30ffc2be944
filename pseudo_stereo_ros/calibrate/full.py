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
Full calibration: intrinsics, distortion and pose from 3D <-> pixel correspondences.

As in the paper: a linear DLT start (:func:`dlt_projection`,
:func:`decompose_projection`) refined by OpenCV's Levenberg-Marquardt, from
at least 6 non-coplanar correspondences (:func:`calibrate_full`).
"""

from __future__ import annotations

from collections.abc import Sequence
import math

import cv2
import numpy as np
from numpy.typing import ArrayLike

from .checks import (CalibrationResult, check_correspondences, check_front, check_image_size,
                     check_inside, check_intrinsics, COPLANAR_RATIO, distortion_flags,
                     LineNumbers, LM_CRITERIA, make_calibration, make_result, point_spread)
from ..camera import Camera
from ..errors import CalibrationFitError

__all__ = [
    'auto_dist_terms',
    'calibrate_full',
    'decompose_projection',
    'dlt_projection',
]


def _normalizing_transform(points: np.ndarray) -> np.ndarray:
    """Return T ((d+1) x (d+1)) moving the centroid to 0 and the mean distance to sqrt(d)."""
    dim = points.shape[1]
    centroid = points.mean(axis=0)
    scale = math.sqrt(dim) / np.mean(np.linalg.norm(points - centroid, axis=1))
    transform = np.eye(dim + 1)
    transform[:dim, :dim] *= scale
    transform[:dim, dim] = -scale * centroid
    return transform


def dlt_projection(world: np.ndarray, pixels: np.ndarray) -> np.ndarray:
    """
    Return the 3x4 projection matrix P of the linear DLT fit (Hartley-normalized).

    :param world: (N, 3) world points, N >= 6, not coplanar
    :param pixels: (N, 2) pixels (distortion is ignored by the linear model)
    :return: P with ``s [u, v, 1] = P [X, Y, Z, 1]``, scaled so that ``det(P[:, :3]) > 0``
    """
    t_world = _normalizing_transform(world)
    t_image = _normalizing_transform(pixels)
    xw = np.hstack((world, np.ones((len(world), 1)))) @ t_world.T
    xi = np.hstack((pixels, np.ones((len(pixels), 1)))) @ t_image.T
    rows = np.zeros((2 * len(world), 12))
    rows[0::2, 0:4] = xw
    rows[0::2, 8:12] = -xi[:, :1] * xw
    rows[1::2, 4:8] = xw
    rows[1::2, 8:12] = -xi[:, 1:2] * xw
    projection = np.linalg.svd(rows)[2][-1].reshape(3, 4)
    projection = np.linalg.inv(t_image) @ projection @ t_world
    if np.linalg.det(projection[:, :3]) < 0:
        projection = -projection
    return projection


def _rq(matrix: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return (upper-triangular K with a positive diagonal, orthogonal Q) with K @ Q = matrix."""
    flip = np.flipud(np.eye(3))
    q, r = np.linalg.qr((flip @ matrix).T)
    upper = flip @ r.T @ flip
    ortho = flip @ q.T
    signs = np.diag(np.sign(np.diag(upper)))
    return upper @ signs, signs @ ortho


def decompose_projection(projection: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Split a projection matrix into K (3, 3), R (3, 3) and t (3,) with ``P ~ K [R | t]``.

    :param projection: (3, 4) with ``det(P[:, :3]) > 0``
    :return: K with ``K[2, 2] = 1``, a rotation R and t [world units]
    """
    upper, rotation = _rq(projection[:, :3])
    translation = np.linalg.solve(upper, projection[:, 3])
    return upper / upper[2, 2], rotation, translation


def auto_dist_terms(count: int) -> int:
    """
    Return how many distortion terms ``calibrate_full`` estimates from ``count`` points.

    A single view has 10 pinhole unknowns (fx, fy, cx, cy, pose): below 12 points nothing is
    left for distortion; radial k1, k2 from 12 points, and all five from 40.
    """
    if count < 12:
        return 0
    if count < 40:
        return 2
    return 5


def _scan_focal_length(world: np.ndarray, pixels: np.ndarray,
                       image_size: tuple[int, int]) -> np.ndarray | None:
    """Return K with a centred principal point and the focal length whose PnP fits best."""
    width, height = image_size
    method = getattr(cv2, 'SOLVEPNP_SQPNP', cv2.SOLVEPNP_EPNP)

    def matrix(log_f: float) -> np.ndarray:
        focal = math.exp(log_f)
        return np.array(((focal, 0.0, (width - 1) / 2.0), (0.0, focal, (height - 1) / 2.0),
                         (0.0, 0.0, 1.0)))

    def cost(log_f: float) -> float:
        k = matrix(log_f)
        try:
            ok, rvec, tvec = cv2.solvePnP(world, pixels, k, None, flags=method)
        except cv2.error:
            return math.inf
        if not ok:
            return math.inf
        rotation = cv2.Rodrigues(rvec)[0]
        if not np.all(world @ rotation[2] + tvec[2] > 0):
            return math.inf
        projected = cv2.projectPoints(world, rvec, tvec, k, None)[0].reshape(-1, 2)
        return float(np.mean(np.sum((projected - pixels) ** 2, axis=1)))

    # Focal lengths from a 170-degree fisheye (0.05 w) to a long telephoto (20 w).
    grid = np.linspace(math.log(0.05 * width), math.log(20.0 * width), 40)
    costs = [cost(x) for x in grid]
    best = int(np.argmin(costs))
    if not math.isfinite(costs[best]):
        return None
    low, high = grid[max(best - 1, 0)], grid[min(best + 1, len(grid) - 1)]
    ratio = (math.sqrt(5.0) - 1.0) / 2.0
    for _ in range(30):  # golden-section search inside the bracketing grid cells
        a, b = high - ratio * (high - low), low + ratio * (high - low)
        if cost(a) < cost(b):
            high = b
        else:
            low = a
    return matrix(0.5 * (low + high))


def _refine_full(world: np.ndarray, pixels: np.ndarray, image_size: tuple[int, int],
                 guess: np.ndarray, dist_terms: int, centred: bool
                 ) -> tuple[float, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Refine K, distortion and pose from a start; return (rms, K, D, R, t) or raise."""
    check_intrinsics(guess, np.zeros(5), image_size)
    camera_matrix = np.array(((guess[0, 0], 0.0, guess[0, 2]), (0.0, guess[1, 1], guess[1, 2]),
                              (0.0, 0.0, 1.0)))
    dist_coeffs: np.ndarray = np.zeros(5)
    # Continuation: freeing high-order distortion far from its optimum lets LM wander off (k3
    # trades against k1, k2 and the focal length), so fit the pinhole model first (with a fixed
    # principal point and aspect when the start assumed them), then k1, k2, then the rest.
    if centred:
        fixed = cv2.CALIB_FIX_PRINCIPAL_POINT
        stages = [(0, fixed | cv2.CALIB_FIX_ASPECT_RATIO), (min(2, dist_terms), fixed),
                  (dist_terms, fixed), (dist_terms, 0)]
    else:
        stages = [(terms, 0) for terms in sorted({0, min(2, dist_terms), dist_terms})]
    for terms, extra in stages:
        flags = distortion_flags(terms) | cv2.CALIB_USE_INTRINSIC_GUESS | extra
        try:
            rms, camera_matrix, dist_coeffs, rvecs, tvecs = cv2.calibrateCamera(
                [world.astype(np.float32)], [pixels.astype(np.float32).reshape(-1, 1, 2)],
                image_size, camera_matrix, dist_coeffs, flags=flags, criteria=LM_CRITERIA)
        except cv2.error as err:
            raise CalibrationFitError(f'OpenCV refinement failed: {err.err}') from err
    dist_coeffs = np.asarray(dist_coeffs, dtype=float).ravel()[:5]
    check_intrinsics(camera_matrix, dist_coeffs, image_size)
    rotation = cv2.Rodrigues(np.asarray(rvecs[0], dtype=float))[0]
    translation = np.asarray(tvecs[0], dtype=float).ravel()
    check_front(world, rotation, translation)
    return float(rms), camera_matrix, dist_coeffs, rotation, translation


def calibrate_full(world: ArrayLike, pixels: ArrayLike, image_size: Sequence[int], *,
                   camera_name: str = 'camera', dist_terms: int | None = None,
                   lines: LineNumbers | None = None) -> CalibrationResult:
    """
    Calibrate intrinsics, distortion and pose from non-coplanar correspondences (the paper's way).

    A linear DLT gives P, decomposed (RQ) into K, R, t; OpenCV's calibrateCamera then refines
    K, distortion and pose together from that start (``CALIB_USE_INTRINSIC_GUESS``).

    :param world: (N, 3) world points [m], N >= 6, spread in 3D (not coplanar)
    :param pixels: (N, 2) raw pixels of the points
    :param image_size: (width, height) [px]
    :param camera_name: ``camera_name`` of the result
    :param dist_terms: distortion terms to estimate (:data:`DISTORTION_TERMS`); default
        :func:`auto_dist_terms` of N
    :param lines: (N,) CSV line of each point, used in messages (default: the point index)
    :return: the result
    :raises CalibrationFitError: too few distinct, repeated, collinear, coplanar or non-finite
        points, pixels outside the image, a principal point outside the image, points behind
        the camera
    """
    width, height = check_image_size(image_size)
    world, pixels = check_correspondences(world, pixels, 6, lines)
    spread = point_spread(world)
    if spread[2] < COPLANAR_RATIO * spread[0]:
        raise CalibrationFitError(
            f'the world points are (nearly) coplanar (thickness {spread[2] / spread[0]:.2%} of '
            'their extent): a full calibration needs points spread in depth; for a plane use '
            'chessboard intrinsics and then extrinsics')
    check_inside(pixels, (width, height))
    if dist_terms is None:
        dist_terms = auto_dist_terms(len(world))
    distortion_flags(dist_terms)

    projection = dlt_projection(world, pixels)
    depth_sign = np.sign(np.hstack((world, np.ones((len(world), 1)))) @ projection[2])
    if np.all(depth_sign < 0):
        raise CalibrationFitError(
            'the points can only be seen by a camera with mirrored axes: the world frame is '
            'left-handed, or the u/v or x/y columns are swapped')
    k_dlt = decompose_projection(projection)[0]
    notes = [f'DLT start: fx {k_dlt[0, 0]:.1f} fy {k_dlt[1, 1]:.1f} cx {k_dlt[0, 2]:.1f} '
             f'cy {k_dlt[1, 2]:.1f} px, skew {k_dlt[0, 1]:.2g} (dropped)']
    # The DLT has 11 free parameters (skew, aspect, principal point) and ignores distortion, so
    # shallow point clouds or strong lenses can put its start far off; a second start (centred
    # principal point, square pixels, focal length scanned) keeps the fit from depending on it.
    starts = [('DLT', k_dlt, False)]
    k_scan = _scan_focal_length(world, pixels, (width, height))
    if k_scan is not None:
        starts.append(('focal-length scan', k_scan, True))
    fits, failures = [], []
    for label, guess, centred in starts:
        try:
            fits.append(_refine_full(world, pixels, (width, height), guess, dist_terms, centred)
                        + (label,))
        except CalibrationFitError as err:
            failures.append(f'{label} start: {err}')
    if not fits:
        raise CalibrationFitError('; '.join(failures))
    rms, camera_matrix, dist_coeffs, rotation, translation, label = min(fits, key=lambda f: f[0])
    notes.append(f'best refinement from the {label} start'
                 + (f' ({"; ".join(failures)})' if failures else ''))
    calibration = make_calibration(camera_name, (width, height), camera_matrix, dist_coeffs,
                                   rotation, translation)
    reprojected = Camera(calibration).project(world)
    return make_result('full', calibration, pixels, reprojected, world=world,
                       dist_terms=dist_terms, notes=tuple(notes))


# -- epipolar check of a calibrated pair --------------------------------------------------------
