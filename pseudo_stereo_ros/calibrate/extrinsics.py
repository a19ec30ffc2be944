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
Camera pose from world <-> raw-pixel correspondences and known intrinsics.

:func:`calibrate_extrinsics` refines every PnP solver's pose and a start
mirrored in the points' plane, and refuses ambiguous or undetermined poses.
"""

from __future__ import annotations

from dataclasses import replace
import math
from typing import TypeAlias

import cv2
import numpy as np
from numpy.typing import ArrayLike

from .checks import (AMBIGUOUS_POSE_RATIO, AMBIGUOUS_PX, AMBIGUOUS_RATIO, AMBIGUOUS_ROTATION_DEG,
                     CalibrationResult, check_correspondences, check_front, check_inside,
                     LineNumbers, LM_CRITERIA, make_result, MAX_CENTRE_STD_RATIO,
                     PLANAR_PNP_RATIO, point_spread)
from ..calibration import CameraCalibration
from ..camera import Camera
from ..errors import CalibrationFitError

__all__ = [
    'calibrate_extrinsics',
]

# A refined pose: ((behind, rms_px), rotation (3, 3), translation (3,), rvec (3, 1)).
_Fit: TypeAlias = tuple[tuple[bool, float], np.ndarray, np.ndarray, np.ndarray]


def _pnp_candidates(world: np.ndarray, ideal: np.ndarray, camera_matrix: np.ndarray,
                    planar: bool) -> list[tuple[np.ndarray, np.ndarray]]:
    methods = []
    if planar:
        methods.append(cv2.SOLVEPNP_IPPE)
    elif len(world) >= 6:
        methods.append(cv2.SOLVEPNP_ITERATIVE)
    if hasattr(cv2, 'SOLVEPNP_SQPNP'):
        methods.append(cv2.SOLVEPNP_SQPNP)
    if not planar or len(methods) == 1:
        methods.append(cv2.SOLVEPNP_EPNP)
    candidates: list[tuple[np.ndarray, np.ndarray]] = []
    for method in methods:
        try:
            count, rvecs, tvecs, _ = cv2.solvePnPGeneric(world, ideal, camera_matrix, None,
                                                         flags=method)
        except cv2.error:
            continue
        candidates.extend(zip(rvecs[:count], tvecs[:count]))
    return candidates


def _flipped_start(world: np.ndarray, rotation: np.ndarray,
                   translation: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
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

    def center(x: np.ndarray) -> np.ndarray:
        return -cv2.Rodrigues(x[:3])[0].T @ x[3:]

    step = 1e-7
    derivative = np.column_stack([(center(params + step * e) - center(params - step * e))
                                  / (2.0 * step) for e in np.eye(6)])
    eigen = np.linalg.eigvalsh(derivative @ covariance @ derivative.T)
    return float(math.sqrt(max(eigen[-1], 0.0))) if np.all(np.isfinite(eigen)) else math.inf


def _refine_pose(world: np.ndarray, ideal: np.ndarray, k: np.ndarray, rvec: ArrayLike,
                 tvec: ArrayLike) -> _Fit | None:
    """
    Refine one PnP start by Levenberg-Marquardt in ideal pixels.

    :return: ``((behind, rms_px), rotation, translation, rvec)``, sortable by its first item
        (poses with every point in front first, then by RMS), or None for a non-finite start
        or result
    """
    rvec, tvec = np.asarray(rvec, float).reshape(3, 1), np.asarray(tvec, float).reshape(3, 1)
    if not (np.all(np.isfinite(rvec)) and np.all(np.isfinite(tvec))):
        return None
    rvec, tvec = cv2.solvePnPRefineLM(world, ideal, k, None, rvec, tvec, LM_CRITERIA)
    rotation = cv2.Rodrigues(rvec)[0]
    in_front = bool(np.all(world @ rotation[2] + tvec[2, 0] > 0))
    projected = cv2.projectPoints(world, rvec, tvec, k, None)[0].reshape(-1, 2)
    rms = float(np.sqrt(np.mean(np.sum((projected - ideal) ** 2, axis=1))))
    if not math.isfinite(rms):
        return None
    return (not in_front, rms), rotation, tvec.ravel(), rvec


def calibrate_extrinsics(intrinsics: CameraCalibration, world: ArrayLike, pixels: ArrayLike, *,
                         camera_name: str | None = None,
                         lines: LineNumbers | None = None) -> CalibrationResult:
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
    world, pixels = check_correspondences(world, pixels, 4, lines)
    image_size = (intrinsics.image_width, intrinsics.image_height)
    check_inside(pixels, image_size)
    camera = Camera(replace(intrinsics, rotation=np.eye(3), translation=np.zeros(3)))
    # Solve in undistorted (ideal) pixels so every distortion model, fisheye included, works
    # alike; ideal and raw pixels differ by the local scale of the distortion only.
    ideal = camera.ideal_pixels(pixels)
    k = camera.K
    spread = point_spread(world)
    planar = spread[2] < PLANAR_PNP_RATIO * spread[0]
    candidates = _pnp_candidates(world, ideal, k, planar)
    fits = [fit for fit in (_refine_pose(world, ideal, k, rvec, tvec)
                            for rvec, tvec in candidates) if fit is not None]
    if not fits:
        raise CalibrationFitError('no pose fits the points (OpenCV solvePnP failed)')
    mirrored = (_refine_pose(world, ideal, k, *_flipped_start(world, rotation, translation))
                for _, rotation, translation, _ in fits)
    fits += [fit for fit in mirrored if fit is not None]
    fits.sort(key=lambda fit: fit[0])
    (_, best_rms), rotation, translation, rvec = fits[0]
    check_front(world, rotation, translation)
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
    return make_result('extrinsics', calibration, pixels, reprojected, world=world,
                       dist_terms=0, notes=notes)


def _rotation_angle_deg(r_a: np.ndarray, r_b: np.ndarray) -> float:
    cosine = (np.trace(r_a @ r_b.T) - 1.0) / 2.0
    return math.degrees(math.acos(float(np.clip(cosine, -1.0, 1.0))))


# -- full calibration ---------------------------------------------------------------------------
