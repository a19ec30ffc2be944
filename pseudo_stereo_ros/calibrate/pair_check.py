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
Epipolar consistency of a calibrated camera pair from a recorded flight.

:func:`epipolar_check` interpolates one camera's track at the other's stamps
and reports the epipolar distances [px]: a calibration that is off shows as a
median far above the detection noise.  Used by ``pseudo_stereo check``.
"""

from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np
from numpy.typing import ArrayLike

from ..camera import Camera
from ..geometry import epipolar_distance

__all__ = [
    'EpipolarCheck',
    'epipolar_check',
]


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


def epipolar_check(cam_a: Camera, stamps_a: ArrayLike, pixels_a: ArrayLike, cam_b: Camera,
                   stamps_b: ArrayLike, pixels_b: ArrayLike, *,
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
