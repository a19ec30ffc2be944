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
Camera calibration files: the one format every part of the package reads.

One YAML file per camera, compatible with the output of ROS camera_calibration
(the camera_info keys ``image_width``, ``image_height``, ``camera_name``,
``camera_matrix``, ``distortion_model``, ``distortion_coefficients``) plus the
extrinsics ``rotation_matrix`` (3x3) and ``translation`` (3 values, metres),
with the convention ``x_cam = R @ x_world + t``.  Other camera_info keys
(``rectification_matrix``, ``projection_matrix``, ``camera_model``) may be
present and are ignored.

Every key is read and checked by one function (``_camera_name``,
``_image_size``, ``_camera_matrix``, ``_distortion``, ``_rotation``, the
shared ``_matrix``); a new key gets its own.  Every error is one
:class:`CalibrationError` line naming the file, the key (or the line and
column of bad YAML) and the reason; non-finite numbers are refused in
every numeric field.
The optional ``time_offset_s`` (default 0) is added to the camera's stamps to
put them on the rig's common shutter clock (see
:mod:`pseudo_stereo_ros.timesync`); :func:`write_time_offsets` updates only
that key of existing files.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
import math
import os
import re
import shutil
import tempfile
from typing import Any

import numpy as np
import yaml

from .errors import CalibrationError
from .formats.yaml_io import read_yaml

__all__ = [
    'CalibrationError',
    'CameraCalibration',
    'DISTORTION_MODELS',
    'calibration_from_dict',
    'calibration_to_dict',
    'load_calibration',
    'load_camera_info',
    'save_calibration',
    'write_time_offsets',
]

#: Distortion model name -> allowed numbers of coefficients (OpenCV order).
#: ``plumb_bob`` and ``radtan`` are OpenCV's (k1, k2, p1, p2[, k3]),
#: ``rational_polynomial`` adds (k4, k5, k6), ``equidistant`` is the fisheye
#: model (k1, k2, k3, k4).
DISTORTION_MODELS = {
    'plumb_bob': (4, 5),
    'radtan': (4, 5),
    'rational_polynomial': (8,),
    'equidistant': (4,),
}

#: Largest allowed deviation of R @ R.T from identity (and of det(R) from 1).
ROTATION_TOLERANCE = 1e-5

#: Largest image side [px]: OpenCV keeps image sizes in 32-bit ints.
MAX_IMAGE_SIZE_PX = 2 ** 31 - 1

PathLike = str | os.PathLike


@dataclass(frozen=True, eq=False)
class CameraCalibration:
    """
    Intrinsics, distortion and pose of one camera.

    ``camera_matrix`` is K (3, 3) in pixels, ``dist_coeffs`` D (k,) in OpenCV
    order for ``distortion_model``, ``rotation`` R (3, 3) and ``translation``
    t (3,) [m] map world to camera coordinates: ``x_cam = R @ x_world + t``.
    ``time_offset_s`` [s] is added to the camera's stamps to put them on the
    common shutter clock (a camera that stamps its frames 5 ms late has -0.005).
    """

    camera_name: str
    image_width: int
    image_height: int
    camera_matrix: np.ndarray
    distortion_model: str
    dist_coeffs: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray
    time_offset_s: float = 0.0

    @property
    def center(self) -> np.ndarray:
        """Return the optical centre in the world frame, (3,) [m]."""
        return -self.rotation.T @ self.translation


def _fail(source: str, key: str, reason: str) -> CalibrationError:
    return CalibrationError(f'{source}: key {key!r}: {reason}')


def _show(value: Any) -> str:
    """Describe a YAML value in a few words for an error message."""
    if isinstance(value, Mapping):
        return 'a mapping'
    if isinstance(value, list):
        return f'a list of {len(value)}'
    if value is None:
        return 'nothing (null)'
    if isinstance(value, bool):
        return f'the boolean {value}'
    if isinstance(value, str):
        text = repr(value)
        return f'the string {text if len(text) <= 40 else text[:37] + "..."}'
    text = repr(value)
    return text if len(text) <= 40 else f'a number of {len(text)} digits'


