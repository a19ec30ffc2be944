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
Camera calibration: chessboard intrinsics, pose from correspondences, full (DLT) calibration.

Three fits, each returning a :class:`CalibrationResult` whose ``calibration``
is a core :class:`~pseudo_stereo_ros.calibration.CameraCalibration` (write it
with :func:`~pseudo_stereo_ros.calibration.save_calibration`):

- :func:`calibrate_intrinsics`: camera matrix and distortion from chessboard
  images (OpenCV, Zhang's method); the pose is left at identity.
- :func:`calibrate_extrinsics`: the pose ``x_cam = R @ x_world + t`` from at
  least 4 world <-> raw-pixel correspondences and known intrinsics.
- :func:`calibrate_full`: intrinsics, distortion and pose from at least 6
  non-coplanar correspondences, as in the paper (a linear DLT start, refined
  by OpenCV's Levenberg-Marquardt).

Pixels are raw (distorted) pixels with OpenCV's convention (integer
coordinates at pixel centres); world points are metres.  Degenerate input is
refused with :class:`CalibrationFitError` (a :class:`CalibrationError`, so
the command line reports it in one line): a fit never returns a silently bad
calibration.  This differs on purpose from the NaN policy of the geometry
functions: a calibration is a file a user keeps, not a per-event result.
"""

from dataclasses import dataclass, field, replace
import math
import os
from typing import Optional, Sequence, Tuple, Union

import cv2
import numpy as np

from ..calibration import CameraCalibration
from ..camera import Camera
from ..errors import CalibrationFitError
from ..geometry import epipolar_distance

__all__ = [
    'CalibrationFitError',
    'CalibrationResult',
    'DISTORTION_TERMS',
    'EpipolarCheck',
    'OUTLIER_SIGMAS',
    'auto_dist_terms',
    'calibrate_extrinsics',
    'calibrate_full',
    'calibrate_intrinsics',
    'decompose_projection',
    'dlt_projection',
    'epipolar_check',
    'flag_outliers',
    'list_images',
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

_LM_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-12)
_IMAGE_EXTENSIONS = ('.png', '.jpg', '.jpeg', '.bmp', '.tif', '.tiff', '.pgm', '.ppm')

ImageInput = Union[str, os.PathLike, np.ndarray]


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
    world: Optional[np.ndarray] = None
    image_labels: Tuple[str, ...] = ()
    image_rms_px: Optional[np.ndarray] = None
    point_image: Optional[np.ndarray] = None
    dist_terms: int = 0
    notes: Tuple[str, ...] = field(default=())
    intrinsics_std: Optional[np.ndarray] = None

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


def flag_outliers(residuals_px: np.ndarray) -> Tuple[np.ndarray, float]:
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


def _as_points(values, columns: int, what: str) -> np.ndarray:
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


def _spread(points: np.ndarray) -> np.ndarray:
    """Return the singular values of the centred points, largest first."""
    return np.linalg.svd(points - points.mean(axis=0), compute_uv=False)


def _repeats(points: np.ndarray, tolerance: float) -> Tuple[int, dict]:
    """Return the number of distinct points and, per first occurrence, the indices repeating it."""
    keys = np.round(points / tolerance) + 0.0  # + 0.0 turns -0.0 into 0.0
    _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    owner = first[np.asarray(inverse).ravel()]
    groups = {}
    for index in np.flatnonzero(owner != np.arange(len(points))):
        groups.setdefault(int(owner[index]), []).append(int(index))
    return len(first), groups


def _describe_repeats(groups: dict, lines: Optional[Sequence[int]]) -> str:
    """Return e.g. ``lines 3, 4 repeat line 2; line 6 repeats line 5``."""
    word = 'line' if lines is not None else 'point'
    label = (lambda i: str(int(lines[i]))) if lines is not None else str
    parts = [f'{word}{"s" if len(repeats) > 1 else ""} {", ".join(label(i) for i in repeats)} '
             f'repeat{"" if len(repeats) > 1 else "s"} {word} {label(first)}'
             for first, repeats in sorted(groups.items())]
    if len(parts) > 5:
        parts = parts[:5] + [f'and {len(parts) - 5} more']
    return '; '.join(parts)


def _check_correspondences(world, pixels, minimum: int,
                           lines: Optional[Sequence[int]] = None
                           ) -> Tuple[np.ndarray, np.ndarray]:
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
    spread = _spread(world)
    if not spread[0] > 0 or spread[1] < COLLINEAR_RATIO * spread[0]:
        raise CalibrationFitError('the world points are collinear (or coincide): a line does '
                                  'not fix a camera; spread the points over a plane or volume')
    pixel_spread = _spread(pixels)
    if not pixel_spread[0] > 0 or pixel_spread[1] < COLLINEAR_RATIO * pixel_spread[0]:
        raise CalibrationFitError('the pixels are collinear: the camera centre lies in the '
                                  'plane of the points, or the pixels do not belong to them')
    return world, pixels


def _check_inside(pixels: np.ndarray, image_size: Tuple[int, int]) -> None:
    width, height = image_size
    outside = ((pixels[:, 0] < -0.5) | (pixels[:, 0] > width - 0.5)
               | (pixels[:, 1] < -0.5) | (pixels[:, 1] > height - 0.5))
    if outside.any():
        index = int(np.argmax(outside))
        raise CalibrationFitError(
            f'image size {width}x{height} contradicts the points: {int(outside.sum())} pixel(s) '
            f'outside the image, first point {index} at ({pixels[index, 0]:.1f}, '
            f'{pixels[index, 1]:.1f})')


def _check_image_size(image_size) -> Tuple[int, int]:
    try:
        width, height = (int(x) for x in image_size)
    except (TypeError, ValueError) as err:
        raise CalibrationFitError(f'image size must be (width, height), got {image_size!r}') \
            from err
    if width <= 0 or height <= 0:
        raise CalibrationFitError(f'image size must be positive, got {width}x{height}')
    return width, height


def _check_front(world: np.ndarray, rotation: np.ndarray, translation: np.ndarray) -> None:
    depth = world @ rotation[2] + translation[2]
    behind = ~(depth > 0)
    if behind.any():
        raise CalibrationFitError(
            f'{int(behind.sum())} of {len(world)} world points are behind the fitted camera '
            f'(first: point {int(np.argmax(behind))}): the world and image points do not '
            'belong together (mirrored axes, swapped columns or wrong pixel order?)')


def _check_intrinsics(camera_matrix: np.ndarray, dist_coeffs: np.ndarray,
                      image_size: Tuple[int, int]) -> None:
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


def _distortion_flags(terms: int) -> int:
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


def _make_result(mode: str, calibration: CameraCalibration, pixels: np.ndarray,
                 reprojected: np.ndarray, **extra) -> CalibrationResult:
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


def _calibration(name: str, image_size, camera_matrix, dist_coeffs, rotation,
                 translation, model: str = 'plumb_bob') -> CameraCalibration:
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


def list_images(directory: Union[str, os.PathLike]) -> list:
    """Return the sorted image files (png, jpg, bmp, tif, pgm, ppm) of a directory."""
    directory = os.fspath(directory)
    if not os.path.isdir(directory):
        raise CalibrationFitError(f'{directory}: not a directory')
    names = sorted(name for name in os.listdir(directory)
                   if name.lower().endswith(_IMAGE_EXTENSIONS))
    if not names:
        raise CalibrationFitError(f'{directory}: no images ({", ".join(_IMAGE_EXTENSIONS)})')
    return [os.path.join(directory, name) for name in names]


def _gray(image: ImageInput, index: int) -> Tuple[np.ndarray, str]:
    if isinstance(image, np.ndarray):
        label = f'image {index}'
        array = image
    else:
        label = os.fspath(image)
        array = cv2.imread(label, cv2.IMREAD_UNCHANGED)
        if array is None:
            raise CalibrationFitError(f'{label}: cannot read the image')
    if array.ndim == 3 and array.shape[2] == 4:
        array = cv2.cvtColor(array, cv2.COLOR_BGRA2GRAY)
    elif array.ndim == 3 and array.shape[2] == 3:
        array = cv2.cvtColor(array, cv2.COLOR_BGR2GRAY)
    elif array.ndim != 2:
        raise CalibrationFitError(f'{label}: not a grey or colour image (shape {array.shape})')
    if array.dtype != np.uint8:
        array = cv2.normalize(array, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)
    return array, label


def _board_points(board: Tuple[int, int], square_m: float) -> np.ndarray:
    cols, rows = board
    grid = np.zeros((cols * rows, 3))
    grid[:, :2] = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2) * square_m
    return grid


def _find_corners(gray: np.ndarray, board: Tuple[int, int]) -> Optional[np.ndarray]:
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    found, corners = cv2.findChessboardCorners(gray, board, flags=flags)
    if not found:
        return None
    corners = corners.reshape(-1, 2)
    cols = board[0]
    # The refinement window must stay inside one square: half the smallest corner spacing.
    grid = corners.reshape(board[1], cols, 2)
    spacing = min(np.linalg.norm(np.diff(grid, axis=1), axis=2).min(),
                  np.linalg.norm(np.diff(grid, axis=0), axis=2).min())
    half = int(np.clip(spacing / 2.0 - 1.0, 2, 11))
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 50, 1e-3)
    refined = cv2.cornerSubPix(gray, corners.reshape(-1, 1, 2).astype(np.float32), (half, half),
                               (-1, -1), criteria)
    return refined.reshape(-1, 2).astype(float)


def _coverage(corner_sets: Sequence[np.ndarray], image_size: Tuple[int, int]) -> float:
    """Return the fraction of the image covered by the union of the boards' convex hulls."""
    scale = 0.25
    width, height = image_size
    mask = np.zeros((max(1, int(height * scale)), max(1, int(width * scale))), np.uint8)
    for corners in corner_sets:
        hull = cv2.convexHull((corners * scale).astype(np.float32)).astype(np.int32)
        cv2.fillConvexPoly(mask, hull, 1)
    return float(mask.mean())


def calibrate_intrinsics(images: Sequence[ImageInput], *, board: Tuple[int, int],
                         square_m: float, camera_name: str = 'camera', dist_terms: int = 4,
                         min_boards: int = 5, min_coverage: float = 0.3,
                         min_tilt_deg: float = 15.0) -> CalibrationResult:
    """
    Calibrate a camera's intrinsics and distortion from chessboard images.

    :param images: image files or arrays (grey or BGR), all of one size
    :param board: inner corners per row and per column ``(cols, rows)``, as OpenCV counts them
        (a board of 9 x 7 squares has 8 x 6 inner corners)
    :param square_m: side of one square [m] (sets the scale of the board poses only)
    :param camera_name: ``camera_name`` of the result
    :param dist_terms: distortion terms to estimate, see :data:`DISTORTION_TERMS`; the default
        4 (k1, k2, p1, p2) fixes k3 = 0 as ROS camera_calibration does, since k3 over-fits
        unless the boards reach the image corners
    :param min_boards: refuse with fewer boards found
    :param min_coverage: refuse when the boards cover less than this fraction of the image
    :param min_tilt_deg: refuse when no two boards' normals differ by this angle (parallel
        boards do not separate focal length from distance)
    :return: the result; its calibration has the identity pose
    :raises CalibrationFitError: unreadable images, too few boards, poor coverage or tilt
    """
    try:
        cols, rows = (int(x) for x in board)
    except (TypeError, ValueError) as err:
        raise CalibrationFitError(f'board must be (cols, rows) inner corners, got {board!r}') \
            from err
    if cols < 2 or rows < 2 or cols == rows:
        # A square corner grid is ambiguous under a 90-degree turn: OpenCV may order it either way.
        raise CalibrationFitError(
            f'board must have at least 2x2 inner corners and cols != rows, got {cols}x{rows}')
    if not (math.isfinite(square_m) and square_m > 0):
        raise CalibrationFitError(f'square size must be positive [m], got {square_m!r}')
    if len(images) == 0:
        raise CalibrationFitError('no images given')
    flags = _distortion_flags(dist_terms)

    image_size = None
    labels, corner_sets, missed = [], [], []
    for index, image in enumerate(images):
        gray, label = _gray(image, index)
        size = (gray.shape[1], gray.shape[0])
        if image_size is None:
            image_size = size
        elif size != image_size:
            raise CalibrationFitError(f'{label}: size {size[0]}x{size[1]} differs from the first '
                                      f'image ({image_size[0]}x{image_size[1]})')
        corners = _find_corners(gray, (cols, rows))
        if corners is None:
            missed.append(label)
        else:
            labels.append(label)
            corner_sets.append(corners)
    if len(corner_sets) < min_boards:
        raise CalibrationFitError(
            f'too few boards: found a {cols}x{rows} inner-corner board in {len(corner_sets)} of '
            f'{len(images)} images, need at least {min_boards} (check --board counts inner '
            'corners, and that the whole board is visible and sharp)')
    coverage = _coverage(corner_sets, image_size)
    if coverage < min_coverage:
        raise CalibrationFitError(
            f'poor coverage: the boards cover {100 * coverage:.0f}% of the image, need at least '
            f'{100 * min_coverage:.0f}%; add images with the board near the edges and corners')

    object_points = _board_points((cols, rows), square_m)
    _, camera_matrix, dist_coeffs, rvecs, tvecs, std_intrinsics = cv2.calibrateCameraExtended(
        [object_points.astype(np.float32)] * len(corner_sets),
        [c.astype(np.float32).reshape(-1, 1, 2) for c in corner_sets], image_size, None,
        np.zeros(5), flags=flags, criteria=_LM_CRITERIA)[:6]
    dist_coeffs = np.asarray(dist_coeffs, dtype=float).ravel()[:5]
    _check_intrinsics(camera_matrix, dist_coeffs, image_size)

    normals = np.array([cv2.Rodrigues(r)[0][:, 2] for r in rvecs])
    cosines = np.clip(np.abs(normals @ normals.T), 0.0, 1.0)
    tilt_spread = math.degrees(math.acos(cosines.min()))
    if tilt_spread < min_tilt_deg:
        raise CalibrationFitError(
            f'too little tilt variety: the board orientations differ by at most '
            f'{tilt_spread:.1f} deg, need {min_tilt_deg:g}; tilt the board (up to ~45 deg) '
            'left/right and up/down')

    reprojected, image_rms, point_image = [], [], []
    for index, (corners, rvec, tvec) in enumerate(zip(corner_sets, rvecs, tvecs)):
        projected = cv2.projectPoints(object_points, rvec, tvec, camera_matrix,
                                      dist_coeffs)[0].reshape(-1, 2)
        reprojected.append(projected)
        image_rms.append(float(np.sqrt(np.mean(np.sum((projected - corners) ** 2, axis=1)))))
        point_image.append(np.full(len(corners), index))
    calibration = _calibration(camera_name, image_size, camera_matrix, dist_coeffs, np.eye(3),
                               np.zeros(3))
    notes = [f'{len(corner_sets)} of {len(images)} images used, coverage {100 * coverage:.0f}%, '
             f'tilt variety {tilt_spread:.0f} deg']
    if missed:
        notes.append(f'no board found in: {", ".join(os.path.basename(m) for m in missed)}')
    image_rms = np.array(image_rms)
    return _make_result(
        'intrinsics', calibration, np.vstack(corner_sets), np.vstack(reprojected),
        image_labels=tuple(labels), image_rms_px=image_rms,
        point_image=np.concatenate(point_image), dist_terms=dist_terms, notes=tuple(notes),
        intrinsics_std=np.asarray(std_intrinsics, dtype=float).ravel()[:4])


# -- pose from correspondences ------------------------------------------------------------------


def _pnp_candidates(world: np.ndarray, ideal: np.ndarray, camera_matrix: np.ndarray,
                    planar: bool) -> list:
    methods = []
    if planar:
        methods.append(cv2.SOLVEPNP_IPPE)
    elif len(world) >= 6:
        methods.append(cv2.SOLVEPNP_ITERATIVE)
    if hasattr(cv2, 'SOLVEPNP_SQPNP'):
        methods.append(cv2.SOLVEPNP_SQPNP)
    if not planar or len(methods) == 1:
        methods.append(cv2.SOLVEPNP_EPNP)
    candidates = []
    for method in methods:
        try:
            count, rvecs, tvecs, _ = cv2.solvePnPGeneric(world, ideal, camera_matrix, None,
                                                         flags=method)
        except cv2.error:
            continue
        candidates.extend(zip(rvecs[:count], tvecs[:count]))
    return candidates


def _flipped_start(world: np.ndarray, rotation: np.ndarray,
                   translation: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return a pose start on the other side of the points' best-fit plane, looking at them.

    For (nearly) flat or distant point sets the camera mirrored in that plane sees almost the
    same image (the Necker flip): refining from here finds that second minimum if it exists.
    """
    centroid = world.mean(axis=0)
    normal = np.linalg.svd(world - centroid)[2][-1]
    center = -rotation.T @ translation
    flipped = center - 2.0 * ((center - centroid) @ normal) * normal
    axis_z = centroid - flipped
    axis_z /= np.linalg.norm(axis_z)
    axis_x = rotation[0] - (rotation[0] @ axis_z) * axis_z
    if np.linalg.norm(axis_x) < 1e-9:
        axis_x = rotation[1] - (rotation[1] @ axis_z) * axis_z
    axis_x /= np.linalg.norm(axis_x)
    flipped_rotation = np.vstack((axis_x, np.cross(axis_z, axis_x), axis_z))
    return cv2.Rodrigues(flipped_rotation)[0], -flipped_rotation @ flipped


def _pose_center_std(world: np.ndarray, rvec: np.ndarray, tvec: np.ndarray,
                     camera_matrix: np.ndarray) -> float:
    """Return the 1-sigma uncertainty [m] of the camera centre (worst axis) at 1 px noise."""
    jacobian = cv2.projectPoints(world, rvec, tvec, camera_matrix, None)[1][:, :6]
    try:
        covariance = np.linalg.inv(jacobian.T @ jacobian)
    except np.linalg.LinAlgError:
        return math.inf
    params = np.concatenate((rvec.ravel(), tvec.ravel()))

    def center(x):
        return -cv2.Rodrigues(x[:3])[0].T @ x[3:]

    step = 1e-7
    derivative = np.column_stack([(center(params + step * e) - center(params - step * e))
                                  / (2.0 * step) for e in np.eye(6)])
    eigen = np.linalg.eigvalsh(derivative @ covariance @ derivative.T)
    return float(math.sqrt(max(eigen[-1], 0.0))) if np.all(np.isfinite(eigen)) else math.inf


def calibrate_extrinsics(intrinsics: CameraCalibration, world, pixels, *,
                         camera_name: Optional[str] = None,
                         lines: Optional[Sequence[int]] = None) -> CalibrationResult:
    """
    Fit a camera's pose from world <-> raw-pixel correspondences and its known intrinsics.

    Every solver's poses and a start mirrored in the points' plane are refined; the pose is
    refused when a second, clearly different pose reprojects the points about as well
    (:data:`AMBIGUOUS_PX`) or when the points do not pin the camera centre down
    (:data:`MAX_CENTRE_STD_RATIO`).

    :param intrinsics: the camera's intrinsics and distortion (its pose is ignored)
    :param world: (N, 3) world points [m], N >= 4 distinct, not collinear (a plane is fine)
    :param pixels: (N, 2) raw pixels of the points in this camera
    :param camera_name: ``camera_name`` of the result (default: the intrinsics' name)
    :param lines: (N,) CSV line of each point, used in messages (default: the point index)
    :return: the result, with the intrinsics unchanged and the fitted pose
    :raises CalibrationFitError: too few distinct, repeated, collinear or non-finite points,
        pixels outside the image, no pose with every point in front of the camera, an
        ambiguous or undetermined pose
    """
    world, pixels = _check_correspondences(world, pixels, 4, lines)
    image_size = (intrinsics.image_width, intrinsics.image_height)
    _check_inside(pixels, image_size)
    camera = Camera(replace(intrinsics, rotation=np.eye(3), translation=np.zeros(3)))
    # Solve in undistorted (ideal) pixels so every distortion model, fisheye included, works
    # alike; ideal and raw pixels differ by the local scale of the distortion only.
    ideal = camera.ideal_pixels(pixels)
    k = camera.K
    spread = _spread(world)
    planar = spread[2] < PLANAR_PNP_RATIO * spread[0]
    candidates = _pnp_candidates(world, ideal, k, planar)
    fits = []

    def refine(rvec, tvec):
        rvec, tvec = np.asarray(rvec, float).reshape(3, 1), np.asarray(tvec, float).reshape(3, 1)
        if not (np.all(np.isfinite(rvec)) and np.all(np.isfinite(tvec))):
            return
        rvec, tvec = cv2.solvePnPRefineLM(world, ideal, k, None, rvec, tvec, _LM_CRITERIA)
        rotation = cv2.Rodrigues(rvec)[0]
        in_front = bool(np.all(world @ rotation[2] + tvec[2, 0] > 0))
        projected = cv2.projectPoints(world, rvec, tvec, k, None)[0].reshape(-1, 2)
        rms = float(np.sqrt(np.mean(np.sum((projected - ideal) ** 2, axis=1))))
        if math.isfinite(rms):
            fits.append(((not in_front, rms), rotation, tvec.ravel(), rvec))

    for rvec, tvec in candidates:
        refine(rvec, tvec)
    if not fits:
        raise CalibrationFitError('no pose fits the points (OpenCV solvePnP failed)')
    for _, rotation, translation, _ in list(fits):
        refine(*_flipped_start(world, rotation, translation))
    fits.sort(key=lambda fit: fit[0])
    (_, best_rms), rotation, translation, rvec = fits[0]
    _check_front(world, rotation, translation)
    center = -rotation.T @ translation
    distance = float(np.linalg.norm(world.mean(axis=0) - center))
    for (behind, rms), other_rotation, other_translation, _ in fits[1:]:
        if behind or rms > max(AMBIGUOUS_PX, AMBIGUOUS_RATIO * best_rms):
            continue
        other_center = -other_rotation.T @ other_translation
        shift = float(np.linalg.norm(other_center - center))
        turn = _rotation_angle_deg(rotation, other_rotation)
        if shift > AMBIGUOUS_POSE_RATIO * distance or turn > AMBIGUOUS_ROTATION_DEG:
            raise CalibrationFitError(
                f'ambiguous pose: two camera poses fit the {len(world)} points (RMS '
                f'{best_rms:.3f} and {rms:.3f} px) with centres '
                + ', '.join(f'{x:.3f}' for x in center) + ' and '
                + ', '.join(f'{x:.3f}' for x in other_center)
                + f' m ({shift:.2f} m, {turn:.1f} deg apart); add points spread wider across '
                'the image and in depth')
    center_std = _pose_center_std(world, rvec, translation.reshape(3, 1), k)
    if not center_std <= MAX_CENTRE_STD_RATIO * distance:
        raise CalibrationFitError(
            f'the points do not fix the pose: 1 px of pixel noise moves the camera centre by '
            f'{center_std:.3g} m (1 sigma) at a distance of {distance:.2f} m (> '
            f'{MAX_CENTRE_STD_RATIO:.0%}); spread the points wider across the image and avoid '
            'near-collinear points')
    calibration = replace(intrinsics, camera_name=str(camera_name or intrinsics.camera_name),
                          rotation=rotation, translation=translation)
    reprojected = Camera(calibration).project(world)
    notes = (('planar points: IPPE',) if planar else ()) + (
        f'camera centre 1-sigma {1000 * center_std:.1f} mm per px of pixel noise',)
    return _make_result('extrinsics', calibration, pixels, reprojected, world=world,
                        dist_terms=0, notes=notes)


def _rotation_angle_deg(r_a: np.ndarray, r_b: np.ndarray) -> float:
    cosine = (np.trace(r_a @ r_b.T) - 1.0) / 2.0
    return math.degrees(math.acos(float(np.clip(cosine, -1.0, 1.0))))


# -- full calibration ---------------------------------------------------------------------------


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


def _rq(matrix: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Return (upper-triangular K with a positive diagonal, orthogonal Q) with K @ Q = matrix."""
    flip = np.flipud(np.eye(3))
    q, r = np.linalg.qr((flip @ matrix).T)
    upper = flip @ r.T @ flip
    ortho = flip @ q.T
    signs = np.diag(np.sign(np.diag(upper)))
    return upper @ signs, signs @ ortho


def decompose_projection(projection: np.ndarray) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
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
                       image_size: Tuple[int, int]) -> Optional[np.ndarray]:
    """Return K with a centred principal point and the focal length whose PnP fits best."""
    width, height = image_size
    method = getattr(cv2, 'SOLVEPNP_SQPNP', cv2.SOLVEPNP_EPNP)

    def matrix(log_f):
        focal = math.exp(log_f)
        return np.array(((focal, 0.0, (width - 1) / 2.0), (0.0, focal, (height - 1) / 2.0),
                         (0.0, 0.0, 1.0)))

    def cost(log_f):
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


def _refine_full(world: np.ndarray, pixels: np.ndarray, image_size: Tuple[int, int],
                 guess: np.ndarray, dist_terms: int, centred: bool) -> tuple:
    """Refine K, distortion and pose from a start; return (rms, K, D, R, t) or raise."""
    _check_intrinsics(guess, np.zeros(5), image_size)
    camera_matrix = np.array(((guess[0, 0], 0.0, guess[0, 2]), (0.0, guess[1, 1], guess[1, 2]),
                              (0.0, 0.0, 1.0)))
    dist_coeffs = np.zeros(5)
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
        flags = _distortion_flags(terms) | cv2.CALIB_USE_INTRINSIC_GUESS | extra
        try:
            rms, camera_matrix, dist_coeffs, rvecs, tvecs = cv2.calibrateCamera(
                [world.astype(np.float32)], [pixels.astype(np.float32).reshape(-1, 1, 2)],
                image_size, camera_matrix, dist_coeffs, flags=flags, criteria=_LM_CRITERIA)
        except cv2.error as err:
            raise CalibrationFitError(f'OpenCV refinement failed: {err.err}') from err
    dist_coeffs = np.asarray(dist_coeffs, dtype=float).ravel()[:5]
    _check_intrinsics(camera_matrix, dist_coeffs, image_size)
    rotation = cv2.Rodrigues(np.asarray(rvecs[0], dtype=float))[0]
    translation = np.asarray(tvecs[0], dtype=float).ravel()
    _check_front(world, rotation, translation)
    return float(rms), camera_matrix, dist_coeffs, rotation, translation


def calibrate_full(world, pixels, image_size: Tuple[int, int], *, camera_name: str = 'camera',
                   dist_terms: Optional[int] = None,
                   lines: Optional[Sequence[int]] = None) -> CalibrationResult:
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
    width, height = _check_image_size(image_size)
    world, pixels = _check_correspondences(world, pixels, 6, lines)
    spread = _spread(world)
    if spread[2] < COPLANAR_RATIO * spread[0]:
        raise CalibrationFitError(
            f'the world points are (nearly) coplanar (thickness {spread[2] / spread[0]:.2%} of '
            'their extent): a full calibration needs points spread in depth; for a plane use '
            'chessboard intrinsics and then extrinsics')
    _check_inside(pixels, (width, height))
    if dist_terms is None:
        dist_terms = auto_dist_terms(len(world))
    _distortion_flags(dist_terms)

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
    calibration = _calibration(camera_name, (width, height), camera_matrix, dist_coeffs,
                               rotation, translation)
    reprojected = Camera(calibration).project(world)
    return _make_result('full', calibration, pixels, reprojected, world=world,
                        dist_terms=dist_terms, notes=tuple(notes))


# -- epipolar check of a calibrated pair --------------------------------------------------------


@dataclass(frozen=True, eq=False)
class EpipolarCheck:
    """
    Epipolar distances of two cameras' observations of one moving target.

    ``stamps_ns`` (M,) are camera a's stamps that camera b's track brackets,
    ``distances_px`` (M,) the symmetric epipolar distance there [ideal px];
    ``skipped`` counts camera a's observations without a bracket.
    """

    stamps_ns: np.ndarray
    distances_px: np.ndarray
    skipped: int

    @property
    def count(self) -> int:
        """Return the number of compared instants."""
        return len(self.distances_px)

    def percentile(self, q: float) -> float:
        """Return the q-th percentile of the distances [px] (NaN when empty)."""
        return float(np.percentile(self.distances_px, q)) if self.count else math.nan


def epipolar_check(cam_a: Camera, stamps_a, pixels_a, cam_b: Camera, stamps_b, pixels_b, *,
                   max_gap_ns: int) -> EpipolarCheck:
    """
    Compare two cameras' observations of one target with their epipolar geometry.

    Camera b's track is interpolated linearly in time to camera a's stamps, in
    undistorted (ideal) pixels where straight motion stays straight, and only
    between two observations at most ``max_gap_ns`` apart (or at an equal stamp).

    :param cam_a: the camera whose stamps are used
    :param stamps_a: (N,) integer stamps [ns]
    :param pixels_a: (N, 2) raw pixels
    :param cam_b: the other camera
    :param stamps_b: (M,) integer stamps [ns]
    :param pixels_b: (M, 2) raw pixels
    :param max_gap_ns: the longest interval to interpolate across [ns]
    :return: the distances; non-finite pixels are ignored
    """
    stamps_a = np.asarray(stamps_a, dtype=np.int64).reshape(-1)
    stamps_b = np.asarray(stamps_b, dtype=np.int64).reshape(-1)
    pixels_a = np.asarray(pixels_a, dtype=float).reshape(-1, 2)
    pixels_b = np.asarray(pixels_b, dtype=float).reshape(-1, 2)
    keep_a = np.all(np.isfinite(pixels_a), axis=1)
    keep_b = np.all(np.isfinite(pixels_b), axis=1)
    stamps_a, pixels_a = stamps_a[keep_a], pixels_a[keep_a]
    order = np.argsort(stamps_b[keep_b], kind='stable')
    stamps_b, pixels_b = stamps_b[keep_b][order], pixels_b[keep_b][order]
    if len(stamps_a) == 0 or len(stamps_b) == 0:
        return EpipolarCheck(np.zeros(0, np.int64), np.zeros(0), len(stamps_a))
    ideal_b = cam_b.ideal_pixels(pixels_b)
    right = np.searchsorted(stamps_b, stamps_a, side='left')
    exact = (right < len(stamps_b)) & (stamps_b[np.minimum(right, len(stamps_b) - 1)] == stamps_a)
    left = right - 1
    inside = (left >= 0) & (right < len(stamps_b))
    lo, hi = np.clip(left, 0, None), np.minimum(right, len(stamps_b) - 1)
    # Integer differences first: stamps near 1.7e18 ns lose precision as float64.
    gap = stamps_b[hi] - stamps_b[lo]
    usable = exact | (inside & (gap <= max_gap_ns) & (gap > 0))
    with np.errstate(invalid='ignore', divide='ignore'):
        weight = np.where(exact, 1.0, (stamps_a - stamps_b[lo]) / np.where(gap > 0, gap, 1))
    interpolated = (ideal_b[lo] * (1.0 - weight[:, None]) + ideal_b[hi] * weight[:, None])
    interpolated = interpolated[usable]
    if len(interpolated) == 0:
        return EpipolarCheck(np.zeros(0, np.int64), np.zeros(0), len(stamps_a))
    # epipolar_distance takes raw pixels: re-distort by projecting a point on each ideal ray.
    directions = cam_b.ray_directions(cam_b.ideal_to_normalized(interpolated))
    raw_b = cam_b.project(cam_b.center + directions)
    distances = epipolar_distance(cam_a, pixels_a[usable], cam_b, raw_b)
    finite = np.isfinite(distances)
    return EpipolarCheck(stamps_a[usable][finite], distances[finite],
                         int(len(stamps_a) - np.count_nonzero(usable)
                             + np.count_nonzero(~finite)))
