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

"""Argument helpers shared by the subcommands."""

import argparse
import math
from typing import Sequence

from . import UsageError
from .. import stamps
from ..errors import RigError
from ..rig import check_camera_name, Rig

__all__ = ['add_camera_argument', 'cameras_from_args', 'check_pixel_options', 'positive',
           'seconds_to_ns']


def add_camera_argument(parser: argparse.ArgumentParser, *, required: bool = True) -> None:
    """Add the repeatable ``--camera NAME=CALIB.yaml`` option."""
    parser.add_argument('--camera', action='append', default=[], required=required,
                        metavar='NAME=CALIB.yaml',
                        help='a camera name and its calibration file (give one per camera)')


def cameras_from_args(values: Sequence[str], *, minimum: int = 2) -> Rig:
    """
    Parse ``NAME=CALIB.yaml`` values into a rig (a mapping name -> camera), in the given order.

    The name given on the command line is the name used in the data (it
    overrides the file's camera_name).

    :raises UsageError: malformed value, a name that is not a ROS name, a duplicate name or
        too few cameras
    :raises CalibrationError: a calibration file is missing or malformed
    """
    files = []
    for value in values:
        name, sep, path = value.partition('=')
        name, path = name.strip(), path.strip()
        if not sep or not name or not path:
            raise UsageError(f'--camera {value!r}: expected NAME=CALIB.yaml')
        if name in (known for known, _ in files):
            raise UsageError(f'--camera {value!r}: camera {name!r} given twice')
        try:
            check_camera_name(name)
        except RigError as err:
            raise UsageError(f'--camera {value!r}: {err}') from err
        files.append((name, path))
    if len(files) < minimum:
        raise UsageError(f'--camera: need at least {minimum} cameras, got {len(files)}')
    return Rig.from_files(files)


def seconds_to_ns(value: float, option: str) -> int:
    """Convert a non-negative duration option in seconds to integer nanoseconds."""
    if not (value >= 0 and math.isfinite(value)):
        raise UsageError(f'{option}: must be a finite, non-negative number of seconds, '
                         f'got {value}')
    return stamps.seconds_to_ns(value)


def check_pixel_options(args) -> None:
    """Check ``--noise`` and ``--quantization`` (finite, >= 0 pixels)."""
    for option in ('noise', 'quantization'):
        value = getattr(args, option)
        if not (value >= 0 and math.isfinite(value)):
            raise UsageError(f'--{option}: must be a finite number of pixels >= 0, got {value}')


def positive(text: str) -> float:
    """Parse a positive float for argparse."""
    value = float(text)
    if not (value > 0 and math.isfinite(value)):
        raise argparse.ArgumentTypeError(f'must be positive, got {text}')
    return value