def _integer(value: Any) -> int | None:
    """Return ``value`` as an int if it is a whole number (``640`` or ``640.0``), else None."""
    if isinstance(value, bool):
        return None
    if isinstance(value, int):
        return value
    if isinstance(value, float) and math.isfinite(value) and value.is_integer():
        return int(value)
    return None


def _entry(data: Mapping[str, Any], key: str, source: str) -> Any:
    if data.get(key) is None:
        raise _fail(source, key, 'missing')
    return data[key]


def _numbers(value: Any, key: str, source: str) -> tuple[np.ndarray, tuple[int, int] | None]:
    """
    Read a matrix value: ``{rows, cols, data}``, a nested list or a flat list of numbers.

    :return: the finite values, flat, and the shape the value declares (rows and cols, or
        the nesting), if any
    """
    declared: tuple[int, int] | None = None
    if isinstance(value, Mapping):
        if 'data' not in value:
            raise _fail(source, key, "missing 'data' (expected {rows, cols, data})")
        rows, cols = value.get('rows'), value.get('cols')
        if rows is not None or cols is not None:
            n_rows, n_cols = _integer(rows), _integer(cols)
            if n_rows is None or n_cols is None or min(n_rows, n_cols) < 1:
                raise _fail(source, key, f'rows and cols must be positive integers, got '
                                         f'{_show(rows)} and {_show(cols)}')
            declared = (n_rows, n_cols)
        value = value['data']
    if not isinstance(value, list):
        raise _fail(source, key, f'expected a list of numbers, got {_show(value)}')
    flat = value
    if any(isinstance(item, list) for item in value):
        if not all(isinstance(item, list) and len(item) == len(value[0]) for item in value):
            raise _fail(source, key, 'not a matrix (rows that are not lists of equal length)')
        flat = [x for row in value for x in row]
        nested = (len(value), len(value[0]))
        if declared is not None and declared != nested:
            raise _fail(source, key, f'rows x cols = {declared[0]}x{declared[1]} but data is '
                                     f'{nested[0]}x{nested[1]}')
        declared = nested
    numbers = []
    for x in flat:
        if isinstance(x, bool) or not isinstance(x, (int, float)):
            raise _fail(source, key, f'not a numeric matrix (holds {_show(x)})')
        try:
            numbers.append(float(x))
        except OverflowError:  # an integer beyond the float range
            numbers.append(math.inf)
    array = np.array(numbers, dtype=float)
    if not np.all(np.isfinite(array)):
        raise _fail(source, key, 'contains a non-finite value')
    if declared is not None and declared[0] * declared[1] != array.size:
        raise _fail(source, key, f'rows x cols = {declared[0]}x{declared[1]} but data has '
                                 f'{array.size} values')
    return array, declared


def _matrix(data: Mapping[str, Any], key: str, shape: tuple, source: str) -> np.ndarray:
    """Read ``key`` as a finite matrix of the given shape ((3, 3), or (3,) for a vector)."""
    array, declared = _numbers(_entry(data, key, source), key, source)
    if len(shape) == 2 and declared is not None and declared != shape:
        raise _fail(source, key, f'expected {shape[0]}x{shape[1]}, declared rows x cols = '
                                 f'{declared[0]}x{declared[1]}')
    size = int(np.prod(shape))
    if array.size != size:
        raise _fail(source, key, f'expected {size} values for shape {shape}, got {array.size}')
    return array.reshape(shape)


# -- one reader per key -------------------------------------------------------------------------


def _camera_name(data: Mapping[str, Any], source: str, raw_name: str | None) -> str:
    _entry(data, 'camera_name', source)
    name = raw_name if raw_name is not None else data['camera_name']
    if not isinstance(name, (str, int, float)) or isinstance(name, bool):
        raise _fail(source, 'camera_name', f'expected a name, got {_show(name)}')
    if isinstance(name, float) and name.is_integer():
        name = int(name)
    name = str(name).strip()
    if not name:
        raise _fail(source, 'camera_name', 'empty')
    return name


