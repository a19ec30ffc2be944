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
``pseudo_stereo refine``: refine extrinsics (and focal lengths) and time offsets from flights.

Bundle adjustment over recorded ball flights (see
:mod:`pseudo_stereo_ros.calibrate.refine`).  Prints the epipolar consistency of
every pair and each camera's reprojection error before and after, what changed
with its 1-sigma uncertainty, and writes the refined calibration files (with
``time_offset_s``) into ``--out-dir`` under the input files' names, never over
an input.  When the flights do not determine the result it writes nothing and
exits with status 2.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
import sys

from . import UsageError
from .common import (add_camera_argument, add_recording_arguments, camera_files,
                     cameras_from_args, read_recordings)
from ..calibrate.refine import (DEFAULT_MAX_SIGMA_DEG, DEFAULT_MAX_SIGMA_FOCAL,
                                DEFAULT_MAX_SIGMA_M, DEFAULT_MAX_SIGMA_S, DEFAULT_MIN_FLIGHTS,
                                DEFAULT_PRIOR_DEG, DEFAULT_PRIOR_M, epipolar_consistency,
                                refine_rig)
from ..calibration import save_calibration
from ..camera import Camera
from ..errors import CalibrationFitError
from ..offsets import camera_time_offsets

__all__ = ['HELP', 'NAME', 'add_arguments', 'run']

NAME = 'refine'
HELP = ("refine the cameras' extrinsics (optionally focal lengths) and time offsets by bundle "
        'adjustment over recorded ball flights; writes new calibration files')


def add_arguments(parser) -> None:
    """Add this command's options."""
    add_camera_argument(parser)
    add_recording_arguments(parser)
    parser.add_argument('--out-dir', required=True, metavar='DIR',
                        help='directory for the refined calibration files (same file names as '
                             'the inputs; never an input)')
    parser.add_argument('--focal', action='store_true',
                        help='also refine the focal lengths (fx and fy by one factor) of every '
                             "camera but the first, relative to the first camera's (held)")
    parser.add_argument('--fixed-offsets', action='store_true',
                        help='keep the time offsets of the calibration files')
    parser.add_argument('--keep-world', action='store_true',
                        help='free every camera pose but hold it near the given one by a prior, '
                             "so the world frame does not move (default: the first camera's "
                             "pose is fixed and the scale by the first two cameras' baseline)")
    parser.add_argument('--prior-deg', type=float, default=DEFAULT_PRIOR_DEG, metavar='DEG',
                        help='--keep-world: 1-sigma prior on each rotation (default: '
                             '%(default)s)')
    parser.add_argument('--prior-m', type=float, default=DEFAULT_PRIOR_M, metavar='M',
                        help='--keep-world: 1-sigma prior on each optical centre (default: '
                             '%(default)s)')
    parser.add_argument('--baseline', type=float, default=None, metavar='M',
                        help="the measured distance between the first two cameras' optical "
                             "centres, which sets the scale (default: the given calibrations')")
    parser.add_argument('--max-gap-s', type=float, default=0.1, metavar='S',
                        help='a gap over this ends a flight [s] (default: %(default)s)')
    parser.add_argument('--min-flights', type=int, default=DEFAULT_MIN_FLIGHTS, metavar='N',
                        help='refuse with fewer flights (default: %(default)s)')
    parser.add_argument('--max-sigma-deg', type=float, default=DEFAULT_MAX_SIGMA_DEG,
                        metavar='DEG', help='refuse a rotation less certain than this '
                                            '(1 sigma, default: %(default)s)')
    parser.add_argument('--max-sigma-m', type=float, default=DEFAULT_MAX_SIGMA_M, metavar='M',
                        help='refuse an optical centre less certain than this (default: '
                             '%(default)s)')
    parser.add_argument('--max-sigma-s', type=float, default=DEFAULT_MAX_SIGMA_S, metavar='S',
                        help='refuse a time offset less certain than this (default: '
                             '%(default)s)')
    parser.add_argument('--max-sigma-focal', type=float, default=DEFAULT_MAX_SIGMA_FOCAL,
                        metavar='R', help='refuse a relative focal length less certain than '
                                          'this (default: %(default)s)')


def _positive(value: float, option: str) -> None:
    if not (math.isfinite(value) and value > 0):
        raise UsageError(f'{option}: expected a positive number, got {value}')


