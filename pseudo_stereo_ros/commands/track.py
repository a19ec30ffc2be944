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

"""``pseudo_stereo track``: run a method offline on recorded observations."""

import sys

from . import UsageError
from .common import add_camera_argument, cameras_from_args, seconds_to_ns
from ..csv_io import CsvError, read_observations, read_truth, write_estimates
from ..experiments import score
from ..fusion import (DEFAULT_MAX_GAP_NS, DEFAULT_SYNC_TOLERANCE_NS, DROP_REASONS, fuse,
                      Fuser, METHODS)

NAME = 'track'
HELP = 'run the fuser offline on observations (stamp_ns,camera,u,v) -> estimates CSV'


def add_arguments(parser) -> None:
    """Add this command's options."""
    add_camera_argument(parser)
    parser.add_argument('--input', required=True, metavar='OBS.csv',
                        help='observations with header stamp_ns,camera,u,v (any row order)')
    parser.add_argument('--output', required=True, metavar='EST.csv',
                        help='estimates with header stamp_ns,camera,x,y,z, in stamp order')
    parser.add_argument('--method', choices=METHODS, default='paper')
    parser.add_argument('--sync-tolerance', type=float, default=DEFAULT_SYNC_TOLERANCE_NS / 1e9,
                        metavar='S', help='observations closer than this are simultaneous '
                                          '(default: %(default)s s)')
    parser.add_argument('--max-gap', type=float, default=DEFAULT_MAX_GAP_NS / 1e9, metavar='S',
                        help='longest gap bridged by interpolation (default: %(default)s s)')
    parser.add_argument('--truth', metavar='TRUTH.csv',
                        help='optional ground truth (stamp_ns,x,y,z): print the error')


def run(args) -> int:
    """Run the command."""
    cameras = cameras_from_args(args.camera)
    try:
        observations = read_observations(args.input, cameras)
        truth = read_truth(args.truth) if args.truth else None
    except CsvError as err:
        raise UsageError(str(err)) from err
    options = {'method': args.method,
               'sync_tolerance_ns': seconds_to_ns(args.sync_tolerance, '--sync-tolerance'),
               'max_gap_ns': seconds_to_ns(args.max_gap, '--max-gap')}
    try:
        Fuser(cameras, **options)
    except ValueError as err:
        raise UsageError(str(err)) from err
    estimates, stats = fuse(cameras, observations, **options)
    write_estimates(args.output, estimates)
    dropped = ', '.join(f'{key} {stats[key]}' for key in DROP_REASONS if stats[key])
    print(f'{len(observations)} observations -> {len(estimates)} estimates '
          f'({args.method}) written to {args.output}'
          + (f'; no estimate: {dropped}' if dropped else ''), file=sys.stderr)
    if truth is not None:
        try:
            result = score(estimates, *truth)
        except ValueError as err:
            raise UsageError(f'--truth {args.truth}: {err}') from err
        print(f'error against {args.truth}: per-coordinate MAE {result.mae_mm:.3f} mm, '
              f'mean 3D distance {result.distance_mm:.3f} mm over {result.count} estimates')
    return 0
