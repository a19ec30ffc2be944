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
Chessboard intrinsics: camera matrix and distortion from board images (Zhang's method).

:func:`calibrate_intrinsics` finds the board corners in each image (OpenCV),
refuses too few or poorly spread boards, and leaves the pose at identity.
:func:`video_boards` picks the frames showing the board from a video file or
a camera device (every n-th frame), so no second tool is needed.
"""

from __future__ import annotations

from collections.abc import Sequence
import math
import os
from typing import TypeAlias

import cv2
import numpy as np

from .checks import (CalibrationResult, check_intrinsics, distortion_flags, LM_CRITERIA,
                     make_calibration, make_result)
from ..errors import CalibrationFitError

__all__ = [
    'calibrate_intrinsics',
    'list_images',
    'video_boards',
]


_IMAGE_EXTENSIONS = ('.png', '.jpg', '.jpeg', '.bmp', '.tif', '.tiff', '.pgm', '.ppm')

ImageInput: TypeAlias = str | os.PathLike[str] | np.ndarray


def list_images(directory: str | os.PathLike[str]) -> list[str]:
    """Return the sorted image files (png, jpg, bmp, tif, pgm, ppm) of a directory."""
    directory = os.fspath(directory)
    if not os.path.isdir(directory):
        raise CalibrationFitError(f'{directory}: not a directory')
    names = sorted(name for name in os.listdir(directory)
                   if name.lower().endswith(_IMAGE_EXTENSIONS))
    if not names:
        raise CalibrationFitError(f'{directory}: no images ({", ".join(_IMAGE_EXTENSIONS)})')
    return [os.path.join(directory, name) for name in names]


def _gray(image: ImageInput, index: int, label: str | None = None) -> tuple[np.ndarray, str]:
    if isinstance(image, np.ndarray):
        label = label or f'image {index}'
        array = image
    else:
        label = os.fspath(image)
        read = cv2.imread(label, cv2.IMREAD_UNCHANGED)
        if read is None:
            raise CalibrationFitError(f'{label}: cannot read the image')
        array = read
    if array.ndim == 3 and array.shape[2] == 4:
        array = cv2.cvtColor(array, cv2.COLOR_BGRA2GRAY)
    elif array.ndim == 3 and array.shape[2] == 3:
        array = cv2.cvtColor(array, cv2.COLOR_BGR2GRAY)
    elif array.ndim != 2:
        raise CalibrationFitError(f'{label}: not a grey or colour image (shape {array.shape})')
    if array.dtype != np.uint8:
        # A dst array, not None: some OpenCV stubs require one (5.1's allow None).  C order
        # whatever the image's (OpenCV refuses a Fortran-ordered dst).
        array = cv2.normalize(array, np.empty(array.shape, array.dtype), 0, 255,
                              cv2.NORM_MINMAX).astype(np.uint8)
    return array, label


def _board_points(board: tuple[int, int], square_m: float) -> np.ndarray:
    cols, rows = board
    grid = np.zeros((cols * rows, 3))
    grid[:, :2] = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2) * square_m
    return grid


def _find_corners(gray: np.ndarray, board: tuple[int, int]) -> np.ndarray | None:
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


def _coverage(corner_sets: Sequence[np.ndarray], image_size: tuple[int, int]) -> float:
    """Return the fraction of the image covered by the union of the boards' convex hulls."""
    scale = 0.25
    width, height = image_size
    mask = np.zeros((max(1, int(height * scale)), max(1, int(width * scale))), np.uint8)
    for corners in corner_sets:
        hull = cv2.convexHull((corners * scale).astype(np.float32)).astype(np.int32)
        cv2.fillConvexPoly(mask, hull, 1)
    return float(mask.mean())


def _is_device(source: str) -> bool:
    text = str(source).strip()
    return text.isdigit() or text.startswith('/dev/')


def _open_video(source: str, capture_factory):
    """Open a video file, or a device given as ``/dev/videoN`` or an index."""
    text = str(source).strip()
    is_device = _is_device(text)
    if is_device:
        device = int(text) if text.isdigit() else text
        if isinstance(device, str) and not os.path.exists(device):
            raise CalibrationFitError(f'{text}: no such device')
        capture = (capture_factory or (lambda d: cv2.VideoCapture(d, cv2.CAP_V4L2)))(device)
    else:
        if not os.path.isfile(text):
            raise CalibrationFitError(f'{text}: no such video file')
        capture = (capture_factory or cv2.VideoCapture)(text)
    if capture is None or not capture.isOpened():
        raise CalibrationFitError(f'{text}: cannot open the {"camera" if is_device else "video"}')
    return capture, is_device


def video_boards(source: str, *, board: tuple[int, int], every_n: int = 10,
                 max_frames: int = 0, max_boards: int = 40,
                 capture_factory=None) -> tuple[list, list, int]:
    """
    Read every n-th frame of a video file or a camera and keep those showing the board.

    :param source: a video file, or a camera: ``/dev/videoN`` or an index
    :param board: inner corners ``(cols, rows)``
    :param every_n: look at every n-th frame (consecutive frames of a video are nearly the
        same view)
    :param max_frames: stop after this many frames (0: the whole file; a camera needs it)
    :param max_boards: keep at most this many boards, evenly spread over the ones found
    :param capture_factory: ``factory(file or device) -> VideoCapture`` (tests)
    :return: ``(images, labels, frames_read)``: the frames with a board, their labels
        (``frame N``) and the number of frames read
    :raises CalibrationFitError: the source cannot be opened or read; bad options
    """
    if int(every_n) < 1 or int(max_frames) < 0 or int(max_boards) < 1:
        raise CalibrationFitError(f'need every_n >= 1, max_frames >= 0 and max_boards >= 1, '
                                  f'got {every_n}, {max_frames}, {max_boards}')
    if _is_device(source) and not max_frames:
        raise CalibrationFitError(f'{source}: a camera needs a frame count (--frames)')
    capture, _ = _open_video(source, capture_factory)
    cols, rows = (int(x) for x in board)
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE | \
        cv2.CALIB_CB_FAST_CHECK
    images, labels = [], []
    count = 0
    try:
        while not max_frames or count < max_frames:
            ok, frame = capture.read()
            if not ok or frame is None:
                break
            count += 1
            if (count - 1) % int(every_n):
                continue
            gray, _ = _gray(frame, count - 1)
            if cv2.findChessboardCorners(gray, (cols, rows), flags=flags)[0]:
                images.append(frame)
                labels.append(f'frame {count - 1}')
    finally:
        capture.release()
    if count == 0:
        raise CalibrationFitError(f'{source}: no frame could be read')
    if len(images) > max_boards:
        keep = np.unique(np.round(np.linspace(0, len(images) - 1, int(max_boards))).astype(int))
        images = [images[i] for i in keep]
        labels = [labels[i] for i in keep]
    return images, labels, count


def calibrate_intrinsics(images: Sequence[ImageInput], *, board: tuple[int, int],
                         square_m: float, camera_name: str = 'camera', dist_terms: int = 4,
                         min_boards: int = 5, min_coverage: float = 0.3,
                         min_tilt_deg: float = 15.0,
                         labels: Sequence[str] | None = None) -> CalibrationResult:
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
    :param labels: names of array images in messages and the result (``frame 120``); files
        are named by their paths
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
    flags = distortion_flags(dist_terms)

    names = list(labels) if labels is not None else [None] * len(images)
    image_size: tuple[int, int] | None = None
    labels = []
    corner_sets: list[np.ndarray] = []
    missed: list[str] = []
    for index, image in enumerate(images):
        gray, label = _gray(image, index, names[index])
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
    assert image_size is not None, 'images is not empty: the first one set the size'
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
    # OpenCV's stubs (those of 5.1 still) require a camera matrix; None (no initial guess) is
    # what OpenCV documents.  'unused-ignore': stubs that allow None do not fail the check.
    _, camera_matrix, dist_coeffs, rvecs, tvecs, std_intrinsics = cv2.calibrateCameraExtended(
        [object_points.astype(np.float32)] * len(corner_sets),
        [c.astype(np.float32).reshape(-1, 1, 2) for c in corner_sets], image_size,
        None,  # type: ignore[call-overload, unused-ignore]
        np.zeros(5), flags=flags, criteria=LM_CRITERIA)[:6]
    dist_coeffs = np.asarray(dist_coeffs, dtype=float).ravel()[:5]
    check_intrinsics(camera_matrix, dist_coeffs, image_size)

    normals = np.array([cv2.Rodrigues(r)[0][:, 2] for r in rvecs])
    cosines = np.clip(np.abs(normals @ normals.T), 0.0, 1.0)
    tilt_spread = math.degrees(math.acos(cosines.min()))
    if tilt_spread < min_tilt_deg:
        raise CalibrationFitError(
            f'too little tilt variety: the board orientations differ by at most '
            f'{tilt_spread:.1f} deg, need {min_tilt_deg:g}; tilt the board (up to ~45 deg) '
            'left/right and up/down')

    reprojected: list[np.ndarray] = []
    image_rms: list[float] = []
    point_image: list[np.ndarray] = []
    for index, (corners, rvec, tvec) in enumerate(zip(corner_sets, rvecs, tvecs)):
        projected = cv2.projectPoints(object_points, rvec, tvec, camera_matrix,
                                      dist_coeffs)[0].reshape(-1, 2)
        reprojected.append(projected)
        image_rms.append(float(np.sqrt(np.mean(np.sum((projected - corners) ** 2, axis=1)))))
        point_image.append(np.full(len(corners), index))
    calibration = make_calibration(camera_name, image_size, camera_matrix, dist_coeffs, np.eye(3),
                                   np.zeros(3))
    notes = [f'{len(corner_sets)} of {len(images)} images used, coverage {100 * coverage:.0f}%, '
             f'tilt variety {tilt_spread:.0f} deg']
    if missed:
        notes.append(f'no board found in: {", ".join(os.path.basename(m) for m in missed)}')
    return make_result(
        'intrinsics', calibration, np.vstack(corner_sets), np.vstack(reprojected),
        image_labels=tuple(labels), image_rms_px=np.array(image_rms),
        point_image=np.concatenate(point_image), dist_terms=dist_terms, notes=tuple(notes),
        intrinsics_std=np.asarray(std_intrinsics, dtype=float).ravel()[:4])


# -- pose from correspondences ------------------------------------------------------------------
