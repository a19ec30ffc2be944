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
``pseudo_stereo check``: epipolar consistency of a calibrated camera pair on observations.

Camera 2's observations are interpolated to camera 1's stamps (the cameras
need not be synchronized), and the distance of each pair to its epipolar
lines is reported in pixels.  With a good calibration it is at the level of
the detection noise; a median above :data:`BAD_MEDIAN_PX` means a wrong
calibration (or wrongly paired cameras) before any 3D is trusted.
"""

import numpy as np

from . import UsageError
from .common import add_camera_argument, cameras_from_args, seconds_to_ns
from ..calibrate import epipolar_check
from ..formats.csv_io import read_observations
from ..offsets import apply_time_offsets, camera_time_offsets

__all__ = ['BAD_MEDIAN_PX', 'GOOD_MEDIAN_PX', 'HELP', 'NAME', 'add_arguments', 'run',
           'verdict']

NAME = 'check'
HELP = ('epipolar consistency of two calibrated cameras on recorded observations '
        '(distance to the epipolar line in pixels)')

#: Median epipolar distances [px] up to GOOD are detector noise; above BAD the calibration is off.
GOOD_MEDIAN_PX = 1.0
BAD_MEDIAN_PX = 2.0


def add_arguments(parser) -> None:
    """Add this command's options."""
    add_camera_argument(parser)
    parser.add_argument('--input', required=True, metavar='OBS.csv',
                        help='observations, header stamp_ns,camera,u,v (as `track` reads)')
    parser.add_argument('--max-gap-s', type=float, default=0.1, metavar='S',
                        help='interpolate camera 2 only across gaps up to this [s] '
                             '(default 0.1)')


def verdict(median_px: float) -> str:
    """Return the verdict line for a median epipolar distance [px]."""
    if median_px <= GOOD_MEDIAN_PX:
        return f'verdict: OK, median {median_px:.2f} px <= {GOOD_MEDIAN_PX:g} px (noise level)'
    if median_px <= BAD_MEDIAN_PX:
        return (f'verdict: MARGINAL, median {median_px:.2f} px: check the calibration, the '
                'detector noise and fast motion across long gaps')
    return (f'verdict: BAD, median {median_px:.2f} px > {BAD_MEDIAN_PX:g} px: likely a bad '
            'calibration (or cameras paired wrongly); do not trust the 3D')


def run(args) -> int:
    """Run the command."""
    cameras = cameras_from_args(args.camera)
    if len(cameras) != 2:
        raise UsageError(f'--camera: check compares exactly two cameras, got {len(cameras)}')
    max_gap_ns = seconds_to_ns(args.max_gap_s, '--max-gap-s')
    # Each camera's time_offset_s (calibration file) puts its stamps on the common clock.
    observations = apply_time_offsets(read_observations(args.input), camera_time_offsets(cameras))
    (name_a, cam_a), (name_b, cam_b) = cameras.items()
    tracks = {}
    for name in (name_a, name_b):
        mine = [o for o in observations if o.camera == name]
        if not mine:
            raise UsageError(f'--input {args.input}: no observations of camera {name!r}')
        tracks[name] = (np.array([o.stamp_ns for o in mine], dtype=np.int64),
                        np.array([(o.u, o.v) for o in mine], dtype=float))
    others = len(observations) - sum(len(t[0]) for t in tracks.values())
    result = epipolar_check(cam_a, *tracks[name_a], cam_b, *tracks[name_b],
                            max_gap_ns=max_gap_ns)
    print(f'{name_a}: {len(tracks[name_a][0])} observations, {name_b}: '
          f'{len(tracks[name_b][0])}' + (f', {others} of other cameras ignored' if others else ''))
    if result.count == 0:
        raise UsageError(f'no {name_a} observation has {name_b} observations on both sides '
                         f'within --max-gap-s {args.max_gap_s:g}: nothing to compare')
    distances = result.distances_px
    print(f'epipolar distance ({name_b} interpolated to {name_a} stamps, {result.count} pairs, '
          f'{result.skipped} skipped): median {np.median(distances):.3f} px, '
          f'p90 {result.percentile(90):.3f} px, max {distances.max():.3f} px')
    print(verdict(float(np.median(distances))))
    return 0
