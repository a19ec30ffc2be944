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
``pseudo_stereo sweep``: ``trajectory`` against ``paper`` on varied simulated cases.

Prints one row per case (see :mod:`pseudo_stereo_ros.evaluation.sweep`) and
the summary the issue's bars are about, then the error at the shutter events
right after each impact of the bouncing ball, and writes that as a plot
(``impact_errors.png``) into ``--out``.
"""

from pathlib import Path

import numpy as np

from ..evaluation.messy import (LARGE_ERROR_M, messy_cases, PERTURBATIONS, run_messy,
                                summarize_messy)
from ..evaluation.sweep import (full_cases, impact_errors, impact_times, run_case, run_strays,
                                small_cases, stray_runs, summarize)
from ..evaluation.table1 import Run, simulate_run
from ..fusion import fuse
from ..sim.scenarios import default_rig

NAME = 'sweep'
HELP = ('trajectory against paper on varied simulated rigs, rates, offsets, noise, jitter and '
        'drops; the error right after impacts (plot)')

#: Shutter events counted after each impact.
IMPACT_EVENTS = 4


def add_arguments(parser) -> None:
    """Add this command's options."""
    parser.add_argument('--full', action='store_true',
                        help='all 144 combinations (about 10 s) instead of the 12 of the '
                             'test suite')
    parser.add_argument('--offsets', type=float, nargs=2, default=(0.5, 0.3),
                        metavar='FRACTION',
                        help="with --full (ignored otherwise): camera 2's two delays as "
                             'fractions of a period '
                             '(default: %(default)s, the tuned cases; the unseen ones: 0.4 0.2)')
    parser.add_argument('--seed-offset', type=int, default=0, metavar='N',
                        help="with --full: added to every case's seed (the unseen cases: 1000)")
    parser.add_argument('--strays', action='store_true',
                        help='instead: 2 %% stray detections (5-60 px) on the bouncing ball '
                             'and the spiral, 30 and 60 fps, seeds 1-30, camera 2 half a period '
                             'after camera 1 and synchronized (2 x 120 flights)')
    parser.add_argument('--messy', action='store_true',
                        help='instead: messy input on near-synchronized cameras (offsets '
                             '0-0.1 of a period): 240 cases, each clean and under each '
                             'perturbation (wrong blobs, bursts, duplicates, NaN, stamps '
                             'shifted back, a silent camera, streamed arrival; about 90 s)')
    parser.add_argument('--out', default='out/sweep', metavar='DIR',
                        help='directory for impact_errors.png (default: %(default)s)')


def run(args) -> int:
    """Run the command."""
    if args.strays:
        return _strays()
    if args.messy:
        return _messy()
    cases = full_cases(offsets=args.offsets, seed_offset=args.seed_offset) if args.full \
        else small_cases()
    print(f'{len(cases)} cases; MAE = per-coordinate mean absolute error [mm]; ratio = '
          'trajectory / paper; coverage = share of shutter events with an estimate')
    print(f'{"case":<62}{"paper":>8}{"traj":>8}{"ratio":>7}{"cover":>7}{"max [mm]":>10}')
    results = []
    for case in cases:
        result = run_case(case)
        results.append(result)
        print(f'{case.label():<62}{result.paper_mae_mm:>8.3f}{result.mae_mm:>8.3f}'
              f'{result.ratio:>7.2f}{result.coverage:>7.3f}{result.max_error_m * 1e3:>10.1f}')
    summary = summarize(results)
    print(f'geometric mean ratio {summary["geometric_mean_ratio"]:.3f} (bar <= 0.4), worst '
          f'{summary["worst_ratio"]:.3f} (bar < 0.95), lowest coverage '
          f'{summary["lowest_coverage"]:.3f} (bar >= 0.9), largest error '
          f'{summary["largest_error_m"] * 1e3:.1f} mm (bar < 500)')
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    curves = _impacts()
    _plot(curves, out / 'impact_errors.png')
    print(f'wrote {out / "impact_errors.png"}')
    return 0


def _strays() -> int:
    """Print the stray-detection runs and their summary."""
    print('2 % stray detections (5-60 px), 0.3 px noise; MAE [mm] with the strays (clean: '
          'without them); ratio = trajectory / paper, both with them')
    summaries = []
    for offset in (0.5, 0.0):
        results = []
        for scenario, fps, seed in stray_runs():
            result = run_strays(scenario, fps, seed, offset=offset)
            results.append(result)
            stats = result.stats
            print(f'off {offset:.1f} {scenario:<7}{fps:>3.0f} fps seed {seed:>2}  traj '
                  f'{result.mae_mm:7.2f}  clean {result.clean_mae_mm:6.2f}  paper '
                  f'{result.paper_mae_mm:6.2f}  ratio {result.ratio:5.2f}  max '
                  f'{result.max_error_m * 1e3:7.1f} mm  strays {result.strays} outlier '
                  f'{stats["outlier"]} breaks {stats["breaks"]} restarts {stats["restarts"]}')
        ratios = np.array([r.ratio for r in results])
        errors = np.array([r.max_error_m for r in results])
        summaries.append(
            f'offset {offset:.1f}: {len(results)} flights: geometric mean ratio '
            f'{np.exp(np.mean(np.log(ratios))):.3f}, {np.count_nonzero(ratios >= 0.95)} at or '
            f'over 0.95, {np.count_nonzero(errors > 0.1)} with an error over 100 mm, largest '
            f'{errors.max() * 1e3:.1f} mm')
    print('\n'.join(summaries))
    return 0


