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

"""``pseudo_stereo simulate``: calibration files, observations.csv and truth.csv of a run."""

from pathlib import Path

from . import UsageError
from .common import check_pixel_options, positive
from ..calibration import save_calibration
from ..evaluation.table1 import Run, simulate_run
from ..formats.csv_io import write_observations, write_truth
from ..sim.scenarios import default_rig, SCENARIOS

NAME = 'simulate'
HELP = 'simulate two unsynchronized cameras watching a ball; write CSV files for track'


def add_arguments(parser) -> None:
    """Add this command's options."""
    parser.add_argument('--scenario', required=True, choices=sorted(SCENARIOS))
    parser.add_argument('--fps', type=positive, default=30.0, help='frame rate of both cameras')
    parser.add_argument('--delta12', type=float, default=1.0 / 60.0, metavar='S',
                        help='delay from a camera-1 shutter to the next camera-2 shutter [s] '
                             '(default 1/60; 0 = synchronized)')
    parser.add_argument('--noise', type=float, default=0.0, metavar='PX',
                        help='Gaussian pixel noise [px]')
    parser.add_argument('--quantization', type=float, default=0.05, metavar='PX',
                        help='sub-pixel step of the detections [px] (default: %(default)s)')
    parser.add_argument('--dropout', type=float, default=0.0,
                        help='probability of a missed detection')
    parser.add_argument('--seed', type=int, default=0, help='random seed')
    parser.add_argument('--out', required=True, metavar='DIR', help='output directory')


def run(args) -> int:
    """Run the command."""
    check_pixel_options(args)
    if not 0 <= args.dropout < 1:
        raise UsageError(f'--dropout must be in [0, 1), got {args.dropout}')
    if not 0 <= args.delta12 < 1.0 / args.fps:
        raise UsageError(f'--delta12 must be in [0, 1/fps = {1.0 / args.fps:.6g}) s')
    cameras = default_rig()
    run_ = Run(args.scenario, fps=args.fps, delta12_s=args.delta12, noise_px=args.noise,
               quantization_px=args.quantization, dropout=args.dropout, seed=args.seed)
    data = simulate_run(run_, cameras)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for camera in cameras:
        save_calibration(camera.calibration, out / f'{camera.name}.yaml')
    write_observations(out / 'observations.csv', data.observations)
    write_truth(out / 'truth.csv', data.truth_stamps, data.truth_points)
    names = ' '.join(f'--camera {c.name}={out / (c.name + ".yaml")}' for c in cameras)
    print(f'wrote {len(data.observations)} observations and {len(data.truth_stamps)} truth rows '
          f'to {out}/\n'
          f'next: pseudo_stereo track {names} --input {out / "observations.csv"} '
          f'--output {out / "estimates.csv"} --truth {out / "truth.csv"}')
    return 0
