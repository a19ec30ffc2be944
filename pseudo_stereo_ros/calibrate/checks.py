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
Shared parts of the calibration fits: tuning constants, the result record, input checks.

Every fit (:mod:`.intrinsics`, :mod:`.extrinsics`, :mod:`.full`) returns a
:class:`CalibrationResult` and refuses degenerate input with
:class:`~pseudo_stereo_ros.errors.CalibrationFitError` through the checks here.
Pixels are raw (distorted) pixels, world points metres.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
import math
from typing import Any, TypeAlias

import cv2
import numpy as np
from numpy.typing import ArrayLike

from ..calibration import CameraCalibration
from ..errors import CalibrationFitError

__all__ = [
    'AMBIGUOUS_POSE_RATIO',
    'AMBIGUOUS_PX',
    'AMBIGUOUS_RATIO',
    'AMBIGUOUS_ROTATION_DEG',
    'COLLINEAR_RATIO',
    'COPLANAR_RATIO',
    'CalibrationResult',
    'DISTORTION_TERMS',
    'DUPLICATE_PX',
    'DUPLICATE_RATIO',
    'LM_CRITERIA',
    'LineNumbers',
    'MAX_CENTRE_STD_RATIO',
    'MAX_MEDIAN_RESIDUAL_PX',
    'OUTLIER_MIN_PX',
    'OUTLIER_SIGMAS',
    'PLANAR_PNP_RATIO',
    'PRINCIPAL_POINT_MAX_OFFSET',
    'check_correspondences',
    'check_front',
    'check_image_size',
    'check_inside',
    'check_intrinsics',
    'distortion_flags',
    'flag_outliers',
    'make_calibration',
    'make_result',
    'point_spread',
]

#: Allowed numbers of estimated distortion terms: none, k1, (k1, k2), (k1, k2, p1, p2), all five.
DISTORTION_TERMS = (0, 1, 2, 4, 5)

#: A residual beyond this many robust standard deviations (and beyond ``OUTLIER_MIN_PX``) is an
#: outlier.  For Gaussian pixel noise the residual length is Rayleigh distributed and exceeds
#: 4 sigma with probability exp(-4^2 / 2) = 0.03 %, so a clean fit flags almost nothing.
OUTLIER_SIGMAS = 4.0
#: Residuals below this are never outliers [px]: sub-pixel noise is not an error.
OUTLIER_MIN_PX = 1.0
# Median length of a 2D isotropic Gaussian vector, in units of its per-axis sigma: sqrt(2 ln 2).
_RAYLEIGH_MEDIAN = math.sqrt(2.0 * math.log(2.0))

#: Points whose smallest spread (singular value of the centred points) is below this fraction
#: of the largest count as coplanar (3D) or collinear (2D, 3D).
COPLANAR_RATIO = 0.02
COLLINEAR_RATIO = 1e-3
#: A fit whose median residual exceeds this [px] explains nothing: refused, not written.
MAX_MEDIAN_RESIDUAL_PX = 10.0
#: A fitted principal point further than this fraction of the image size from its centre
#: means the image size (or the fit) is wrong: real lenses are centred to a few per cent.
PRINCIPAL_POINT_MAX_OFFSET = 0.2
#: A plane that is this flat is solved with OpenCV's planar PnP (IPPE).
PLANAR_PNP_RATIO = 1e-6
#: World points closer than this fraction of their extent, and pixels closer than
#: ``DUPLICATE_PX``, are one point: a repeated row adds no constraint, it only hides how few
#: points there are (3 points repeated 3 times look like 9 but leave the pose ambiguous).
DUPLICATE_RATIO = 1e-9
DUPLICATE_PX = 1e-6
#: A second pose that reprojects the points within this RMS [px] (or within
#: ``AMBIGUOUS_RATIO`` times the best RMS) fits them as well as measured pixels can tell:
#: when it differs from the best pose by more than ``AMBIGUOUS_POSE_RATIO`` of the viewing
#: distance (or ``AMBIGUOUS_ROTATION_DEG``), the pose is ambiguous and is refused.
AMBIGUOUS_PX = 1.0
AMBIGUOUS_RATIO = 2.0
AMBIGUOUS_POSE_RATIO = 0.01
AMBIGUOUS_ROTATION_DEG = 1.0
#: A pose whose camera centre has a 1-sigma uncertainty above this fraction of the viewing
#: distance for 1 px of pixel noise (from the Jacobian of the projection) is not determined
#: by the points: refused.  A square of 4 points filling a third of the image gives 0.005.
MAX_CENTRE_STD_RATIO = 0.1