def _messy() -> int:
    """Print the messy-input table: per perturbation, both methods."""
    cases = messy_cases()
    print(f'{len(cases)} cases (every rig, 30 and 60 fps, offsets 0-0.1 of a period, rounding '
          'or 0.3 px noise, jitter and drops, three motions) under each perturbation:')
    for name, text in PERTURBATIONS.items():
        print(f'  {name:<12}{text}')
    results = [run_messy(case, perturbation) for perturbation in PERTURBATIONS
               for case in cases]
    over = f'> {LARGE_ERROR_M:g} m'
    print(f'{"perturbation":<13}{"runs":>5}{over:>9}{"largest [m]":>13}{"MAE [mm]":>10}'
          f'{"cover":>7}  |  paper:{over:>8}{"largest [m]":>13}{"MAE [mm]":>10}{"cover":>7}  |'
          f'{"traj > paper":>13}{"non-finite":>11}{"unbalanced":>11}')
    for name, row in summarize_messy(results).items():
        print(f'{name:<13}{row["runs"]:>5}{row["over"]:>9}{row["largest_m"]:>13.2f}'
              f'{row["mae_mm"]:>10.2f}{row["coverage"]:>7.3f}  |  {"":<6}{row["paper_over"]:>8}'
              f'{row["paper_largest_m"]:>13.2f}{row["paper_mae_mm"]:>10.2f}'
              f'{row["paper_coverage"]:>7.3f}  |'
              f'{row["worse"]:>13}{row["non_finite"]:>11}{row["unbalanced"]:>11}')
    print('MAE: per-coordinate, mean over the runs; cover: estimates per shutter event of the '
          "unperturbed case, mean over the runs; traj > paper: runs where trajectory's MAE "
          'is the larger; non-finite: estimates of either method (must be 0); unbalanced: '
          'runs whose counts do not add up (must be 0)')
    return 0


def _impacts() -> dict:
    """Print and return the errors [mm] after each impact of the bouncing ball, per run."""
    cameras = default_rig()
    impacts = impact_times()
    print(f'3D error [mm] at the {IMPACT_EVENTS} shutter events after each of the '
          f'{len(impacts)} impacts (bounce scenario, default rig), mean over events and '
          'impacts:')
    curves = {}
    for fps in (30.0, 60.0):
        for noise in (0.0, 0.3):
            data = simulate_run(Run('bounce', fps=fps, delta12_s=0.5 / fps, noise_px=noise),
                                cameras)
            row = {}
            for method in ('paper', 'trajectory'):
                estimates, _ = fuse(cameras, data.observations, method=method)
                row[method] = impact_errors(estimates, data.truth_stamps, data.truth_points,
                                            impacts, events=IMPACT_EVENTS,
                                            observations=data.observations) * 1e3
            label = f'{fps:.0f} fps, ' + (f'noise {noise} px' if noise else 'round 0.05 px')
            curves[label] = row
            print(f'  {label:<22} paper {np.nanmean(row["paper"]):6.1f}   trajectory '
                  f'{np.nanmean(row["trajectory"]):6.1f}   per event paper '
                  f'{np.round(np.nanmean(row["paper"], axis=0), 1).tolist()} trajectory '
                  f'{np.round(np.nanmean(row["trajectory"], axis=0), 1).tolist()}')
    return curves


def _plot(curves: dict, path: Path) -> None:
    """Write the errors after impacts: one panel per run, both methods."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(1, len(curves), figsize=(4 * len(curves), 3.5), sharey=True)
    events = np.arange(1, IMPACT_EVENTS + 1)
    for axis, (label, row) in zip(np.atleast_1d(axes), curves.items()):
        for method, style in (('paper', 'r-o'), ('trajectory', 'b-s')):
            errors = row[method]
            for impact in errors:
                axis.plot(events, impact, style, alpha=0.35, ms=3)
            axis.plot(events, np.nanmean(errors, axis=0), style, lw=2,
                      label=f'{method} (mean {np.nanmean(errors):.1f} mm)')
        axis.set_title(label)
        axis.set_xlabel('shutter event after the impact')
        axis.set_xticks(events)
        axis.legend(fontsize=8)
    np.atleast_1d(axes)[0].set_ylabel('3D error [mm]')
    figure.tight_layout()
    figure.savefig(path, dpi=100)
    plt.close(figure)