def _outputs(args, cameras) -> dict:
    """Return camera name -> output path, refusing to overwrite an input or clash."""
    out_dir = Path(args.out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise UsageError(f'--out-dir {out_dir}: exists and is not a directory')
    inputs = {name: Path(path) for name, path in camera_files(args.camera).items()}
    outputs: dict[str, Path] = {}
    for name in cameras:
        target = out_dir / inputs[name].name
        if target in outputs.values():
            raise UsageError(f"--out-dir {out_dir}: two cameras' files are both named "
                             f'{inputs[name].name}; copy one under another name first')
        for source in inputs.values():
            if target.exists() and os.path.samefile(target, source) \
                    or target.resolve() == source.resolve():
                raise UsageError(f'--out-dir {out_dir}: would overwrite the input {source}; '
                                 'choose another directory')
        outputs[name] = target
    return outputs


def run(args) -> int:
    """Run the command."""
    for option in ('prior_deg', 'prior_m', 'max_gap_s', 'max_sigma_deg', 'max_sigma_m',
                   'max_sigma_s', 'max_sigma_focal'):
        _positive(getattr(args, option), '--' + option.replace('_', '-'))
    if args.baseline is not None:
        _positive(args.baseline, '--baseline')
    if args.min_flights < 1:
        raise UsageError(f'--min-flights: expected at least 1, got {args.min_flights}')
    cameras = cameras_from_args(args.camera)
    outputs = _outputs(args, cameras)
    recordings = read_recordings(args, cameras)
    given = camera_time_offsets(cameras)
    result = refine_rig(cameras, recordings, estimate_offsets=not args.fixed_offsets,
                        focal=args.focal, keep_world=args.keep_world, baseline_m=args.baseline,
                        prior_deg=args.prior_deg, prior_m=args.prior_m,
                        max_gap_s=args.max_gap_s, min_flights=args.min_flights,
                        max_sigma_deg=args.max_sigma_deg, max_sigma_m=args.max_sigma_m,
                        max_sigma_s=args.max_sigma_s, max_sigma_focal=args.max_sigma_focal)
    refined = [Camera(result.calibrations[name], name=name) for name in cameras]
    before = epipolar_consistency(list(cameras.values()), recordings, given,
                                  max_gap_s=args.max_gap_s)
    after = epipolar_consistency(refined, recordings,
                                 {name: result.calibrations[name].time_offset_s
                                  for name in cameras}, max_gap_s=args.max_gap_s)
    _print(result, before, after, args)
    if result.refusals:
        raise CalibrationFitError('not written: ' + '; '.join(result.refusals))
    Path(args.out_dir).mkdir(parents=True, exist_ok=True)
    for name, path in outputs.items():
        save_calibration(result.calibrations[name], path)
    print('wrote ' + ', '.join(str(path) for path in outputs.values()))
    return 0


def _print(result, before, after, args) -> None:
    gauge = ('world kept by priors' if args.keep_world
             else 'first camera fixed, scale by the baseline of the first two')
    print(f'refine: {result.flights} flights, {result.points} ball positions; {gauge}; '
          f'detection noise {result.sigma_px:.3f} px')
    print('epipolar consistency, median [px] (before -> after):')
    for (a, b), (median, count) in before.items():
        print(f'  {a} / {b}: {median:.2f} -> {after[(a, b)][0]:.2f}  ({count} detections)')
    print(f'{"camera":<12} {"reprojection median [px]":>26}  {"rotation [deg]":>16} '
          f'{"centre [cm]":>14} {"focal [%]":>14} {"offset [ms]":>20}')
    for camera in result.cameras:
        focal = (f'{camera.focal * 100:+.2f}+-{camera.sigma_focal * 100:.2f}'
                 if args.focal else '-')
        offset = (f'{camera.offset_s * 1e3:+.3f}+-{camera.sigma_offset_s * 1e3:.3f}'
                  if camera.sigma_offset_s else f'{camera.offset_s * 1e3:+.3f} (kept)')
        print(f'{camera.name:<12} {camera.reprojection_before_px:>12.3f} -> '
              f'{camera.reprojection_after_px:<10.3f}  '
              f'{camera.rotation_deg:>7.3f}+-{camera.sigma_rotation_deg:<6.3f} '
              f'{camera.centre_m * 100:>6.2f}+-{camera.sigma_centre_m * 100:<5.2f} '
              f'{focal:>14} {offset:>20}')
    print("the refined calibration's uncertainty moves the ball positions by "
          f'{result.sigma_position_m * 1e3:.1f} mm rms (1 sigma): the 3D error it adds; more '
          'throws, spread over the view, make it smaller')
    for note in result.notes:
        print(f'note: {note}', file=sys.stderr)
