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

Stamps are integer nanoseconds and are parsed as integers, never floats,
within the int64 range.  Every CSV of the package (these and the
correspondences of ``pseudo_stereo calibrate``) is read by :func:`read_rows`,
so encodings, byte-order marks and malformed lines get the same one-line
errors everywhere.
Files are written to a temporary name and renamed, so a failed run never
leaves a half-written file that looks complete.
"""

from __future__ import annotations

from collections.abc import Collection, Iterable, Iterator, Sequence
import csv
import math
import os
from pathlib import Path
import tempfile
from typing import Any

import numpy as np

from ..calibration import PathLike
from ..errors import CsvError
from ..records import Estimate, Observation

__all__ = [
    'CsvError',
    'ESTIMATE_COLUMNS',
    'OBSERVATION_COLUMNS',
    'STAMP_MAX_NS',
    'STAMP_MIN_NS',
    'TRUTH_COLUMNS',
    'parse_float',
    'parse_stamp',
    'read_estimates',
    'read_observations',
    'read_rows',
    'read_truth',
    'write_estimates',
    'write_observations',
    'write_truth',
]

OBSERVATION_COLUMNS = ('stamp_ns', 'camera', 'u', 'v')
ESTIMATE_COLUMNS = ('stamp_ns', 'camera', 'x', 'y', 'z')
TRUTH_COLUMNS = ('stamp_ns', 'x', 'y', 'z')


#: The range of a stamp [ns]: a signed 64-bit integer, as numpy and the fuser keep it.
STAMP_MIN_NS, STAMP_MAX_NS = -2 ** 63, 2 ** 63 - 1


def _bad_byte_line(path: PathLike) -> tuple[int, int, int] | tuple[None, None, None]:
    """Return ``(line, byte, offset)`` of the first byte of a file that is not UTF-8."""
    with open(path, 'rb') as stream:
        data = stream.read()
    try:
        data.decode('utf-8-sig')
    except UnicodeDecodeError as err:
        return data.count(b'\n', 0, err.start) + 1, data[err.start], err.start
    return None, None, None


def read_rows(path: PathLike, columns: Sequence[str], *, comments: bool = False,
              lowercase: bool = False) -> Iterator[tuple[str, int, dict[str, str]]]:
    """
    Yield the rows of a CSV file with the required columns: the one CSV reader of the package.

    A UTF-8 byte-order mark (spreadsheet exports) is skipped; empty lines are skipped.
    Columns beyond the required ones are allowed.

    :param path: the file
    :param columns: the required column names
    :param comments: skip lines whose first field starts with ``#``
    :param lowercase: match the header's names case-insensitively
    :return: an iterator of ``(source, line number, row dict)`` (names stripped, and lowered
        with ``lowercase``)
    :raises CsvError: one line naming the file, the line and the reason: unreadable, not UTF-8
        (the line of the first bad byte), malformed CSV (a field over the csv module's
        131,072-character limit, a stray quote), a missing column, a row with fewer values
        than the header
    """
    source = os.fspath(path)
    try:
        # utf-8-sig: a byte-order mark is not part of the first column.
        stream = open(path, newline='', encoding='utf-8-sig')
    except OSError as err:
        raise CsvError(f'{source}: cannot read: {err.strerror}') from err
    expected = ','.join(columns)
    with stream:
        reader = csv.reader(stream)
        try:
            header: list[str] | None = None
            for record in reader:
                if not ''.join(record).strip() or (
                        comments and record[0].lstrip().startswith('#')):
                    continue
                if header is None:
                    header = [name.strip() for name in record]
                    if lowercase:
                        header = [name.lower() for name in header]
                    missing = [name for name in columns if name not in header]
                    if missing:
                        raise CsvError(f'{source}:{reader.line_num}: missing column(s) '
                                       f'{", ".join(missing)} (expected header {expected})')
                    continue
                if len(record) < len(header):
                    raise CsvError(f'{source}:{reader.line_num}: expected {len(header)} values '
                                   f'({",".join(header)}), got {len(record)}')
                yield source, reader.line_num, dict(zip(header, record))
        except UnicodeDecodeError as err:
            line, byte, offset = _bad_byte_line(path)
            raise CsvError(f'{source}:{line}: not a UTF-8 CSV file (byte 0x{byte:02x} at '
                           f'offset {offset})' if line is not None else
                           f'{source}: not a UTF-8 CSV file ({err.reason})') from err
        except csv.Error as err:
            raise CsvError(f'{source}:{reader.line_num}: malformed CSV: {err}') from err
    if header is None:
        raise CsvError(f'{source}: missing column(s) {", ".join(columns)} (empty file; '
                       f'expected header {expected})')


def parse_stamp(text: str, source: str, line: int, column: str) -> int:
    """Parse an integer stamp [ns] within the int64 range; raise :class:`CsvError` naming it."""
    try:
        value = int(text.strip())
    except (AttributeError, ValueError):
        raise CsvError(f'{source}:{line}: column {column}: not an integer: {text!r}') from None
    if not STAMP_MIN_NS <= value <= STAMP_MAX_NS:
        raise CsvError(f'{source}:{line}: column {column}: {text.strip()[:40]} is outside the '
                       f'int64 range of a stamp [ns] ({STAMP_MIN_NS} to {STAMP_MAX_NS})')
    return value


def parse_float(text: str, source: str, line: int, column: str, *, finite: bool = True) -> float:
    """Parse a number (finite unless ``finite`` is False); raise :class:`CsvError` naming it."""
    try:
        value = float(text.strip())
    except (AttributeError, ValueError):
        raise CsvError(f'{source}:{line}: column {column}: not a number: {text!r}') from None
    if finite and not math.isfinite(value):
        raise CsvError(f'{source}:{line}: column {column}: not finite: {text!r}')
    return value


def read_observations(path: PathLike,
                      cameras: Collection[str] | None = None) -> list[Observation]:
    """
    Read an observations CSV (``stamp_ns,camera,u,v``).

    :param path: the file
    :param cameras: the known camera names; a row naming another is an error
    :return: the observations in file order
    :raises CsvError: naming the file, line and reason
    """
    observations = []
    for source, line, row in read_rows(path, OBSERVATION_COLUMNS):
        camera = (row['camera'] or '').strip()
        if not camera:
            raise CsvError(f'{source}:{line}: column camera: empty')
        if cameras is not None and camera not in cameras:
            raise CsvError(f'{source}:{line}: unknown camera {camera!r} '
                           f'(configured: {", ".join(sorted(cameras))})')
        observations.append(Observation(
            camera, parse_stamp(row['stamp_ns'], source, line, 'stamp_ns'),
            parse_float(row['u'], source, line, 'u', finite=False),
            parse_float(row['v'], source, line, 'v', finite=False)))
    return observations


def read_estimates(path: PathLike) -> list[Estimate]:
    """Read an estimates CSV (``stamp_ns,camera,x,y,z``); ``kind`` is read as ''."""
    return [Estimate(parse_stamp(row['stamp_ns'], source, line, 'stamp_ns'),
                     row['camera'].strip(),
                     parse_float(row['x'], source, line, 'x'),
                     parse_float(row['y'], source, line, 'y'),
                     parse_float(row['z'], source, line, 'z'), '')
            for source, line, row in read_rows(path, ESTIMATE_COLUMNS)]


def read_truth(path: PathLike) -> tuple[np.ndarray, np.ndarray]:
    """
    Read a truth CSV (``stamp_ns,x,y,z``, rows in any order).

    :param path: the file
    :return: ((N,) int64 stamps [ns] sorted, (N, 3) positions [m])
    :raises CsvError: naming the file, line and reason (also for a repeated stamp)
    """
    rows: dict[int, list[float]] = {}
    for source, line, row in read_rows(path, TRUTH_COLUMNS):
        stamp = parse_stamp(row['stamp_ns'], source, line, 'stamp_ns')
        if stamp in rows:
            raise CsvError(f'{source}:{line}: stamp {stamp} repeated')
        rows[stamp] = [parse_float(row[c], source, line, c) for c in 'xyz']
    stamps = sorted(rows)
    return (np.array(stamps, dtype=np.int64),
            np.array([rows[s] for s in stamps], dtype=float).reshape(-1, 3))


def _write_atomically(path: PathLike, header: Sequence[str],
                      rows: Iterable[Sequence[Any]]) -> None:
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


def write_observations(path: PathLike, observations: Iterable[Observation]) -> None:
    """Write an observations CSV; pixels with 17 significant digits (exact round trip)."""
    _write_atomically(path, OBSERVATION_COLUMNS,
                      ((o.stamp_ns, o.camera, repr(float(o.u)), repr(float(o.v)))
                       for o in observations))


def write_estimates(path: PathLike, estimates: Iterable[Estimate]) -> None:
    """Write an estimates CSV in the given (stamp) order; metres, exact round trip."""
    _write_atomically(path, ESTIMATE_COLUMNS,
                      ((e.stamp_ns, e.camera, repr(e.x), repr(e.y), repr(e.z))
                       for e in estimates))


def write_truth(path: PathLike, stamps: Sequence[int] | np.ndarray, points: np.ndarray) -> None:
    """Write a truth CSV of (N,) stamps [ns] and (N, 3) positions [m]."""
    _write_atomically(path, TRUTH_COLUMNS,
                      ((int(s), repr(float(p[0])), repr(float(p[1])), repr(float(p[2])))
                       for s, p in zip(stamps, points)))
