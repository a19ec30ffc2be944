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

from __future__ import annotations

import argparse
from collections.abc import Sequence
import math

from . import UsageError
from .. import stamps
from ..errors import RigError
from ..rig import check_camera_name, Rig

__all__ = ['add_camera_argument', 'add_recording_arguments', 'camera_files', 'cameras_from_args',
           'check_pixel_options', 'name_values', 'positive', 'read_recordings', 'seconds_to_ns',
           'time_offsets_from_args']


def add_camera_argument(parser: argparse.ArgumentParser, *, required: bool = True) -> None:
    """Add the repeatable ``--camera NAME=CALIB.yaml`` option."""
    parser.add_argument('--camera', action='append', default=[], required=required,
                        metavar='NAME=CALIB.yaml',
                        help='a camera name and its calibration file (give one per camera)')


def name_values(values: Sequence[str], option: str, *, what: str = 'VALUE',
                names: Sequence[str] | None = None) -> dict[str, str]:
    """
    Parse repeated ``NAME=VALUE`` option values into name -> value, in the given order.

    The one parser of per-camera options (``--camera``, ``--time-offset``, and
    ``bringup``'s ``--camera``, ``--calibration``, ``--fps``, ``--phase``).

    :param option: the option, for the messages (e.g. ``--camera``)
    :param what: what VALUE is, for the messages (e.g. ``CALIB.yaml``)
    :param names: the allowed names (None: any)
    :raises UsageError: a value without NAME or VALUE, a name not among ``names``, a name twice
    """
    pairs: dict[str, str] = {}
    for value in values:
        name, sep, text = value.partition('=')
        name, text = name.strip(), text.strip()
        if not sep or not name or not text:
            raise UsageError(f'{option} {value!r}: expected NAME={what}')
        if names is not None and name not in names:
            raise UsageError(f'{option} {value!r}: no camera {name!r}, not one of the cameras '
                             f'({", ".join(names)})')
        if name in pairs:
            raise UsageError(f'{option} {value!r}: camera {name!r} given twice')
        pairs[name] = text
    return pairs


def camera_files(values: Sequence[str]) -> dict[str, str]:
    """
    Parse ``NAME=CALIB.yaml`` values into camera name -> file path, in the given order.

    :func:`cameras_from_args` loads the files, and commands that write next to
    them or into them (``refine``, ``sync``) take the paths from here.

    :raises UsageError: malformed value, a name that is not a ROS name or a duplicate name
    """
    files = name_values(values, '--camera', what='CALIB.yaml')
    for name, path in files.items():
        try:
            check_camera_name(name)
        except RigError as err:
            raise UsageError(f'--camera {name}={path}: {err}') from err
    return files


def cameras_from_args(values: Sequence[str], *, minimum: int = 2) -> Rig:
    """
    Parse ``NAME=CALIB.yaml`` values into a rig (a mapping name -> camera), in the given order.

    The name given on the command line is the name used in the data (it
    overrides the file's camera_name).

    :raises UsageError: malformed value, a name that is not a ROS name, a duplicate name or
        too few cameras
    :raises CalibrationError: a calibration file is missing or malformed
    """
    files = camera_files(values)
    if len(files) < minimum:
        raise UsageError(f'--camera: need at least {minimum} cameras, got {len(files)}')
    return Rig.from_files(list(files.items()))


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


def time_offsets_from_args(values: Sequence[str], cameras) -> dict:
    """
    Parse ``--time-offset NAME=SECONDS`` values (camera name -> offset [s]).

    :param values: the option's values
    :param cameras: the rig (names must be among its cameras)
    :raises UsageError: malformed value, unknown camera, non-finite number, a name twice
    """
    offsets = {}
    for name, number in name_values(values, '--time-offset', what='SECONDS',
                                    names=list(cameras)).items():
        try:
            seconds = float(number)
        except ValueError:
            seconds = math.nan
        if not math.isfinite(seconds):
            raise UsageError(f'--time-offset {name}={number}: expected NAME=SECONDS '
                             '(a finite number)')
        offsets[name] = seconds
    return offsets


def add_recording_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``--input OBS.csv`` / ``--bag BAG`` (either, each repeatable: one recording each)."""
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument('--input', action='append', metavar='OBS.csv',
                        help='observations with header stamp_ns,camera,u,v and raw stamps '
                             '(repeat for several recordings)')
    source.add_argument('--bag', action='append', metavar='BAG',
                        help='a ROS 2 bag with /<camera>/ball/image_point (or image_raw, the '
                             'detector runs first) per camera (repeat for several recordings)')


def read_recordings(args, cameras) -> list:
    """
    Read the recordings of ``--input`` or ``--bag`` (one observation list per file).

    :raises UsageError: a recording without observations of the first camera
    :raises CsvError, BagError: unreadable or malformed input (the message names it)
    """
    from ..formats.csv_io import read_observations
    from .track import bag_observations
    names = list(cameras)
    recordings = []
    for path in args.input or []:
        recordings.append((path, read_observations(path, cameras)))
    for bag in args.bag or []:
        recordings.append((bag, bag_observations(bag, names, {})[0]))
    for source, observations in recordings:
        if not any(obs.camera == names[0] for obs in observations):
            raise UsageError(f'{source}: no observations of camera {names[0]!r}')
    return [observations for _, observations in recordings]
