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
``pseudo_stereo sync``: estimate each camera's time offset from recorded ball flights.

Offsets are relative to the first ``--camera`` (which keeps the offset of its
calibration file, 0 by default); see :mod:`pseudo_stereo_ros.timesync` for the
method, the uncertainty and the warnings.  ``--json`` prints
``{"offsets_s": {...}, "uncertainty_s": {...}, ...}``; ``--write`` stores the
offsets as ``time_offset_s`` in the calibration files (only that line of each
file changes) and refuses while any camera has a warning.
"""

import json
import math
import sys

from . import UsageError
from .common import (add_camera_argument, add_recording_arguments, camera_files,
                     cameras_from_args, read_recordings)
from ..calibration import PathLike, write_time_offsets
from ..timesync import DEFAULT_MAX_UNCERTAINTY_S, estimate_time_offsets

__all__ = ['HELP', 'NAME', 'add_arguments', 'run']

NAME = 'sync'
HELP = ("estimate each camera's time offset (relative to the first camera) from recorded "
        'ball flights; --write stores them in the calibration files')


def add_arguments(parser) -> None:
    """Add this command's options."""
    add_camera_argument(parser)
    add_recording_arguments(parser)
    parser.add_argument('--search-s', type=float, default=0.0, metavar='S',
                        help='search at least this far either side of the given offsets [s] '
                             '(default: one frame period)')
    parser.add_argument('--max-gap-s', type=float, default=0.1, metavar='S',
                        help='interpolate a track only across gaps up to this [s] '
                             '(default: %(default)s)')
    parser.add_argument('--max-uncertainty-s', type=float, default=DEFAULT_MAX_UNCERTAINTY_S,
                        metavar='S', help='warn "unobservable" above this 1 sigma [s] '
                                          '(default: %(default)s)')
    parser.add_argument('--json', action='store_true',
                        help='print the result as JSON: {"offsets_s": {NAME: s}, '
                             '"uncertainty_s": {NAME: s}, ...}')
    parser.add_argument('--write', action='store_true',
                        help='store the offsets as time_offset_s in the calibration files '
                             '(refused while a camera has a warning)')


def _check(value: float, option: str, *, positive: bool) -> None:
    if not math.isfinite(value) or value < 0 or (positive and value == 0):
        kind = 'positive' if positive else 'non-negative'
        raise UsageError(f'{option}: expected a finite, {kind} number of seconds, got {value}')


def run(args) -> int:
    """Run the command."""
    _check(args.search_s, '--search-s', positive=False)
    _check(args.max_gap_s, '--max-gap-s', positive=True)
    _check(args.max_uncertainty_s, '--max-uncertainty-s', positive=True)
    cameras = cameras_from_args(args.camera)
    files = camera_files(args.camera)
    recordings = read_recordings(args, cameras)
    result = estimate_time_offsets(cameras, recordings, search_s=args.search_s,
                                   max_gap_s=args.max_gap_s,
                                   max_uncertainty_s=args.max_uncertainty_s)
    if args.json:
        print(json.dumps(_as_json(result), indent=2))
    else:
        _print(result)
    for name, warnings in result.warnings.items():
        for warning in warnings:
            print(f'warning: {name}: {warning}', file=sys.stderr)
    if args.write:
        blocked = [name for name, warnings in result.warnings.items() if warnings]
        if blocked:
            raise UsageError(f'--write: not writing: {", ".join(blocked)} ha'
                             f'{"s" if len(blocked) == 1 else "ve"} a warning (see above); '
                             'nothing written')
        updates: dict[PathLike, float] = {files[name]: result.offsets_s[name]
                                          for name in list(cameras)[1:]}
        if len(set(updates)) != len(updates):
            raise UsageError('--write: two cameras share a calibration file; nothing written')
        write_time_offsets(updates)
        print('wrote time_offset_s to ' + ', '.join(str(path) for path in updates),
              file=sys.stderr)
    return 0


def _finite(value: float):
    return value if math.isfinite(value) else None


def _as_json(result) -> dict:
    return {
        'offsets_s': dict(result.offsets_s),
        'uncertainty_s': {name: _finite(value) for name, value in result.uncertainty_s.items()},
        'reference': result.reference,
        'samples': result.samples,
        'residual_median_before_px': {name: _finite(value)
                                      for name, value in result.median_before_px.items()},
        'residual_median_after_px': {name: _finite(value)
                                     for name, value in result.median_after_px.items()},
        'pairs': [{'cameras': [p.camera_a, p.camera_b], 'offset_s': p.offset_s,
                   'uncertainty_s': _finite(p.uncertainty_s), 'samples': p.samples,
                   'crossing': p.crossing} for p in result.pairs],
        'closure_p': _finite(result.closure_p),
        'warnings': result.warnings,
    }


def _print(result) -> None:
    reference = result.reference
    print(f'time offsets relative to {reference} (kept at '
          f'{result.given_s[reference] * 1e3:+.3f} ms); true time = stamp + offset')
    print(f'{"camera":<12} {"offset [ms]":>12} {"1 sigma [ms]":>13} {"given [ms]":>11} '
          f'{"samples":>8}  epipolar residual median before -> after [px]')
    for name, offset in result.offsets_s.items():
        if name == reference:
            continue
        sigma = result.uncertainty_s[name]
        print(f'{name:<12} {offset * 1e3:>+12.3f} {sigma * 1e3:>13.3f} '
              f'{result.given_s[name] * 1e3:>+11.3f} {result.samples[name]:>8d}  '
              f'{result.median_before_px[name]:.2f} -> {result.median_after_px[name]:.2f}')
    for pair in result.pairs:
        print(f'  pair {pair.camera_a} -> {pair.camera_b}: {pair.offset_s * 1e3:+.3f} '
              f'+- {pair.uncertainty_s * 1e3:.3f} ms ({pair.samples} samples, '
              f'{pair.crossing:.0%} of the image motion crosses the epipolar lines)')
