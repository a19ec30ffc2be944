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
Per-camera time offsets: the convention, and the one place they are applied.

A camera's offset ``o`` [s] is *added* to its stamps to put them on the rig's
common shutter clock: ``true = stamp + o``.  A camera whose driver stamps its
frames 5 ms after the shutter has ``o = -0.005``; cameras on hosts whose
clocks differ have the difference.  The offset is the calibration file's
``time_offset_s`` (0 when absent), which ``track --time-offset`` and the fuser
node's ``time_offsets_s`` override.

Offsets are applied at one boundary, before any fusion method sees an
observation: :func:`apply_time_offsets` for recorded observations
(``track``, ``check``, ``holdout``), :func:`shift_observation` per point in the
fuser node.  Estimates are therefore stamped on the common clock and the
methods need no change.  Stamps stay integer nanoseconds.  Estimating
offsets is :mod:`pseudo_stereo_ros.timesync`.  ROS-free, stdlib only.
"""

from __future__ import annotations

import math
from typing import Dict, Iterable, List, Mapping, Optional, Sequence

from .camera import Camera
from .errors import UsageError
from .records import Observation
from .stamps import seconds_to_ns

__all__ = [
    'apply_time_offsets',
    'camera_time_offsets',
    'shift_observation',
]


def camera_time_offsets(cameras: Mapping[str, Camera] | Sequence[Camera],
                        overrides: Optional[Mapping[str, float]] = None) -> Dict[str, float]:
    """
    Return each camera's time offset [s]: its calibration's ``time_offset_s``, or an override.

    :param cameras: a :class:`~pseudo_stereo_ros.rig.Rig` (name -> camera) or cameras
    :param overrides: name -> offset [s] that replace the calibration's value
    :return: name -> offset [s], in the cameras' order
    :raises UsageError: an override names an unknown camera or is not finite
    """
    if isinstance(cameras, Mapping):
        cameras = list(cameras.values())
    offsets = {camera.name: float(camera.calibration.time_offset_s) for camera in cameras}
    for name, value in (overrides or {}).items():
        if name not in offsets:
            raise UsageError(f'time offset for unknown camera {name!r} '
                             f'(cameras: {", ".join(offsets)})')
        if isinstance(value, bool) or not math.isfinite(value):
            raise UsageError(f'time offset of camera {name!r}: expected a finite number of '
                             f'seconds, got {value!r}')
        offsets[name] = float(value)
    return offsets


def shift_observation(observation: Observation, offset_ns: int) -> Observation:
    """Return the observation with ``offset_ns`` added to its stamp (integer ns)."""
    if not offset_ns:
        return observation
    return observation._replace(stamp_ns=observation.stamp_ns + int(offset_ns))


def apply_time_offsets(observations: Iterable[Observation],
                       offsets_s: Mapping[str, float]) -> List[Observation]:
    """
    Put observations on the common clock: add each camera's offset to its stamps.

    :param observations: the observations (any cameras, any order)
    :param offsets_s: camera name -> offset [s]; cameras not named keep their stamps
    :return: the shifted observations, in the given order (stamps stay integer ns)
    """
    offsets_ns = {name: seconds_to_ns(value) for name, value in offsets_s.items()}
    return [shift_observation(obs, offsets_ns.get(obs.camera, 0)) for obs in observations]
