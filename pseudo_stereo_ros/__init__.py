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
Pseudo stereo vision for unsynchronized cameras, as a ROS 2 package.

The core (this package's modules that are not ``*_node`` or ``bringup``)
imports neither rclpy nor any message package: :mod:`.calibration`,
:mod:`.camera`, :mod:`.geometry`, :mod:`.fusion` and :mod:`.simulation`.
"""

from .calibration import CalibrationError, CameraCalibration, load_calibration, save_calibration
from .camera import Camera
from .errors import PseudoStereoError
from .fusion import fuse, Fuser, make_fuser, METHODS
from .records import Estimate, GroundTruth, Observation
from .trajectory import TrajectoryFuser

__all__ = [
    'CalibrationError',
    'Camera',
    'CameraCalibration',
    'Estimate',
    'Fuser',
    'GroundTruth',
    'METHODS',
    'Observation',
    'PseudoStereoError',
    'TrajectoryFuser',
    'fuse',
    'load_calibration',
    'make_fuser',
    'save_calibration',
]