LM_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-12)

#: The (N,) CSV line of each correspondence, for error messages.
LineNumbers: TypeAlias = Sequence[int] | np.ndarray


@dataclass(frozen=True, eq=False)
class CalibrationResult:
    """
    A fitted calibration and how well it explains its input.

    ``pixels`` (N, 2) are the measured raw pixels, ``reprojected`` (N, 2)
    their model predictions, ``residuals_px`` (N,) the distances between
    them and ``outliers`` (N,) flags residuals beyond ``outlier_threshold_px``.
    For chessboards, N counts every corner of every used image,
    ``point_image`` (N,) gives each corner's index into ``image_labels`` and
    ``intrinsics_std`` (4,) the standard deviations of fx, fy, cx, cy [px]
    that OpenCV estimates from the residuals (1 sigma).
    """

    mode: str
    calibration: CameraCalibration
    pixels: np.ndarray
    reprojected: np.ndarray
    residuals_px: np.ndarray
    outliers: np.ndarray
    outlier_threshold_px: float
    rms_px: float
    world: np.ndarray | None = None
    image_labels: tuple[str, ...] = ()
    image_rms_px: np.ndarray | None = None
    point_image: np.ndarray | None = None
    dist_terms: int = 0
    notes: tuple[str, ...] = field(default=())
    intrinsics_std: np.ndarray | None = None

    def summary(self) -> str:
        """Return a short multi-line description: RMS, intrinsics, pose, outliers."""
        calib = self.calibration
        k = calib.camera_matrix
        lines = [
            f'{self.mode} calibration of {calib.camera_name!r}: {len(self.residuals_px)} points, '
            f'RMS {self.rms_px:.3f} px, max {float(np.max(self.residuals_px)):.3f} px, '
            f'{int(self.outliers.sum())} outlier(s) (> {self.outlier_threshold_px:.2f} px)',
            f'  image {calib.image_width}x{calib.image_height}, fx {k[0, 0]:.2f} fy {k[1, 1]:.2f}'
            f' cx {k[0, 2]:.2f} cy {k[1, 2]:.2f} px',
            f'  {calib.distortion_model} '
            + ' '.join(f'{x:.6g}' for x in calib.dist_coeffs)
            + f' ({self.dist_terms} term(s) estimated)',
        ]
        if self.intrinsics_std is not None:
            lines.append('  1-sigma uncertainty: fx, fy, cx, cy '
                         + ' '.join(f'{x:.2f}' for x in self.intrinsics_std) + ' px')
        if self.mode != 'intrinsics':
            center = calib.center
            lines.append('  camera centre in the world: '
                         + ', '.join(f'{x:.4f}' for x in center) + ' m')
        lines.extend(f'  note: {note}' for note in self.notes)
        return '\n'.join(lines)


# -- shared checks ------------------------------------------------------------------------------


def flag_outliers(residuals_px: ArrayLike) -> tuple[np.ndarray, float]:
    """
    Flag residuals far beyond the robust noise level.

    :param residuals_px: (N,) residual lengths [px]
    :return: (N,) boolean flags and the threshold used [px]: ``max(OUTLIER_SIGMAS * sigma,
        OUTLIER_MIN_PX)`` with sigma the per-axis noise estimated from the median length
    """
    residuals_px = np.asarray(residuals_px, dtype=float)
    sigma = float(np.median(residuals_px)) / _RAYLEIGH_MEDIAN if len(residuals_px) else 0.0
    threshold = max(OUTLIER_SIGMAS * sigma, OUTLIER_MIN_PX)
    return residuals_px > threshold, threshold


def _as_points(values: ArrayLike, columns: int, what: str) -> np.ndarray:
    try:
        array = np.array(values, dtype=float)
    except (TypeError, ValueError) as err:
        raise CalibrationFitError(f'{what}: not numeric ({err})') from err
    if array.ndim != 2 or array.shape[1] != columns:
        raise CalibrationFitError(f'{what}: expected an (N, {columns}) array, got shape '
                                  f'{array.shape}')
    bad = ~np.all(np.isfinite(array), axis=1)
    if bad.any():
        raise CalibrationFitError(f'{what}: non-finite value in point {int(np.argmax(bad))}')
    return array