def _image_size(data: Mapping[str, Any], key: str, source: str) -> int:
    value = _entry(data, key, source)
    size = _integer(value)
    if size is None or not 0 < size <= MAX_IMAGE_SIZE_PX:
        raise _fail(source, key, f'expected a positive integer number of pixels (at most '
                                 f'{MAX_IMAGE_SIZE_PX}), got {_show(value)}')
    return size


def _camera_matrix(data: Mapping[str, Any], source: str) -> np.ndarray:
    camera_matrix = _matrix(data, 'camera_matrix', (3, 3), source)
    fx, fy = camera_matrix[0, 0], camera_matrix[1, 1]
    if fx <= 0 or fy <= 0:
        raise _fail(source, 'camera_matrix', f'focal lengths must be positive, got {fx}, {fy}')
    if not np.allclose(camera_matrix[2], (0.0, 0.0, 1.0)) or camera_matrix[1, 0] != 0:
        raise _fail(source, 'camera_matrix', 'expected [[fx, s, cx], [0, fy, cy], [0, 0, 1]]')
    return camera_matrix


def _distortion(data: Mapping[str, Any], source: str) -> tuple[str, np.ndarray]:
    """Read ``distortion_model`` and its ``distortion_coefficients``."""
    model = str(_entry(data, 'distortion_model', source))
    if model not in DISTORTION_MODELS:
        raise _fail(source, 'distortion_model',
                    f'unknown model {model!r} (known: {", ".join(DISTORTION_MODELS)})')
    key = 'distortion_coefficients'
    coeffs, _ = _numbers(_entry(data, key, source), key, source)
    allowed = DISTORTION_MODELS[model]
    if coeffs.size not in allowed:
        raise _fail(source, key, f'model {model!r} takes {" or ".join(map(str, allowed))} '
                                 f'coefficients, got {coeffs.size}')
    return model, coeffs


def _rotation(data: Mapping[str, Any], source: str) -> np.ndarray:
    rotation = _matrix(data, 'rotation_matrix', (3, 3), source)
    deviation = np.abs(rotation @ rotation.T - np.eye(3)).max()
    det = np.linalg.det(rotation)
    if deviation > ROTATION_TOLERANCE or abs(det - 1.0) > ROTATION_TOLERANCE:
        raise _fail(source, 'rotation_matrix',
                    f'not a rotation (|R R^T - I| = {deviation:.2g}, det = {det:.6g})')
    return rotation


def _time_offset(data: Mapping[str, Any], source: str) -> float:
    """Read the optional ``time_offset_s`` [s] (0 when absent)."""
    value = data.get('time_offset_s', 0.0)
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not math.isfinite(value):
        raise _fail(source, 'time_offset_s', f'expected a finite number of seconds, got {value!r}')
    return float(value)


def calibration_from_dict(data: Mapping[str, Any], *, source: str = '<dict>',
                          raw_name: str | None = None) -> CameraCalibration:
    """
    Build a calibration from a parsed YAML mapping, validating every key.

    :param data: the mapping as read by ``yaml.safe_load``
    :param source: the file name used in error messages
    :param raw_name: ``camera_name`` exactly as written in the file (YAML may
        have read a numeric name such as 22276213 as a number)
    :return: the validated calibration
    :raises CalibrationError: naming the source, the key and the reason, in one line
    """
    if not isinstance(data, Mapping):
        raise CalibrationError(f'{source}: expected a YAML mapping of calibration keys, '
                               f'got {_show(data)}')
    name = _camera_name(data, source, raw_name)
    width = _image_size(data, 'image_width', source)
    height = _image_size(data, 'image_height', source)
    camera_matrix = _camera_matrix(data, source)
    model, dist_coeffs = _distortion(data, source)
    rotation = _rotation(data, source)
    translation = _matrix(data, 'translation', (3,), source)
    time_offset_s = _time_offset(data, source)

    for array in (camera_matrix, dist_coeffs, rotation, translation):
        array.setflags(write=False)
    return CameraCalibration(
        camera_name=name, image_width=width, image_height=height,
        camera_matrix=camera_matrix, distortion_model=model, dist_coeffs=dist_coeffs,
        rotation=rotation, translation=translation, time_offset_s=time_offset_s)


