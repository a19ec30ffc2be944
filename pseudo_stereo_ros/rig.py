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
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from itertools import combinations
import os
from pathlib import Path

import numpy as np

from .calibration import PathLike
from .camera import Camera
from .errors import RigError
from .geometry import fundamental_matrix

__all__ = ['DEFAULT_CAMERA_NAMES', 'Rig', 'config_dir']

#: The cameras of the package's default rig (``config/rig/<name>.yaml``).
DEFAULT_CAMERA_NAMES = ('camera1', 'camera2')


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

    def __init__(self, cameras: Sequence[Camera], *, minimum: int = 1):
        """
        Make a rig of calibrated cameras.

        :param cameras: the cameras; their names must be unique and non-empty
        :param minimum: the least number of cameras the caller needs
        :raises RigError: too few cameras, or an empty or repeated name
        """
        names = [camera.name for camera in cameras]
        if any(not isinstance(name, str) or not name for name in names):
            raise RigError(f'camera names must be non-empty strings, got {names}')
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
        :raises RigError: too few cameras, or an empty or repeated name
        """
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