def point_spread(points: np.ndarray) -> np.ndarray:
    """Return the singular values of the centred points, largest first."""
    return np.linalg.svd(points - points.mean(axis=0), compute_uv=False)


def _repeats(points: np.ndarray, tolerance: float) -> tuple[int, dict[int, list[int]]]:
    """Return the number of distinct points and, per first occurrence, the indices repeating it."""
    keys = np.round(points / tolerance) + 0.0  # + 0.0 turns -0.0 into 0.0
    _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    owner = first[np.asarray(inverse).ravel()]
    groups: dict[int, list[int]] = {}
    for index in np.flatnonzero(owner != np.arange(len(points))):
        groups.setdefault(int(owner[index]), []).append(int(index))
    return len(first), groups


def _describe_repeats(groups: dict[int, list[int]], lines: LineNumbers | None) -> str:
    """Return e.g. ``lines 3, 4 repeat line 2; line 6 repeats line 5``."""
    word = 'line' if lines is not None else 'point'
    label = (lambda i: str(int(lines[i]))) if lines is not None else str
    parts = [f'{word}{"s" if len(repeats) > 1 else ""} {", ".join(label(i) for i in repeats)} '
             f'repeat{"" if len(repeats) > 1 else "s"} {word} {label(first)}'
             for first, repeats in sorted(groups.items())]
    if len(parts) > 5:
        parts = parts[:5] + [f'and {len(parts) - 5} more']
    return '; '.join(parts)


def check_correspondences(world: ArrayLike, pixels: ArrayLike, minimum: int,
                          lines: LineNumbers | None = None) -> tuple[np.ndarray, np.ndarray]:
    world = _as_points(world, 3, 'world points')
    pixels = _as_points(pixels, 2, 'pixels')
    if len(world) != len(pixels):
        raise CalibrationFitError(f'{len(world)} world points but {len(pixels)} pixels')
    if lines is not None and len(lines) != len(world):
        raise CalibrationFitError(f'{len(lines)} line numbers for {len(world)} points')
    if len(world) < minimum:
        raise CalibrationFitError(f'too few points: {len(world)}, need at least {minimum}')
    extent = float(np.max(np.ptp(world, axis=0)))
    distinct, groups = _repeats(world, max(DUPLICATE_RATIO * extent, 1e-300))
    if groups:
        raise CalibrationFitError(
            f'repeated world points: {distinct} distinct of {len(world)} '
            f'({_describe_repeats(groups, lines)}); a repeat adds no constraint, remove it'
            + (f' (need at least {minimum} distinct points)' if distinct < minimum else ''))
    distinct, groups = _repeats(pixels, DUPLICATE_PX)
    if distinct < minimum:
        raise CalibrationFitError(
            f'too few distinct pixels: {distinct} of {len(pixels)} '
            f'({_describe_repeats(groups, lines)} at the same pixel), need at least {minimum}')
    spread = point_spread(world)
    if not spread[0] > 0 or spread[1] < COLLINEAR_RATIO * spread[0]:
        raise CalibrationFitError('the world points are collinear (or coincide): a line does '
                                  'not fix a camera; spread the points over a plane or volume')
    pixel_spread = point_spread(pixels)
    if not pixel_spread[0] > 0 or pixel_spread[1] < COLLINEAR_RATIO * pixel_spread[0]:
        raise CalibrationFitError('the pixels are collinear: the camera centre lies in the '
                                  'plane of the points, or the pixels do not belong to them')
    return world, pixels


def check_inside(pixels: np.ndarray, image_size: tuple[int, int]) -> None:
    width, height = image_size
    outside = ((pixels[:, 0] < -0.5) | (pixels[:, 0] > width - 0.5)
               | (pixels[:, 1] < -0.5) | (pixels[:, 1] > height - 0.5))
    if outside.any():
        index = int(np.argmax(outside))
        raise CalibrationFitError(
            f'image size {width}x{height} contradicts the points: {int(outside.sum())} pixel(s) '
            f'outside the image, first point {index} at ({pixels[index, 0]:.1f}, '
            f'{pixels[index, 1]:.1f})')


def check_image_size(image_size: Iterable[float]) -> tuple[int, int]:
    try:
        width, height = (int(x) for x in image_size)
    except (TypeError, ValueError) as err:
        raise CalibrationFitError(f'image size must be (width, height), got {image_size!r}') \
            from err
    if width <= 0 or height <= 0:
        raise CalibrationFitError(f'image size must be positive, got {width}x{height}')
    return width, height


