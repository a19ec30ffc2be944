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

"""``pseudo_stereo bench``: fuser throughput and accuracy per method, in one run."""

import time

from .common import positive
from ..evaluation.table1 import Run, score, simulate_run
from ..fusion import fuse, METHODS
from ..sim.scenarios import default_rig

NAME = 'bench'
HELP = 'events per second of the fuser on one core, and accuracy, for every method'

#: The targets [events/s] (a 30 fps pair needs 60): the paper method, and the trajectory fit.
TARGET_EVENTS_PER_S = 20_000
TARGET_TRAJECTORY_EVENTS_PER_S = 5_000


def add_arguments(parser) -> None:
    """Add this command's options."""
    parser.add_argument('--turns', type=positive, default=20.0,
                        help='turns of the spiral scenario to simulate (default: %(default)s)')
    parser.add_argument('--repeat', type=int, default=3,
                        help='timed repetitions; the fastest counts (default: %(default)s)')
    parser.add_argument('--noise', type=float, default=0.3, metavar='PX',
                        help='Gaussian pixel noise [px] (default: %(default)s)')


def run(args) -> int:
    """Run the command."""
    cameras = default_rig()
    run_ = Run('spiral', noise_px=args.noise, scenario_options={'turns': args.turns})
    data = simulate_run(run_, cameras)
    events = len(data.observations)
    print(f'fuser benchmark: spiral, {args.turns:g} turns, 2 cameras x 30 fps, '
          f'noise {args.noise} px: {events} events, best of {args.repeat}, one core')
    rates = {}
    for method in METHODS:
        best = float('inf')
        for _ in range(max(args.repeat, 1)):
            start = time.perf_counter()
            estimates, _ = fuse(cameras, data.observations, method=method)
            best = min(best, time.perf_counter() - start)
        rates[method] = events / best
        result = score(estimates, data.truth_stamps, data.truth_points)
        print(f'  {method:<10} {rates[method]:>10,.0f} events/s  '
              f'{best / events * 1e6:7.1f} us/event  {len(estimates):>6} estimates  '
              f'MAE {result.mae_mm:6.2f} mm  3D {result.distance_mm:6.2f} mm')
    baseline = rates['naive']
    print(f'paper / naive throughput ratio: {rates["paper"] / baseline:.2f} '
          f'(naive = one triangulation per event, the baseline measured in this run)')
    print(f'trajectory / paper throughput ratio: {rates["trajectory"] / rates["paper"]:.3f} '
          f'(measured in this run)')
    for method, target in (('paper', TARGET_EVENTS_PER_S),
                           ('trajectory', TARGET_TRAJECTORY_EVENTS_PER_S)):
        verdict = 'meets' if rates[method] >= target else 'MISSES'
        print(f'{method}: {rates[method]:,.0f} events/s {verdict} the target of '
              f'{target:,} events/s ({rates[method] / 60:,.0f}x a 30 fps pair)')
    return 0