def load_calibration(path: PathLike) -> CameraCalibration:
    """
    Read and validate one camera's calibration YAML file.

    The file is read by :func:`~pseudo_stereo_ros.formats.yaml_io.read_yaml`:
    at most 1 MiB, no aliases, nesting at most 32 deep.

    :param path: the file
    :return: the calibration
    :raises CalibrationError: the file is missing, not YAML, or malformed; one line naming
        the file, the line or the key, and the reason
    """
    data, raw_name = _read_calibration_yaml(path)
    return calibration_from_dict(data, source=os.fspath(path), raw_name=raw_name)


def _read_calibration_yaml(path: PathLike) -> tuple[Any, str | None]:
    """
    Read a calibration or camera_info file through the guarded YAML reader.

    :return: the document, and ``camera_name`` as written (a numeric name keeps its digits:
        0123, 1e5), or None
    :raises CalibrationError: unreadable, too large, nested too deep, aliases, not YAML
    """
    data, node = read_yaml(path, error=CalibrationError)
    raw_name = None
    if isinstance(node, yaml.MappingNode):
        raw_name = next((value.value for key, value in node.value
                         if isinstance(key, yaml.ScalarNode) and key.value == 'camera_name'
                         and isinstance(value, yaml.ScalarNode) and value.tag.endswith(
                             (':int', ':float', ':str'))), None)
    return data, raw_name


def _yaml_matrix(array: np.ndarray) -> dict:
    rows, cols = (1, array.size) if array.ndim == 1 else array.shape
    return {'rows': rows, 'cols': cols, 'data': [float(x) for x in array.ravel()]}


def calibration_to_dict(calibration: CameraCalibration) -> dict:
    """
    Return the calibration as a camera_info-compatible mapping.

    :param calibration: the calibration
    :return: a mapping ready for ``yaml.safe_dump``
    """
    k = calibration.camera_matrix
    projection = np.zeros((3, 4))
    projection[:, :3] = k
    return {
        'image_width': calibration.image_width,
        'image_height': calibration.image_height,
        'camera_name': calibration.camera_name,
        'camera_matrix': _yaml_matrix(k),
        'distortion_model': calibration.distortion_model,
        'distortion_coefficients': _yaml_matrix(calibration.dist_coeffs),
        'rectification_matrix': _yaml_matrix(np.eye(3)),
        'projection_matrix': _yaml_matrix(projection),
        'rotation_matrix': _yaml_matrix(calibration.rotation),
        'translation': [float(x) for x in calibration.translation],
        'time_offset_s': float(calibration.time_offset_s),
    }


def save_calibration(calibration: CameraCalibration, path: PathLike) -> None:
    """
    Write a calibration YAML file that :func:`load_calibration` reads back exactly.

    :param calibration: the calibration
    :param path: the file to write
    """
    data = calibration_to_dict(calibration)
    for value in (data['camera_matrix'], data['distortion_coefficients'],
                  data['rotation_matrix'], {'data': [data['time_offset_s']]}):
        if not all(math.isfinite(x) for x in value['data']):
            raise CalibrationError(f'{os.fspath(path)}: refusing to write non-finite values')
    with open(path, 'w', encoding='utf-8') as stream:
        yaml.safe_dump(data, stream, sort_keys=False)


def load_camera_info(path: PathLike) -> CameraCalibration:
    """
    Read a camera's intrinsics from a camera_info YAML file, with or without a pose.

    Accepts the files ROS ``camera_calibration`` writes (``ost.yaml``) and
    ``camera_info_manager`` reads as they are: ``image_width``, ``image_height``,
    ``camera_name``, ``camera_matrix``, ``distortion_model`` and
    ``distortion_coefficients`` are used; ``rectification_matrix`` and
    ``projection_matrix`` are ignored.  Such a file has no extrinsics: the pose is
    then the identity.  A file of this package (with ``rotation_matrix`` and
    ``translation``) is read with its pose, as :func:`load_calibration` reads it.

    :param path: the file
    :return: the calibration (identity pose when the file has none)
    :raises CalibrationError: the file is missing, not YAML, or malformed (naming the file,
        the key and the reason); a pose with only one of ``rotation_matrix`` and
        ``translation`` is malformed
    """
    data, raw_name = _read_calibration_yaml(path)
    if isinstance(data, dict) and 'rotation_matrix' not in data and 'translation' not in data:
        data = dict(data, rotation_matrix=np.eye(3).tolist(), translation=[0.0, 0.0, 0.0])
    return calibration_from_dict(data, source=os.fspath(path), raw_name=raw_name)


