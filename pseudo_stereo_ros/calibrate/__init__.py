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

- :func:`calibrate_intrinsics` (:mod:`.intrinsics`): camera matrix and
  distortion from chessboard images (OpenCV, Zhang's method); the pose is left
  at identity.
- :func:`calibrate_extrinsics` (:mod:`.extrinsics`): the pose
  ``x_cam = R @ x_world + t`` from at least 4 world <-> raw-pixel
  correspondences and known intrinsics.
- :func:`calibrate_full` (:mod:`.full`): intrinsics, distortion and pose from
  at least 6 non-coplanar correspondences, as in the paper (a linear DLT
  start, refined by OpenCV's Levenberg-Marquardt).

:func:`epipolar_check` (:mod:`.pair_check`) checks a calibrated pair against
a recorded flight.  The tuning constants and input checks the fits share live
in :mod:`.checks`.

Pixels are raw (distorted) pixels with OpenCV's convention (integer
coordinates at pixel centres); world points are metres.  Degenerate input is
refused with :class:`~pseudo_stereo_ros.errors.CalibrationFitError` (a
:class:`~pseudo_stereo_ros.errors.CalibrationError`, so the command line
reports it in one line): a fit never returns a silently bad calibration.
This differs on purpose from the NaN policy of the geometry functions: a
calibration is a file a user keeps, not a per-event result.
"""

from .checks import CalibrationResult, DISTORTION_TERMS, flag_outliers, OUTLIER_SIGMAS
from .extrinsics import calibrate_extrinsics
from .full import auto_dist_terms, calibrate_full, decompose_projection, dlt_projection
from .intrinsics import calibrate_intrinsics, list_images, video_boards
from .pair_check import epipolar_check, EpipolarCheck
from ..errors import CalibrationFitError

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
    'video_boards',
]
