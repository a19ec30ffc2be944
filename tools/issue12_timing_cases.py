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
Reproduce the fuser timing faults of issue 12, section 1, and print one line per case.

Run from the repository root (``.venv/bin/python tools/issue12_timing_cases.py``).
Every case streams observations through :meth:`Fuser.update` one by one, as the
fuser node does, with the fuser's default options unless the case says
otherwise, so the script runs against any version of the fuser and prints
numbers to compare before and after a change.  Simulated cameras are the
default rig (``config/rig``, 640 x 480 px) watching the turntable scenario
(a ball circling at 2.4 m/s).
"""

import math

import numpy as np
from pseudo_stereo_ros.fusion import Fuser
from pseudo_stereo_ros.records import Observation
from pseudo_stereo_ros.sim.scenarios import (DEFAULT_EPOCH_NS, default_rig, make_scenario,
                                             observe, shutter_stamps, truth_at)

FPS = 30.0


def _errors(estimates, scenario):
    """Return the 3D errors [m] of estimates against the scenario's truth."""
    if not estimates:
        return np.zeros(0)
    stamps = np.array([e.stamp_ns for e in estimates], dtype=np.int64)
    points = np.array([(e.x, e.y, e.z) for e in estimates])
    return np.linalg.norm(points - truth_at(scenario, stamps), axis=1)


def _stream(fuser, observations):
    """Feed observations one by one; return the estimates (None results left out)."""
    estimates = []
    for observation in observations:
        estimate = fuser.update(observation)
        if estimate is not None:
            estimates.append(estimate)
    return estimates


def _recording(duration_s, phase_s, *, noise_px=0.3, jitter_ns=0, seed=0):
    """Return (cameras, scenario, observations) of two 30 fps cameras, camera2 phase_s later."""
    cameras = default_rig()
    scenario = make_scenario('turntable', duration=duration_s)
    rng = np.random.default_rng(seed)
    stamps = []
    for phase in (0.0, phase_s):
        clean = shutter_stamps(FPS, duration_s)
        # Phases below the rounding of shutter_stamps: added to the integer stamps directly.
        shifted = clean + int(round(phase * 1e9))
        if jitter_ns:
            shifted = shifted + rng.integers(-jitter_ns, jitter_ns + 1, len(shifted))
        stamps.append(shifted)
    observations = observe(scenario, cameras, stamps, noise_px=noise_px, seed=seed)
    return cameras, scenario, observations


def _double_frame(observations, index, delay_ns):
    """Return observations with camera1's frame at ``index`` delivered again delay_ns later."""
    ones = [k for k, o in enumerate(observations) if o.camera == 'camera1']
    k = ones[index]
    copy = observations[k]._replace(stamp_ns=observations[k].stamp_ns + delay_ns)
    return observations[:k + 1] + [copy] + observations[k + 1:]


def case_double_frame_near_simultaneous():
    """One 3 ns double frame, cameras 1 us - 1 ms apart, 0.3 px noise."""
    worst, count, over = 0.0, 0, 0
    for seed, phase in enumerate((1e-6, 1e-5, 1e-4, 5e-4, 1e-3)):
        cameras, scenario, observations = _recording(10.0, phase, seed=seed)
        estimates = _stream(Fuser(cameras), _double_frame(observations, 5, 3))
        errors = _errors(estimates, scenario)
        worst = max(worst, float(errors.max()))
        count += len(errors)
        over += int(np.sum(errors > 0.1))
    print(f'A  3 ns double frame, phase 1 us-1 ms: worst error {worst:.3g} m, '
          f'{over} of {count} estimates over 10 cm')


def case_double_frame_synchronized():
    """Fuse synchronized 30 fps cameras (+-5 us jitter) with and without a 20 us double frame."""
    cameras, scenario, observations = _recording(60.0, 0.0, jitter_ns=5_000, seed=11)
    for label, stream in (('without', observations),
                          ('with 20 us double frame', _double_frame(observations, 40, 20_000))):
        errors = _errors(_stream(Fuser(cameras), stream), scenario)
        print(f'B  synchronized +-5 us jitter, {label}: {int(np.sum(errors > 0.1))} of '
              f'{len(errors)} estimates over 10 cm, worst {errors.max():.3g} m')


def case_zero_tolerance():
    """Fuse the same kind of streams with sync_tolerance_ns=0."""
    total, over, worst = 0, 0, 0.0
    for seed, phase in enumerate((0.0, 1e-6, 1e-5, 1e-4, 5e-4, 1e-3)):
        cameras, scenario, observations = _recording(60.0, phase, jitter_ns=5_000, seed=seed)
        errors = _errors(_stream(Fuser(cameras, sync_tolerance_ns=0), observations), scenario)
        total += len(errors)
        over += int(np.sum(errors > 100.0))
        worst = max(worst, float(errors.max()))
    print(f'C  sync_tolerance 0, phases 0-1 ms, +-5 us jitter: {over} of {total} estimates '
          f'over 100 m, worst {worst:.3g} m')


