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
The shared data records: one detection in, one 3D estimate out, and the truth.

Stamps are integer nanoseconds on the cameras' common clock; pixels are raw
(distorted) image coordinates [px]; positions are world coordinates [m].
ROS-free: every part of the package (core, formats, nodes) exchanges these.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple, TypeAlias

import numpy as np

__all__ = [
    'Estimate',
    'GroundTruth',
    'Observation',
    'Point3',
    'positions_array',
]

#: A 3D point or direction as plain floats (x, y, z) [m].
Point3: TypeAlias = tuple[float, float, float]


class Observation(NamedTuple):
    """One detection: camera name, shutter stamp [integer ns], raw pixel (u, v)."""

    camera: str
    stamp_ns: int
    u: float
    v: float


class Estimate(NamedTuple):
    """
    One 3D estimate at a shutter event.

    ``x, y, z`` are world coordinates [m], ``stamp_ns`` the shutter stamp of
    the event, ``camera`` the camera that fired, and ``kind`` one of
    ``'pseudo'`` (paper method), ``'sync'`` (simultaneous pair),
    ``'interpolated'`` (an observation that arrived after a later one of the
    partner: Steps I-III at its own time) or ``'naive'``.
    """

    stamp_ns: int
    camera: str
    x: float
    y: float
    z: float
    kind: str


class GroundTruth(NamedTuple):
    """The true ball position [m] at a shutter stamp [integer ns] (simulation and replays)."""

    stamp_ns: int
    x: float
    y: float
    z: float


def positions_array(records: Sequence[Estimate | GroundTruth]) -> np.ndarray:
    """Return the (N, 3) positions [m] of a list of estimates or truth records."""
    return np.array([(r.x, r.y, r.z) for r in records], dtype=float).reshape(-1, 3)