def check_front(world: np.ndarray, rotation: np.ndarray, translation: np.ndarray) -> None:
    depth = world @ rotation[2] + translation[2]
    behind = ~(depth > 0)
    if behind.any():
        raise CalibrationFitError(
            f'{int(behind.sum())} of {len(world)} world points are behind the fitted camera '
            f'(first: point {int(np.argmax(behind))}): the world and image points do not '
            'belong together (mirrored axes, swapped columns or wrong pixel order?)')


def check_intrinsics(camera_matrix: np.ndarray, dist_coeffs: np.ndarray,
                     image_size: tuple[int, int]) -> None:
    if not (np.all(np.isfinite(camera_matrix)) and np.all(np.isfinite(dist_coeffs))):
        raise CalibrationFitError('the fit diverged (non-finite camera matrix or distortion)')
    fx, fy, cx, cy = (camera_matrix[0, 0], camera_matrix[1, 1], camera_matrix[0, 2],
                      camera_matrix[1, 2])
    if not (fx > 0 and fy > 0):
        raise CalibrationFitError(f'the fit gave non-positive focal lengths ({fx:.4g}, {fy:.4g})')
    width, height = image_size
    if (abs(cx - (width - 1) / 2.0) > PRINCIPAL_POINT_MAX_OFFSET * width
            or abs(cy - (height - 1) / 2.0) > PRINCIPAL_POINT_MAX_OFFSET * height):
        raise CalibrationFitError(
            f'image size {width}x{height} contradicts the points: the fitted principal point '
            f'({cx:.1f}, {cy:.1f}) is far from the image centre (more than '
            f'{PRINCIPAL_POINT_MAX_OFFSET:.0%} of the size; wrong image size, or points that '
            'do not constrain the camera)')


def distortion_flags(terms: int) -> int:
    if terms not in DISTORTION_TERMS:
        raise CalibrationFitError(f'dist_terms must be one of {DISTORTION_TERMS}, got {terms!r}')
    flags = 0
    if terms < 5:
        flags |= cv2.CALIB_FIX_K3
    if terms < 4:
        flags |= cv2.CALIB_ZERO_TANGENT_DIST
    if terms < 2:
        flags |= cv2.CALIB_FIX_K2
    if terms < 1:
        flags |= cv2.CALIB_FIX_K1
    return flags


def make_result(mode: str, calibration: CameraCalibration, pixels: np.ndarray,
                reprojected: np.ndarray, **extra: Any) -> CalibrationResult:
    residuals = np.linalg.norm(reprojected - pixels, axis=1)
    if not np.all(np.isfinite(residuals)):
        raise CalibrationFitError('the fitted camera cannot project every point (diverged fit)')
    median = float(np.median(residuals))
    if median > MAX_MEDIAN_RESIDUAL_PX:
        raise CalibrationFitError(
            f'no camera fits the points: median residual {median:.1f} px (> '
            f'{MAX_MEDIAN_RESIDUAL_PX:g} px); check the column order (x,y,z,u,v), the units '
            '(metres, raw pixels) and the axes of the world frame')
    outliers, threshold = flag_outliers(residuals)
    for array in (pixels, reprojected, residuals, outliers):
        array.setflags(write=False)
    return CalibrationResult(
        mode=mode, calibration=calibration, pixels=pixels, reprojected=reprojected,
        residuals_px=residuals, outliers=outliers, outlier_threshold_px=threshold,
        rms_px=float(np.sqrt(np.mean(residuals ** 2))), **extra)


def make_calibration(name: str, image_size: Sequence[int], camera_matrix: ArrayLike,
                     dist_coeffs: ArrayLike, rotation: ArrayLike, translation: ArrayLike,
                     model: str = 'plumb_bob') -> CameraCalibration:
    camera_matrix = np.array(camera_matrix, dtype=float)
    camera_matrix[1, 0] = camera_matrix[2, 0] = camera_matrix[2, 1] = 0.0
    camera_matrix[2, 2] = 1.0
    return CameraCalibration(
        camera_name=str(name), image_width=int(image_size[0]), image_height=int(image_size[1]),
        camera_matrix=camera_matrix, distortion_model=model,
        dist_coeffs=np.array(dist_coeffs, dtype=float).ravel(),
        rotation=np.array(rotation, dtype=float),
        translation=np.array(translation, dtype=float).ravel())


# -- chessboards --------------------------------------------------------------------------------