def case_bad_stamps():
    """One bad stamp of camera1 in a clean stream; zero stamps every 0.1 s."""
    cameras, scenario, observations = _recording(10.0, 1 / 60, noise_px=0.0)
    clean = {e.stamp_ns for e in _stream(Fuser(cameras), observations)}
    at = 150
    for label, stamp in (('stamp 0', 0), ('negative stamp', -1),
                         ('stamp 1e6 s ahead', observations[at].stamp_ns + 10**15)):
        bad = observations[at]._replace(camera='camera1', stamp_ns=stamp)
        stream = observations[:at] + [bad] + observations[at:]
        got = {e.stamp_ns for e in _stream(Fuser(cameras), stream)}
        following = [o.stamp_ns for o in observations[at:at + 30] if o.stamp_ns in clean]
        lost = sum(1 for s in following if s not in got)
        print(f'D  one {label} from camera1: {lost} of the next {len(following)} estimates '
              f'lost')
    stream, next_zero = [], DEFAULT_EPOCH_NS
    for observation in observations:
        if observation.stamp_ns >= next_zero:
            stream.append(Observation('camera1', 0, observation.u, observation.v))
            next_zero += 100_000_000
        stream.append(observation)
    got = _stream(Fuser(cameras), stream)
    print(f'D  a zero-stamp message every 0.1 s from camera1: {len(got)} estimates '
          f'(clean stream: {len(clean)})')


def case_garbage_pixels():
    """Pixels far outside the image: (-1e6, 1e6) and a garbage fuzz."""
    cameras, scenario, observations = _recording(10.0, 1 / 60, noise_px=0.0)
    stream = list(observations)
    for k in range(100, len(stream), 97):
        stream[k] = stream[k]._replace(u=-1e6, v=1e6)
    estimates = _stream(Fuser(cameras), stream)
    errors = _errors(estimates, scenario)
    print(f'E  (-1e6, 1e6) px every 97th observation: {int(np.sum(errors > 1.0))} of '
          f'{len(errors)} estimates over 1 m off, worst {errors.max():.3g} m')
    box = {'workspace_min_m': (-1.0, -1.0, -1.0), 'workspace_max_m': (4.0, 3.0, 3.0)}
    for label, options in (('', {}), (', with a workspace box', box)):
        try:
            fuser = Fuser(cameras, **options)
        except TypeError:  # a fuser without the option
            print(f'E  52,000 garbage pixels{label}: no such option')
            continue
        rng = np.random.default_rng(5)
        far, outputs = 0, 0
        stamp = DEFAULT_EPOCH_NS
        for _ in range(52_000):
            stamp += int(rng.integers(1_000_000, 20_000_000))
            scale = 10.0 ** rng.integers(2, 7)
            u, v = (float(x) for x in rng.uniform(-scale, scale, 2))
            estimate = fuser.update(Observation(str(rng.choice(['camera1', 'camera2'])),
                                                stamp, u, v))
            if estimate is not None:
                outputs += 1
                far += math.dist((estimate.x, estimate.y, estimate.z), (1.5, 1.0, 1.0)) > 100.0
        print(f'E  52,000 garbage pixels (|u|, |v| up to 1e2-1e6){label}: {far} of {outputs} '
              f'outputs over 100 m from the volume')


def case_api_misuse():
    """Wrong types as pixel or stamp: what happens, and do the counts add up."""
    cameras = default_rig()
    for label, observation in (
            ('u a string', Observation('camera1', DEFAULT_EPOCH_NS, 'abc', 100.0)),
            ('u None', Observation('camera1', DEFAULT_EPOCH_NS, None, 100.0)),
            ('u = 10**400', Observation('camera1', DEFAULT_EPOCH_NS, 10**400, 100.0)),
            ('stamp True', Observation('camera1', True, 300.0, 200.0))):
        fuser = Fuser(cameras)
        try:
            fuser.update(observation)
            outcome = 'returned'
        except Exception as err:  # noqa: B902 - the point is to see any exception
            outcome = f'raised {type(err).__name__}'
        stats = fuser.stats
        drops = {key: value for key, value in stats.items()
                 if key not in ('observations', 'estimates', 'resets', 'late') and value}
        print(f'F  {label}: {outcome}; observations {stats["observations"]}, drops {drops}')


def main():
    """Run every case."""
    case_double_frame_near_simultaneous()
    case_double_frame_synchronized()
    case_zero_tolerance()
    case_bad_stamps()
    case_garbage_pixels()
    case_api_misuse()


if __name__ == '__main__':
    main()
