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
The CSV files other tools script against; keep these column names.

- observations: ``stamp_ns,camera,u,v`` (rows in any order; raw pixels)
- estimates: ``stamp_ns,camera,x,y,z`` (world metres, in stamp order)
- truth: ``stamp_ns,x,y,z``

Stamps are integer nanoseconds and are parsed as integers, never floats.
Files are written to a temporary name and renamed, so a failed run never
leaves a half-written file that looks complete.
"""

import csv
import math
import os
from pathlib import Path
import tempfile
from typing import Collection, Iterable, List, Optional, Sequence

import numpy as np

from ..errors import CsvError
from ..records import Estimate, Observation

__all__ = [
    'CsvError',
    'ESTIMATE_COLUMNS',
    'OBSERVATION_COLUMNS',
    'TRUTH_COLUMNS',
    'read_estimates',
    'read_observations',
    'read_truth',
    'write_estimates',
    'write_observations',
    'write_truth',
]

OBSERVATION_COLUMNS = ('stamp_ns', 'camera', 'u', 'v')
ESTIMATE_COLUMNS = ('stamp_ns', 'camera', 'x', 'y', 'z')
TRUTH_COLUMNS = ('stamp_ns', 'x', 'y', 'z')


def _rows(path, columns: Sequence[str]):
    """Yield (line number, row dict) of a CSV file with the required columns."""
    source = os.fspath(path)
    try:
        # utf-8-sig: a byte-order mark (spreadsheet exports) is not part of the first column.
        stream = open(path, newline='', encoding='utf-8-sig')
    except OSError as err:
        raise CsvError(f'{source}: cannot read: {err.strerror}') from err
    with stream:
        reader = csv.DictReader(stream)
        try:
            header = [name.strip() for name in (reader.fieldnames or [])]
            missing = [name for name in columns if name not in header]
            if missing:
                raise CsvError(f'{source}:1: missing column(s) {", ".join(missing)} '
                               f'(expected header {",".join(columns)})')
            reader.fieldnames = header
            for row in reader:
                yield source, reader.line_num, row
        except (UnicodeDecodeError, csv.Error) as err:
            raise CsvError(f'{source}:{reader.line_num + 1}: not a UTF-8 CSV file '
                           f'({err})') from err


def _int(text: str, source: str, line: int, column: str) -> int:
    try:
        return int(text.strip())
    except (AttributeError, ValueError):
        raise CsvError(f'{source}:{line}: column {column}: not an integer: {text!r}') from None


def _float(text: str, source: str, line: int, column: str, *, finite: bool = True) -> float:
    try:
        value = float(text.strip())
    except (AttributeError, ValueError):
        raise CsvError(f'{source}:{line}: column {column}: not a number: {text!r}') from None
    if finite and not math.isfinite(value):
        raise CsvError(f'{source}:{line}: column {column}: not finite: {text!r}')
    return value


def read_observations(path, cameras: Optional[Collection[str]] = None) -> List[Observation]:
    """
    Read an observations CSV (``stamp_ns,camera,u,v``).

    :param path: the file
    :param cameras: the known camera names; a row naming another is an error
    :return: the observations in file order
    :raises CsvError: naming the file, line and reason
    """
    observations = []
    for source, line, row in _rows(path, OBSERVATION_COLUMNS):
        camera = (row['camera'] or '').strip()
        if not camera:
            raise CsvError(f'{source}:{line}: column camera: empty')
        if cameras is not None and camera not in cameras:
            raise CsvError(f'{source}:{line}: unknown camera {camera!r} '
                           f'(configured: {", ".join(sorted(cameras))})')
        observations.append(Observation(
            camera, _int(row['stamp_ns'], source, line, 'stamp_ns'),
            _float(row['u'], source, line, 'u', finite=False),
            _float(row['v'], source, line, 'v', finite=False)))
    return observations


def read_estimates(path) -> List[Estimate]:
    """Read an estimates CSV (``stamp_ns,camera,x,y,z``); ``kind`` is read as ''."""
    return [Estimate(_int(row['stamp_ns'], source, line, 'stamp_ns'), row['camera'].strip(),
                     _float(row['x'], source, line, 'x'), _float(row['y'], source, line, 'y'),
                     _float(row['z'], source, line, 'z'), '')
            for source, line, row in _rows(path, ESTIMATE_COLUMNS)]


def read_truth(path) -> tuple:
    """
    Read a truth CSV (``stamp_ns,x,y,z``, rows in any order).

    :param path: the file
    :return: ((N,) int64 stamps [ns] sorted, (N, 3) positions [m])
    :raises CsvError: naming the file, line and reason (also for a repeated stamp)
    """
    rows = {}
    for source, line, row in _rows(path, TRUTH_COLUMNS):
        stamp = _int(row['stamp_ns'], source, line, 'stamp_ns')
        if stamp in rows:
            raise CsvError(f'{source}:{line}: stamp {stamp} repeated')
        rows[stamp] = [_float(row[c], source, line, c) for c in 'xyz']
    stamps = sorted(rows)
    return (np.array(stamps, dtype=np.int64),
            np.array([rows[s] for s in stamps], dtype=float).reshape(-1, 3))


def _write_atomically(path, header: Sequence[str], rows: Iterable[Sequence]) -> None:
    path = Path(path)
    if path.is_dir():
        raise CsvError(f'{path}: is a directory, not a file to write')
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        handle, temporary = tempfile.mkstemp(dir=path.parent, prefix=f'.{path.name}.',
                                             suffix='.tmp')
    except OSError as err:
        raise CsvError(f'{path}: cannot write: {err.strerror}') from err
    try:
        with os.fdopen(handle, 'w', newline='', encoding='utf-8') as stream:
            writer = csv.writer(stream, lineterminator='\n')
            writer.writerow(header)
            writer.writerows(rows)
        os.replace(temporary, path)
    except BaseException:
        os.unlink(temporary)
        raise


def write_observations(path, observations: Iterable[Observation]) -> None:
    """Write an observations CSV; pixels with 17 significant digits (exact round trip)."""
    _write_atomically(path, OBSERVATION_COLUMNS,
                      ((o.stamp_ns, o.camera, repr(float(o.u)), repr(float(o.v)))
                       for o in observations))


def write_estimates(path, estimates: Iterable[Estimate]) -> None:
    """Write an estimates CSV in the given (stamp) order; metres, exact round trip."""
    _write_atomically(path, ESTIMATE_COLUMNS,
                      ((e.stamp_ns, e.camera, repr(e.x), repr(e.y), repr(e.z))
                       for e in estimates))


def write_truth(path, stamps: Sequence[int], points: np.ndarray) -> None:
    """Write a truth CSV of (N,) stamps [ns] and (N, 3) positions [m]."""
    _write_atomically(path, TRUTH_COLUMNS,
                      ((int(s), repr(float(p[0])), repr(float(p[1])), repr(float(p[2])))
                       for s, p in zip(stamps, points)))
