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
The package's error tree: one base class, one subclass per concern.

Every error a user can fix (a bad file, option, parameter or message)
derives from :class:`PseudoStereoError`.  Its message names the input and the
reason in one line.  The command line maps the base class to exit status 2
in one place (:mod:`pseudo_stereo_ros.cli.main`); the nodes map it to the
one-line FATAL start-up error in one place
(:func:`pseudo_stereo_ros.ros.node_tools.run_node`).  Anything else is a bug
and keeps its traceback.  The base derives from :class:`ValueError` so that
callers that caught ``ValueError`` before keep working.
"""

from __future__ import annotations

__all__ = [
    'BagError',
    'CalibrationError',
    'CalibrationFitError',
    'CaptureError',
    'CsvError',
    'DetectorConfigError',
    'EncodingError',
    'FuserConfigError',
    'PseudoStereoError',
    'RigError',
    'StartupError',
    'UsageError',
]


class PseudoStereoError(ValueError):
    """An input a user can fix; the message names it and says why, in one line."""


class CalibrationError(PseudoStereoError):
    """A calibration file or its values are invalid; the message names the file and key."""


class CalibrationFitError(CalibrationError):
    """The calibration data cannot determine the camera (too few, degenerate or ambiguous)."""


class CaptureError(PseudoStereoError):
    """A frame source cannot be opened or read (a device, a video file); the message names it."""


class DetectorConfigError(PseudoStereoError):
    """A ball detector option is invalid; the message names it."""


class RigError(PseudoStereoError):
    """A set of cameras is invalid: too few, or a repeated name or one that is not a ROS name."""


class EncodingError(PseudoStereoError):
    """An image has an encoding or size the detector cannot use."""


class FuserConfigError(PseudoStereoError):
    """A fuser option is invalid; the message names it."""


class CsvError(PseudoStereoError):
    """A CSV file is unreadable or malformed; the message names the file and line."""


class BagError(PseudoStereoError):
    """A bag is missing, unreadable or lacks a topic; the message names the bag."""


class StartupError(PseudoStereoError):
    """A node's parameter or file is invalid at start-up; the message names it."""


class UsageError(PseudoStereoError):
    """A bad argument, option value or input file of a command or evaluation (exit status 2)."""
