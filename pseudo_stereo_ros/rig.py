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
A rig: the named, calibrated cameras of one set-up, built one way everywhere.

The command line (``--camera NAME=CALIB.yaml``), the nodes (``camera_names``
and ``calibration_files`` parameters) and the simulation all build their
cameras here.  The name given by the user is the name used in the data (topic
namespaces, CSV columns); it overrides the file's ``camera_name``.  The default
rig is ``config/rig/<name>.yaml`` of the package (two 640x480 cameras,
``camera1`` and ``camera2``).  ROS-free.

A camera name is a ROS namespace token everywhere (``/<name>/ball/image_point``,
``/<name>/image_raw``, the node namespace in ``bringup``), so one rule,
:func:`check_camera_name`, holds for the command line as for the nodes: a
letter, then letters, digits or underscores, at most
:data:`MAX_CAMERA_NAME_LENGTH` characters.  That is ROS 2's rule for a name
token (rcl refuses a token that starts with a digit or holds another
character) without a leading underscore (hidden topics) or a ``/``.  Names
are refused, not mapped: a mapped name would differ between the user's files
and the topics.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from itertools import combinations
import os
from pathlib import Path
import re

import numpy as np

from .calibration import PathLike
from .camera import Camera
from .errors import RigError
from .geometry import fundamental_matrix

__all__ = ['CAMERA_NAME_RULE', 'DEFAULT_CAMERA_NAMES', 'MAX_CAMERA_NAME_LENGTH', 'Rig',
           'check_camera_name', 'config_dir']

#: The cameras of the package's default rig (``config/rig/<name>.yaml``).
DEFAULT_CAMERA_NAMES = ('camera1', 'camera2')

#: Longest camera name: keeps ``/<namespace>/<name>/ball/image_point`` well inside ROS's limit
#: of about 250 characters for a topic name.
MAX_CAMERA_NAME_LENGTH = 100

#: The rule, as error messages state it.
CAMERA_NAME_RULE = (f'a letter, then letters, digits or underscores, at most '
                    f'{MAX_CAMERA_NAME_LENGTH} characters')

_CAMERA_NAME = re.compile(r'[A-Za-z][A-Za-z0-9_]*')


def check_camera_name(name: str) -> str:
    """
    Return ``name`` if it is a valid camera name (a ROS name token), else raise.

    :param name: the camera name
    :return: the name
    :raises RigError: one line naming the name, the rule and a valid name to use instead
    """
    if (isinstance(name, str) and len(name) <= MAX_CAMERA_NAME_LENGTH
            and _CAMERA_NAME.fullmatch(name)):
        return name
    if not isinstance(name, str) or not name:
        raise RigError(f'camera name {name!r} is not a valid ROS name: use {CAMERA_NAME_RULE}')
    suggestion = re.sub(r'[^A-Za-z0-9_]', '_', name)
    if not suggestion[0].isalpha():
        suggestion = 'camera_' + suggestion.lstrip('_')
    suggestion = suggestion[:MAX_CAMERA_NAME_LENGTH]
    raise RigError(f'camera name {name!r} is not a valid ROS name (it is the namespace of the '
                   f"camera's topics): use {CAMERA_NAME_RULE}, e.g. {suggestion!r}")


def config_dir() -> Path:
    """
    Return the package's config directory.

    In a source tree or editable install it is ``config/`` beside the package;
    in a colcon install it is ``share/pseudo_stereo_ros/config``.

    :raises FileNotFoundError: neither exists
    """
    source = Path(__file__).resolve().parent.parent / 'config'
    if source.is_dir():
        return source
    for parent in Path(__file__).resolve().parents:
        candidate = parent / 'share' / 'pseudo_stereo_ros' / 'config'
        if candidate.is_dir():
            return candidate
    raise FileNotFoundError('cannot find the pseudo_stereo_ros config directory '
                            f'(looked beside {os.fspath(source.parent)} and in share/)')


class Rig(Mapping[str, Camera]):
    """
    Named cameras in a fixed order, with their pairwise epipolar geometry.

    A read-only mapping name -> :class:`~pseudo_stereo_ros.camera.Camera`;
    iteration gives the names in the order given.  :attr:`cameras` is the
    list of cameras in that order.
    """

    def __init__(self, cameras: Sequence[Camera], *, minimum: int = 1) -> None:
        """
        Make a rig of calibrated cameras.

        :param cameras: the cameras; their names must be unique and valid
            (:func:`check_camera_name`)
        :param minimum: the least number of cameras the caller needs
        :raises RigError: too few cameras, or an invalid or repeated name
        """
        names = [check_camera_name(camera.name) for camera in cameras]
        repeated = sorted({name for name in names if names.count(name) > 1})
        if repeated:
            raise RigError(f'camera names must be unique, got {", ".join(repeated)} twice')
        if len(names) < minimum:
            raise RigError(f'need at least {minimum} cameras, got {len(names)}')
        self._cameras = dict(zip(names, cameras))
        self._fundamental: dict[tuple[str, str], np.ndarray] = {}

    @classmethod
    def from_files(cls, files: Sequence[tuple[str, PathLike]], *, minimum: int = 1) -> Rig:
        """
        Load a rig from ``(name, calibration file)`` pairs, in order.

        :param files: the pairs; the name overrides the file's ``camera_name``
        :param minimum: the least number of cameras the caller needs
        :raises CalibrationError: a file is missing or malformed (the message names it)
        :raises RigError: too few cameras, or an invalid or repeated name
        """
        for name, _ in files:
            check_camera_name(name)  # before reading files: a bad name is the first fault
        return cls([Camera.from_file(path, name=name) for name, path in files], minimum=minimum)

    @classmethod
    def default(cls, names: Sequence[str] = DEFAULT_CAMERA_NAMES) -> Rig:
        """Load the package's default rig: ``config/rig/<name>.yaml`` for each name."""
        rig_dir = config_dir() / 'rig'
        return cls.from_files([(name, rig_dir / f'{name}.yaml') for name in names])

    @property
    def names(self) -> list[str]:
        """Return the camera names, in order."""
        return list(self._cameras)

    @property
    def cameras(self) -> list[Camera]:
        """Return the cameras, in order."""
        return list(self._cameras.values())

    def pairs(self) -> list[tuple[str, str]]:
        """Return every unordered pair of camera names, in rig order."""
        return list(combinations(self._cameras, 2))

    def fundamental(self, name_a: str, name_b: str) -> np.ndarray:
        """
        Return F (3, 3) with ``p_b^T F p_a = 0`` for homogeneous *ideal* pixels of a pair.

        :param name_a: the camera whose points are mapped to lines
        :param name_b: the camera in whose ideal image the lines lie
        """
        key = (name_a, name_b)
        if key not in self._fundamental:
            self._fundamental[key] = fundamental_matrix(self[name_a], self[name_b])
        return self._fundamental[key]

    def __getitem__(self, name: str) -> Camera:
        return self._cameras[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._cameras)

    def __len__(self) -> int:
        return len(self._cameras)

    def __repr__(self) -> str:
        return f'Rig({", ".join(self._cameras)})'
