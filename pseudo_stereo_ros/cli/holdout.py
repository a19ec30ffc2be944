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

r"""
``pseudo_stereo holdout``: score methods on real bags by a held-out third camera.

Example (the test data)::

    D=test/data/lfg_table_tennis
    pseudo_stereo holdout $D/n1_n1 $D/n3_p1_v14 $D/p2_p2 \
        --camera camera_1=$D/22276213_calibration.yaml \
        --camera camera_2=$D/22276209_calibration.yaml \
        --camera camera_3=$D/22276216_calibration.yaml
"""

import argparse
from pathlib import Path

from . import UsageError
from .common import add_camera_argument, cameras_from_args, seconds_to_ns
from ..evaluation.holdout import holdout, HOLDOUT_METHODS, three_camera_consistency
from ..formats.bagio import read_observations
from ..fusion import METHOD_ALIASES
from ..offsets import apply_time_offsets, camera_time_offsets

NAME = 'holdout'
#: A held-out error above this is a gross error [px] (the issue's threshold).
GROSS_PX = 20.0
HELP = ('run two cameras of a bag through each method and score the estimates by reprojection '
        'into a held-out third camera (median, p90, mean px)')


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the command's arguments."""
    parser.add_argument('bags', nargs='+', metavar='BAG',
                        help='bags with /<camera>/ball/image_point topics of all three cameras')
    add_camera_argument(parser)
    parser.add_argument('--inputs', nargs=2, default=['camera_1', 'camera_2'],
                        metavar=('CAMERA', 'CAMERA'), help='the two input cameras')
    parser.add_argument('--held-out', default='camera_3', metavar='CAMERA',
                        help='the camera that judges (default: camera_3)')
    parser.add_argument('--methods', nargs='+', default=list(HOLDOUT_METHODS),
                        choices=HOLDOUT_METHODS + tuple(METHOD_ALIASES),
                        help='methods to score (default: all; best: trajectory)')
    parser.add_argument('--sync-tolerance', type=float, default=None, metavar='S',
                        help="the fuser's sync tolerance [s] (default: the fuser's)")
    parser.add_argument('--three-cameras', action='store_true',
                        help='also run trajectory on all three cameras and compare it with the '
                             'two-camera run at the held-out stamps (consistency: with the '
                             'held-out camera as an input it cannot judge)')
    parser.add_argument('--max-gap', type=float, default=None, metavar='S',
                        help="the fuser's max gap [s], also the longest interpolation span "
                             "(default: the fuser's)")


def run(args: argparse.Namespace) -> int:
    """Print one table row per bag and method; return 0."""
    cameras = cameras_from_args(args.camera, minimum=3)
    names = list(args.inputs) + [args.held_out]
    missing = [name for name in names if name not in cameras]
    if missing:
        raise UsageError(f'no --camera for {", ".join(missing)}')
    sync_tolerance_ns = None if args.sync_tolerance is None else seconds_to_ns(
        args.sync_tolerance, '--sync-tolerance')
    max_gap_ns = None if args.max_gap is None else seconds_to_ns(args.max_gap, '--max-gap')
    rows, consistency = [], []
    for bag in args.bags:
        # Each camera's time_offset_s (calibration file) puts its stamps on the common clock.
        observations = apply_time_offsets(read_observations(bag, names),
                                          camera_time_offsets(cameras))
        results = holdout(cameras, observations, inputs=args.inputs,
                          held_out=args.held_out, methods=args.methods,
                          sync_tolerance_ns=sync_tolerance_ns, max_gap_ns=max_gap_ns)
        for method, result in results.items():
            rows.append((Path(bag).name, method, result.count, result.median_px, result.p90_px,
                         result.mean_px, int((result.errors > GROSS_PX).sum()),
                         result.available))
        if args.three_cameras:
            consistency.append((Path(bag).name, three_camera_consistency(
                cameras, observations, inputs=args.inputs, held_out=args.held_out,
                max_gap_ns=max_gap_ns)))
    width = max(len('bag'), *(len(row[0]) for row in rows))
    print(f'Held-out reprojection error in {args.held_out} [px], inputs '
          f'{args.inputs[0]} + {args.inputs[1]}; all methods on the same events '
          f'(gross: over {GROSS_PX:g} px; available: events this method alone can score)')
    print(f'{"bag":<{width}}  {"method":<10} {"events":>6} {"median":>7} {"p90":>7} '
          f'{"mean":>7} {"gross":>6} {"available":>9}')
    for bag, method, count, median, p90, mean, gross, available in rows:
        print(f'{bag:<{width}}  {method:<10} {count:>6d} {median:>7.2f} {p90:>7.2f} '
              f'{mean:>7.2f} {gross:>6d} {available:>9d}')
    if consistency:
        print(f'trajectory on {", ".join(names)} at the {args.held_out} stamps (not a held-out '
              f'score: {args.held_out} is an input): median reprojection into '
              f'{args.held_out} (self) and median distance to the two-camera estimate, in '
              f'{args.held_out} px')
        for bag, values in consistency:
            print(f'{bag:<{width}}  events {values["events"]:>5d}  self '
                  f'{values["self_px"]:5.2f} px  to two-camera {values["between_px"]:5.2f} px '
                  f'({values["compared"]} events both cover)')
    return 0