#: A top-level ``time_offset_s:`` line of a block-style YAML file (value and comment apart).
_OFFSET_LINE = re.compile(r'^time_offset_s[ \t]*:[^\r\n#]*(?P<comment>#[^\r\n]*)?', re.MULTILINE)


def _format_seconds(seconds: float) -> str:
    """Return seconds as a YAML float with ns resolution (``-0.0123``, never ``1e-05``)."""
    text = f'{float(seconds):.9f}'.rstrip('0')
    text = text + '0' if text.endswith('.') else text
    return '0.0' if text in ('-0.0', '0.0') else text


def _with_time_offset(source: str, text: str, seconds: float) -> str:
    """Return a calibration file's text with ``time_offset_s`` set (validated)."""
    if isinstance(seconds, bool) or not math.isfinite(seconds):
        raise CalibrationError(f'{source}: time_offset_s must be a finite number, got {seconds!r}')
    newline = '\r\n' if '\r\n' in text else '\n'
    value = _format_seconds(seconds)
    matches = list(_OFFSET_LINE.finditer(text))
    if len(matches) > 1:
        raise CalibrationError(f"{source}: key 'time_offset_s' appears {len(matches)} times")
    if matches:
        match = matches[0]
        comment = match.group('comment')
        line = f'time_offset_s: {value}' + (f'  {comment}' if comment else '')
        text = text[:match.start()] + line + text[match.end():]
    else:
        if text and not text.endswith(('\n', '\r')):
            text += newline
        text += f'time_offset_s: {value}{newline}'
    written: CameraCalibration | None
    try:
        written = calibration_from_dict(yaml.safe_load(text), source=source)
    except (yaml.YAMLError, CalibrationError):
        written = None
    if written is None or written.time_offset_s != float(value):
        raise CalibrationError(f'{source}: cannot add time_offset_s to this file (not a block '
                               f'mapping?); add the line "time_offset_s: {value}" by hand')
    return text


def write_time_offsets(offsets: Mapping[PathLike, float]) -> None:
    """
    Set ``time_offset_s`` in existing calibration files, keeping every other byte.

    Each file's text is edited (the key's line replaced, or appended at the
    end), never re-dumped, so comments, key order and number formatting
    survive.  Every edit is made and validated before any file is replaced
    (each atomically), so an error leaves all files unchanged.

    :param offsets: calibration file -> offset [s] (finite)
    :raises CalibrationError: a file is unreadable or malformed, or the edit cannot be made
        (e.g. a flow-style ``{...}`` file)
    """
    texts = {}
    for path, seconds in offsets.items():
        source = os.fspath(path)
        load_calibration(path)  # a malformed file is reported as such, not as a failed edit
        try:
            with open(path, encoding='utf-8', newline='') as stream:
                text = stream.read()
        except OSError as err:
            raise CalibrationError(f'{source}: cannot read: {err.strerror}') from err
        texts[source] = _with_time_offset(source, text, seconds)
    for source, text in texts.items():
        directory = os.path.dirname(os.path.abspath(source))
        try:
            handle, temporary = tempfile.mkstemp(prefix='.time_offset_', dir=directory)
        except OSError as err:
            raise CalibrationError(f'{source}: cannot write: {err.strerror}') from err
        try:
            with os.fdopen(handle, 'w', encoding='utf-8', newline='') as stream:
                stream.write(text)
            shutil.copymode(source, temporary)
            os.replace(temporary, source)
        except OSError as err:
            if os.path.exists(temporary):
                os.unlink(temporary)
            raise CalibrationError(f'{source}: cannot write: {err.strerror}') from err
