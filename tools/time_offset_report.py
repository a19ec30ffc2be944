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
Measure time-offset estimation and refinement (the README's figures; opt-in, minutes).

    .venv/bin/python tools/time_offset_report.py sync      # offset sweep, paper method, online
    .venv/bin/python tools/time_offset_report.py refine    # perturbed rig, synthetic
    .venv/bin/python tools/time_offset_report.py throws    # how many throws the 3D bar needs
    .venv/bin/python tools/time_offset_report.py focal     # --focal, camera2's focal +-2%
    .venv/bin/python tools/time_offset_report.py real      # the table-tennis bags

Synthetic recordings: the default rig, the scenarios spiral, bounce, straight
and turntable one after another with 0.5 s pauses (6.6 s), camera2's stamps
off by ``-offset`` (so ``time_offset_s = offset`` corrects them).
"""

import argparse
from dataclasses import replace
from pathlib import Path
import sys
import time

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from pseudo_stereo_ros.calibrate import epipolar_check  # noqa: E402
from pseudo_stereo_ros.calibrate.refine import refine_rig  # noqa: E402
from pseudo_stereo_ros.camera import Camera  # noqa: E402
from pseudo_stereo_ros.evaluation.holdout import holdout  # noqa: E402
from pseudo_stereo_ros.evaluation.time_offsets import (  # noqa: E402
    event_errors_mm, perturbed_calibration, random_throws, simulate_flights)
from pseudo_stereo_ros.fusion import fuse  # noqa: E402
from pseudo_stereo_ros.offsets import apply_time_offsets  # noqa: E402
from pseudo_stereo_ros.rig import Rig  # noqa: E402
from pseudo_stereo_ros.sim.scenarios import default_rig  # noqa: E402
from pseudo_stereo_ros.timesync import estimate_time_offsets, OnlineOffsetEstimator  # noqa: E402

SCENARIOS = ('spiral', 'bounce', 'straight', 'turntable')
LFG = REPO / 'test' / 'data' / 'lfg_table_tennis'
LFG_CAMERAS = {'camera_1': '22276213', 'camera_2': '22276209', 'camera_3': '22276216'}
SESSIONS = ('n1_n1', 'n3_p1_v14', 'p2_p2')


def sync_report(seeds: int) -> None:
    """Offset recovery, the paper method with and without offsets, online convergence."""
    cameras = default_rig()
    print('sync: camera2 offset recovered from 6.6 s of flights (4 scenarios), '
          f'{seeds} seeds per cell; error = estimate - truth')
    print(f'{"fps":>4} {"noise":>5} {"offsets [ms]":>22} {"max |error| [ms]":>17} '
          f'{"rms error":>10} {"median sigma":>13} {"|error| <= 2 sigma":>19} '
          f'{"<= 3 sigma":>11}')
    for fps in (30.0, 168.0):
        for noise in (0.0, 0.3):
            errors, sigmas = [], []
            for offset_ms in range(-15, 16, 3):
                for seed in range(seeds):
                    recording = simulate_flights(cameras, offsets_s={'camera2': offset_ms / 1e3},
                                                 fps=fps, noise_px=noise, seed=seed,
                                                 scenarios=SCENARIOS)
                    result = estimate_time_offsets(cameras, [recording.observations])
                    errors.append(result.offsets_s['camera2'] - offset_ms / 1e3)
                    sigmas.append(result.uncertainty_s['camera2'])
            errors, sigmas = np.abs(errors), np.array(sigmas)
            print(f'{fps:>4.0f} {noise:>5.1f} {"-15, -12, ..., +15":>22} '
                  f'{errors.max() * 1e3:>17.3f} {np.sqrt(np.mean(errors ** 2)) * 1e3:>10.3f} '
                  f'{np.median(sigmas) * 1e3:>13.3f} {np.mean(errors <= 2 * sigmas):>19.0%} '
                  f'{np.mean(errors <= 3 * sigmas):>11.0%}')

    print('\npaper method, mean 3D error [mm] at every event (scored at its true time), '
          '0.3 px noise')
    print(f'{"fps":>4} {"offset [ms]":>12} {"true offsets":>13} {"estimated":>10} '
          f'{"none":>8} {"estimated/true":>15} {"none/true":>10}')
    for fps in (30.0, 168.0):
        for offset_ms in (-15, -5, 5, 15):
            recording = simulate_flights(cameras, offsets_s={'camera2': offset_ms / 1e3},
                                         fps=fps, noise_px=0.3, seed=7, scenarios=SCENARIOS)
            estimate = estimate_time_offsets(cameras, [recording.observations]).offsets_s
            row = {}
            for label, offsets in (('true', recording.offsets_s), ('estimated', estimate),
                                   ('none', {})):
                estimates, _ = fuse(cameras, apply_time_offsets(recording.observations,
                                                                offsets))
                row[label] = float(np.mean(event_errors_mm(recording, estimates, offsets)))
            print(f'{fps:>4.0f} {offset_ms:>+12d} {row["true"]:>13.2f} {row["estimated"]:>10.2f} '
                  f'{row["none"]:>8.2f} {row["estimated"] / row["true"]:>15.3f} '
                  f'{row["none"] / row["true"]:>10.1f}')

    print('\nonline estimate (fuser node core: 10 s window, updated every second of stamps), '
          'camera2 offset +10 ms, 0.3 px noise')
    print(f'{"fps":>4} ' + ' '.join(f'{f"{t:g} s":>16}' for t in (1, 2, 3, 4, 6)))
    for fps in (30.0, 168.0):
        recording = simulate_flights(cameras, offsets_s={'camera2': 0.010}, fps=fps,
                                     noise_px=0.3, seed=3, scenarios=SCENARIOS)
        estimator = OnlineOffsetEstimator(cameras, {})
        start = recording.observations[0].stamp_ns
        marks, cells = [1.0, 2.0, 3.0, 4.0, 6.0], []
        for observation in recording.observations:
            while marks and observation.stamp_ns - start >= marks[0] * 1e9:
                marks.pop(0)
                estimate = estimator.update()
                cells.append('-' if estimate is None else
                             f'{(estimate.offsets_s["camera2"] - 0.010) * 1e3:+.2f}'
                             f'+-{estimate.uncertainty_s["camera2"] * 1e3:.2f}'
                             + ('' if estimator.usable('camera2') else '!'))
            estimator.add(observation)
        print(f'{fps:>4.0f} ' + ' '.join(f'{cell:>16}' for cell in cells))
    print('(error +- 1 sigma [ms] of the estimate after that much recording; '
          '! = not usable yet)')


def refine_report(seeds: int) -> None:
    """Refine a rig whose camera2 is perturbed by 1 degree and 2 cm."""
    cameras = default_rig()
    true = cameras[1].calibration
    baseline = float(np.linalg.norm(cameras[1].center - cameras[0].center))
    print('refine: camera2 rotated 1 deg (random axis) and moved 2 cm (random direction); '
          'flights: the 4 scenarios x repeats, 0.3 px noise, offsets estimated (true 0)')
    print(f'{"fps":>4} {"flights":>7} {"seed":>4} {"mode":<16} '
          f'{"epipolar [px] true / perturbed -> refined":>28} '
          f'{"3D error [mm] true / perturbed / refined":>42} {"rot err [deg]":>14} '
          f'{"sigma":>6} {"s":>6} {"refused":>8}')
    for fps, repeats in ((30.0, 1), (30.0, 4), (168.0, 1)):
        for seed in range(seeds):
            bad = Camera(perturbed_calibration(true, degrees=1.0, metres=0.02, seed=seed),
                         name='camera2')
            recording = simulate_flights(cameras, offsets_s={}, fps=fps, noise_px=0.3,
                                         seed=seed, scenarios=SCENARIOS * repeats)
            for mode, options in (('baseline given', {}),
                                  ('baseline known', {'baseline_m': baseline}),
                                  ('keep-world', {'keep_world': True})):
                start = time.perf_counter()
                result = refine_rig([cameras[0], bad], [recording.observations], **options)
                seconds = time.perf_counter() - start
                refined = [Camera(result.calibrations[c.name], name=c.name) for c in cameras]
                offsets = {name: c.time_offset_s for name, c in result.calibrations.items()}
                errors = []
                for rig, applied in ((cameras, {}), ([cameras[0], bad], {}),
                                     (refined, offsets)):
                    estimates, _ = fuse(rig, apply_time_offsets(recording.observations,
                                                                applied))
                    errors.append(np.mean(event_errors_mm(recording, estimates, applied)))
                epipolar = [_epipolar(rig[0], rig[1], recording.observations, applied)
                            for rig, applied in ((cameras, {}), ([cameras[0], bad], {}),
                                                 (refined, offsets))]
                rotation = result.calibrations['camera2'].rotation @ true.rotation.T
                angle = np.degrees(np.arccos(np.clip((np.trace(rotation) - 1) / 2, -1, 1)))
                print(f'{fps:>4.0f} {result.flights:>7d} {seed:>4d} {mode:<16} '
                      f'{epipolar[0]:>5.2f} / {epipolar[1]:>5.2f} -> {epipolar[2]:<5.2f} '
                      f'{errors[0]:>14.2f} / {errors[1]:>8.2f} / {errors[2]:>8.2f}    '
                      f'{angle:>14.3f} {result.cameras[1].sigma_rotation_deg:>6.3f} '
                      f'{seconds:>5.0f}s {"yes" if result.refusals else "no":>8}')


def _refine_case(cameras, bad, recording, **options):
    """Refine camera2 with the true baseline; return (result, 3D error ratio, rot err, s)."""
    baseline = float(np.linalg.norm(cameras[1].center - cameras[0].center))
    start = time.perf_counter()
    result = refine_rig([cameras[0], bad], [recording.observations], baseline_m=baseline,
                        **options)
    seconds = time.perf_counter() - start
    refined = [Camera(result.calibrations[c.name], name=c.name) for c in cameras]
    offsets = {name: c.time_offset_s for name, c in result.calibrations.items()}
    errors = []
    for rig, applied in ((cameras, recording.offsets_s), (refined, offsets)):
        estimates, _ = fuse(rig, apply_time_offsets(recording.observations, applied))
        errors.append(float(np.mean(event_errors_mm(recording, estimates, applied))))
    rotation = result.calibrations['camera2'].rotation @ cameras[1].R.T
    angle = float(np.degrees(np.arccos(np.clip((np.trace(rotation) - 1) / 2, -1, 1))))
    return result, errors[1] / errors[0], angle, seconds


FORCED = {'max_sigma_deg': np.inf, 'max_sigma_m': np.inf, 'max_sigma_s': np.inf,
          'max_sigma_focal': np.inf}


def throws_report(seeds: int) -> None:
    """How much flight the 3D bar (within 10% of the true calibration's) needs."""
    cameras = default_rig()
    print('refine with random throws across the view (random_throws: start and end in a box '
          'both cameras see, 0.6-1 s each, 0.5 s pauses); camera2 rotated 1 deg and moved 2 cm, '
          'offset +5 ms estimated, the true baseline given; forced (no refusal) to show the '
          f'error; {seeds} seeds per row')
    print(f'{"fps":>4} {"noise":>5} {"throws":>6} {"seconds":>7} '
          f'{"3D refined/true: median":>24} {"max":>6} {"<= 1.1":>7} '
          f'{"rot err [deg] median":>21} {"1 sigma median":>15} {"accepted":>9} {"s/run":>6}')
    for fps, noise, count in ((30.0, 0.3, 10), (30.0, 0.3, 20), (30.0, 0.1, 20),
                              (30.0, 0.3, 40), (30.0, 0.3, 80), (168.0, 0.3, 10),
                              (168.0, 0.3, 20), (168.0, 0.3, 40)):
        rows = []
        for seed in range(seeds):
            throws = random_throws(count, seed=100 + seed)
            bad = Camera(perturbed_calibration(cameras[1].calibration, degrees=1.0,
                                               metres=0.02, seed=seed), name='camera2')
            recording = simulate_flights(cameras, offsets_s={'camera2': 0.005}, fps=fps,
                                         noise_px=noise, seed=seed, scenarios=throws)
            result, ratio, angle, seconds = _refine_case(cameras, bad, recording, **FORCED)
            accepted = result.cameras[1].sigma_rotation_deg <= 0.1
            rows.append((ratio, angle, result.cameras[1].sigma_rotation_deg, accepted,
                         seconds, sum(t.duration_s for t in throws)))
        a = np.array(rows, dtype=float)
        print(f'{fps:>4.0f} {noise:>5.1f} {count:>6d} {np.mean(a[:, 5]):>7.0f} '
              f'{np.median(a[:, 0]):>24.3f} {a[:, 0].max():>6.3f} {np.mean(a[:, 0] <= 1.1):>7.0%} '
              f'{np.median(a[:, 1]):>21.3f} {np.median(a[:, 2]):>15.3f} '
              f'{np.mean(a[:, 3]):>9.0%} {np.mean(a[:, 4]):>6.1f}')


def focal_report() -> None:
    """--focal: camera2's focal length off by +-2% (and its pose 1 deg, 2 cm)."""
    cameras = default_rig()
    print('refine --focal: camera2 focal x1.02 / x0.98 and (second block) also rotated 1 deg and '
          "moved 2 cm; camera1's focal length held; true baseline; forced (no refusal)")
    print(f'{"fps":>4} {"noise":>5} {"throws":>6} {"pose":>5} {"focal":>6} '
          f'{"focal err [%]":>14} {"1 sigma [%]":>12} {"rot err [deg]":>14} '
          f'{"3D refined/true":>16} {"refused by default":>19}')
    for fps, noise, count in ((30.0, 0.0, 20), (30.0, 0.3, 20), (168.0, 0.3, 40)):
        for pose in (False, True):
            for seed, factor in enumerate((1.02, 0.98)):
                calibration = cameras[1].calibration
                if pose:
                    calibration = perturbed_calibration(calibration, degrees=1.0,
                                                        metres=0.02, seed=seed)
                matrix = calibration.camera_matrix.copy()
                matrix[0, 0] *= factor
                matrix[1, 1] *= factor
                bad = Camera(replace(calibration, camera_matrix=matrix), name='camera2')
                recording = simulate_flights(cameras, offsets_s={'camera2': -0.008}, fps=fps,
                                             noise_px=noise, seed=seed,
                                             scenarios=random_throws(count, seed=seed))
                result, ratio, angle, _ = _refine_case(cameras, bad, recording, focal=True,
                                                       **FORCED)
                default, _, _, _ = _refine_case(cameras, bad, recording, focal=True)
                error = (result.calibrations['camera2'].camera_matrix[0, 0]
                         / cameras[1].K[0, 0] - 1.0)
                refused = '; '.join(r.split(':')[0] + ':' + r.split(':')[1][:24]
                                    for r in default.refusals) or 'no'
                print(f'{fps:>4.0f} {noise:>5.1f} {count:>6d} {"yes" if pose else "no":>5} '
                      f'{factor:>6.2f} {error * 100:>+14.3f} '
                      f'{result.cameras[1].sigma_focal * 100:>12.3f} {angle:>14.3f} '
                      f'{ratio:>16.3f}  {refused}')


def _epipolar(camera_a, camera_b, observations, offsets) -> float:
    shifted = apply_time_offsets(observations, offsets)
    tracks = {}
    for camera in (camera_a, camera_b):
        mine = sorted((o for o in shifted if o.camera == camera.name), key=lambda o: o.stamp_ns)
        tracks[camera.name] = (np.array([o.stamp_ns for o in mine]),
                               np.array([(o.u, o.v) for o in mine]))
    result = epipolar_check(camera_a, *tracks[camera_a.name], camera_b, *tracks[camera_b.name],
                            max_gap_ns=100_000_000)
    return float(np.median(result.distances_px))


def _kind(warning: str) -> str:
    """Return a warning's kind (too short, unobservable, varies, confounded, no data)."""
    return next((kind for kind in ('too short', 'unobservable', 'varies', 'confounded',
                                   'no data') if kind in warning), warning.split(':')[0])


def real_report() -> None:
    """Sync per session, and refine on cameras 1 + 2 judged by the held-out camera_3."""
    from pseudo_stereo_ros.formats.bagio import read_observations
    rig = Rig.from_files([(name, LFG / f'{serial}_calibration.yaml')
                          for name, serial in LFG_CAMERAS.items()])
    sessions = {s: read_observations(LFG / s, list(LFG_CAMERAS)) for s in SESSIONS}
    print('sync per session (offsets relative to camera_1; pairs and the combined estimate)')
    for session, observations in sessions.items():
        result = estimate_time_offsets(rig, [observations], search_s=0.02)
        pairs = ', '.join(f'{p.camera_a[-1]}->{p.camera_b[-1]} {p.offset_s * 1e3:+.2f}'
                          f'+-{p.uncertainty_s * 1e3:.2f}' for p in result.pairs)
        combined = ', '.join(f'{n} {result.offsets_s[n] * 1e3:+.2f}'
                             f'+-{result.uncertainty_s[n] * 1e3:.2f}' for n in list(rig)[1:])
        flags = sorted({_kind(w) for ws in result.warnings.values() for w in ws})
        print(f'  {session:<10} pairs [ms]: {pairs}; combined: {combined}; closure p = '
              f'{result.closure_p:.1e}; warnings: {", ".join(flags) or "none"}')

    print('\nthe pair alone (cameras 1 + 2, as a two-camera rig would see it), its offset '
          'applied, judged by camera_3: check median, held-out paper / oracle median [px]')
    for session, observations in sessions.items():
        pair = estimate_time_offsets([rig['camera_1'], rig['camera_2']], [observations],
                                     search_s=0.02)
        offset = pair.offsets_s['camera_2']
        cells = []
        for label, offsets in (('given', {}), (f'camera_2 {offset * 1e3:+.2f} ms', {
                'camera_2': offset})):
            shifted = apply_time_offsets(observations, offsets)
            result = holdout(dict(rig), shifted, methods=('paper', 'oracle'))
            check = _epipolar(rig['camera_1'], rig['camera_2'], shifted, {})
            cells.append(f'{label}: {check:.2f} {result["paper"].median_px:.2f} / '
                         f'{result["oracle"].median_px:.2f}')
        flags = sorted({_kind(w) for w in pair.warnings['camera_2']})
        print(f'  {session:<10} ' + ' | '.join(cells)
              + f'; warnings: {", ".join(flags) or "none"}')

    def evaluate(cameras: dict, offsets: dict, label: str) -> None:
        cells = []
        for session, observations in sessions.items():
            shifted = apply_time_offsets(observations, offsets)
            epipolar = _epipolar(cameras['camera_1'], cameras['camera_2'], shifted, {})
            result = holdout(cameras, shifted, methods=('paper', 'oracle'))
            cells.append(f'{session} {epipolar:5.2f} {result["paper"].median_px:5.2f} '
                         f'{result["oracle"].median_px:5.2f}')
        print(f'  {label:<44} ' + ' | '.join(cells))

    print('\nrefine on camera_1 + camera_2 (all three sessions), judged by camera_3 '
          '(untouched); per session: check median [px], held-out paper / oracle median [px]')
    evaluate(dict(rig), {}, 'given calibration')
    forced = {'max_sigma_deg': np.inf, 'max_sigma_m': np.inf, 'max_sigma_s': np.inf,
              'max_sigma_focal': np.inf}
    for label, options in (('offsets + extrinsics', {}),
                           ('extrinsics, offsets fixed', {'estimate_offsets': False}),
                           ('offsets + extrinsics, keep-world', {'keep_world': True}),
                           ('extrinsics, keep-world, offsets fixed',
                            {'keep_world': True, 'estimate_offsets': False})):
        start = time.perf_counter()
        result = refine_rig([rig['camera_1'], rig['camera_2']], list(sessions.values()),
                            **options)
        verdict = 'REFUSED: ' + '; '.join(result.refusals) if result.refusals else 'accepted'
        if result.refusals:  # what it would have written: the same fit without the bounds
            result = refine_rig([rig['camera_1'], rig['camera_2']], list(sessions.values()),
                                **options, **forced)
        cameras = dict(rig)
        for name in ('camera_1', 'camera_2'):
            cameras[name] = Camera(result.calibrations[name], name=name)
        offsets = {name: c.time_offset_s for name, c in result.calibrations.items()}
        camera = result.cameras[1]
        print(f'  {label}: {time.perf_counter() - start:.0f} s; camera_2 rotation '
              f'{camera.rotation_deg:.2f}+-{camera.sigma_rotation_deg:.2f} deg, centre '
              f'{camera.centre_m * 100:.1f}+-{camera.sigma_centre_m * 100:.1f} cm, offset '
              f'{camera.offset_s * 1e3:+.2f}+-{camera.sigma_offset_s * 1e3:.2f} ms, '
              f'correlation {camera.offset_correlation:.2f}; reprojection '
              f'{camera.reprojection_before_px:.2f} -> {camera.reprojection_after_px:.2f} px; '
              f'{verdict}')
        evaluate(cameras, offsets, f'  -> {label}' + (' (forced)' if 'REFUSED' in verdict
                                                      else ''))


def main() -> int:
    """Run the chosen report."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('report', choices=('sync', 'refine', 'throws', 'focal', 'real'))
    parser.add_argument('--seeds', type=int, default=3)
    args = parser.parse_args()
    {'sync': lambda: sync_report(args.seeds), 'refine': lambda: refine_report(args.seeds),
     'throws': lambda: throws_report(args.seeds), 'focal': focal_report,
     'real': real_report}[args.report]()
    return 0


if __name__ == '__main__':
    sys.exit(main())
