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
The fuser's timing rules on real-world faults (issue 12, section 1), and the gates behind them.

Each fault of the issue has a regression test here that goes through the
public :class:`Fuser` API (so it ran, and failed, on the fuser before the
shared :class:`~pseudo_stereo_ros.timing.InputGate` existed); the gate and
the plausibility gate are then tested on their own.  Bounds: the simulated
cameras are the default rig (640 x 480 px, about 3 m from the ball), where
0.3 px of noise gives a few centimetres of error at worst; a fault handled
right costs no accuracy, so the faulty stream's worst error is bounded by
the clean stream's.
"""

from collections import Counter
import math

import numpy as np
from pseudo_stereo_ros.cli.main import main
from pseudo_stereo_ros.errors import FuserConfigError
from pseudo_stereo_ros.formats.csv_io import write_observations
from pseudo_stereo_ros.fusion import fuse, Fuser
from pseudo_stereo_ros.records import Observation, positions_array
from pseudo_stereo_ros.rig import config_dir
from pseudo_stereo_ros.sim.scenarios import (DEFAULT_EPOCH_NS, default_rig, make_scenario, observe,
                                             shutter_stamps, truth_at)
import pytest

# The modules new with these rules (timing, plausibility) are imported inside the tests that
# use them, so that the regression tests run, and fail, against the fuser before them.


def recording(duration_s, phase_s, *, fps=30.0, noise_px=0.3, jitter_ns=0, seed=0,
              scenario='turntable'):
    """Return (cameras, scenario, observations): camera2 phase_s after camera1 [s]."""
    cameras = default_rig()
    run = make_scenario(scenario, duration=duration_s) if scenario == 'turntable' \
        else make_scenario(scenario)
    rng = np.random.default_rng(seed)
    stamps = []
    for phase in (0.0, phase_s):
        # Sub-microsecond phases are added to the integer stamps directly.
        shifted = shutter_stamps(fps, duration_s) + int(round(phase * 1e9))
        if jitter_ns:
            shifted = shifted + rng.integers(-jitter_ns, jitter_ns + 1, len(shifted))
        stamps.append(shifted)
    return cameras, run, observe(run, cameras, stamps, noise_px=noise_px, seed=seed)


def stream(fuser, observations):
    """Feed observations one by one, as the node does; return the estimates."""
    return [e for e in map(fuser.update, observations) if e is not None]


def errors(estimates, scenario):
    stamps = np.array([e.stamp_ns for e in estimates], dtype=np.int64)
    return np.linalg.norm(positions_array(estimates) - truth_at(scenario, stamps), axis=1)


def double_frame(observations, index, delay_ns, camera='camera1'):
    """Return observations with a camera's index-th frame delivered again delay_ns later."""
    k = [i for i, o in enumerate(observations) if o.camera == camera][index]
    copy = observations[k]._replace(stamp_ns=observations[k].stamp_ns + delay_ns)
    return observations[:k + 1] + [copy] + observations[k + 1:]


def counts_add_up(fuser):
    return fuser.unaccounted() == 0


# -- 1.1 a double trigger -------------------------------------------------------------------------

@pytest.mark.parametrize('phase_s', [1e-6, 1e-5])
@pytest.mark.parametrize('seed', [0, 2])
def test_a_double_frame_does_not_collapse_the_sync_tolerance(phase_s, seed):
    # Cameras 1-10 us apart are one instant (paired directly); a 3 ns double frame used to set
    # the tolerance to 0 for good, and the prediction then divided by the cameras' phase.
    cameras, scenario, observations = recording(2.0, phase_s, seed=seed)
    clean = errors(stream(Fuser(cameras), observations), scenario)
    fuser = Fuser(cameras)
    doubled = errors(stream(fuser, double_frame(observations, 5, 3)), scenario)
    assert fuser.sync_tolerance_ns == 1_000_000
    assert doubled.max() <= 1.5 * clean.max(), (doubled.max(), clean.max())


@pytest.mark.parametrize('seed', [1, 3])
def test_synchronized_jittered_cameras_with_a_double_frame(seed):
    # Synchronized 30 fps cameras with +-5 us jitter and one 20 us double frame.
    cameras, scenario, observations = recording(4.0, 0.0, jitter_ns=5_000, seed=seed)
    clean = errors(stream(Fuser(cameras), observations), scenario)
    doubled = errors(stream(Fuser(cameras), double_frame(observations, 5, 20_000)), scenario)
    assert clean.max() < 0.05  # 0.3 px at 3 m
    assert doubled.max() <= 1.5 * clean.max(), (doubled.max(), clean.max())


@pytest.mark.parametrize('seed', [0, 2])
def test_zero_tolerance_never_extrapolates_from_a_tiny_baseline(seed):
    # No direct pairs at all: every estimate is a prediction, and two anchors 0-10 us apart
    # must count as one instant (the baseline floor), not give a gain of thousands.
    cameras, scenario, observations = recording(4.0, 0.0, jitter_ns=5_000, seed=seed)
    fuser = Fuser(cameras, sync_tolerance_ns=0)
    estimates = stream(fuser, observations)
    assert len(estimates) > 0.95 * len(observations)
    reference = errors(stream(Fuser(cameras), observations), scenario)
    assert errors(estimates, scenario).max() <= 2 * reference.max()


def test_reset_restores_the_configured_tolerance():
    cameras, scenario, observations = recording(0.1, 0.001, fps=500.0, noise_px=0.0)
    fuser = Fuser(cameras)
    fuser.process(observations)
    assert fuser.sync_tolerance_ns == 500_000  # a quarter of the 2 ms period
    fuser.reset()
    assert fuser.sync_tolerance_ns == 1_000_000


def test_implausible_estimates_are_dropped_counted_and_do_not_lock_out():
    # At 120 fps a detection 150 px off (a wrong blob inside the image) puts the estimates of
    # its event and of the events that extrapolate from it metres away. The gate lets an
    # estimate move at most 60 m/s x 2/240 s = 0.5 m from the accepted one two events back
    # (5 ms minimum): nothing farther may be returned, and the estimates after the bad ones
    # must come back.
    fps = 120.0
    cameras, scenario, observations = recording(2.0, 0.5 / fps, fps=fps, noise_px=0.0)
    k = 60
    wrong = list(observations)
    wrong[k] = wrong[k]._replace(u=wrong[k].u + 150.0)
    fuser = Fuser(cameras)
    estimates = stream(fuser, wrong)
    reference = stream(Fuser(cameras, max_speed_mps=None), wrong)
    assert errors(reference, scenario).max() > 1.0  # what the gate is for
    assert fuser.stats['implausible'] >= 1 and counts_add_up(fuser)
    assert errors(estimates, scenario).max() < 0.5
    # Every estimate of the clean stream after the bad event's influence is there.
    clean = {e.stamp_ns for e in stream(Fuser(cameras), observations)}
    after = {s for s in clean if s > observations[k + 4].stamp_ns}
    assert after <= {e.stamp_ns for e in estimates}


def test_estimates_outside_the_workspace_box_are_dropped():
    cameras, scenario, observations = recording(2.0, 1 / 60, noise_px=0.0)
    # The turntable circles (1.5, 1.0) with radius 0.5 m: cut the box at x = 1.5.
    estimates, stats = fuse(cameras, observations, workspace_min_m=(-1.0, -1.0, -1.0),
                            workspace_max_m=(1.5, 3.0, 3.0))
    everything, _ = fuse(cameras, observations)
    assert estimates and all(e.x <= 1.5 for e in estimates)
    assert stats['implausible'] == sum(1 for e in everything if e.x > 1.5) > 10


# -- 1.2 one bad stamp --------------------------------------------------------------------------

@pytest.mark.parametrize('bad', ['zero', 'negative', 'ahead'])
def test_one_bad_stamp_is_an_outlier_not_a_new_session(bad):
    cameras, scenario, observations = recording(3.0, 1 / 60, noise_px=0.2)
    k = 45
    stamp = {'zero': 0, 'negative': -1, 'ahead': observations[k].stamp_ns + 10**15}[bad]
    faulty = observations[:k] + [observations[k]._replace(stamp_ns=stamp)] + observations[k:]
    fuser = Fuser(cameras)
    estimates = stream(fuser, faulty)
    assert estimates == stream(Fuser(cameras), observations)  # nothing lost, nothing changed
    assert fuser.stats['stamp_outlier'] == 1 and fuser.stats['resets'] == 0
    assert counts_add_up(fuser)


def test_zero_stamps_every_tenth_of_a_second_cost_nothing():
    cameras, scenario, observations = recording(3.0, 1 / 60, noise_px=0.2)
    faulty, next_zero, zeros = [], DEFAULT_EPOCH_NS + 50_000_000, 0
    for observation in observations:
        if observation.stamp_ns >= next_zero:
            faulty.append(observation._replace(camera='camera1', stamp_ns=0))
            next_zero += 100_000_000
            zeros += 1
        faulty.append(observation)
    fuser = Fuser(cameras)
    assert stream(fuser, faulty) == stream(Fuser(cameras), observations)
    assert fuser.stats['stamp_outlier'] == zeros == 30


def test_a_jump_the_cameras_agree_on_starts_a_new_session():
    # The whole rig's clock jumps ahead by an hour (a restarted clock): a new session, and the
    # second part is fused like a fresh start.
    cameras, scenario, observations = recording(2.0, 1 / 60, noise_px=0.2)
    half = len(observations) // 2
    jumped = observations[:half] + [o._replace(stamp_ns=o.stamp_ns + 3600 * 10**9)
                                    for o in observations[half:]]
    fuser = Fuser(cameras)
    estimates = stream(fuser, jumped)
    assert fuser.session == 1 and fuser.stats['stamp_outlier'] == 0
    second = [e for e in estimates if e.stamp_ns > DEFAULT_EPOCH_NS + 3600 * 10**9]
    fresh = stream(Fuser(cameras), jumped[half:])
    assert second == fresh and len(second) == len(observations) - half - 3


def test_a_pause_with_one_camera_resuming_first_starts_a_new_session():
    # After a 2 s pause camera1 alone fires for 0.1 s before camera2 sees the ball again.
    cameras, scenario, observations = recording(2.0, 1 / 60, noise_px=0.0)
    pause = 2 * 10**9
    first = [o for o in observations if o.stamp_ns < DEFAULT_EPOCH_NS + 10**9]
    resume = DEFAULT_EPOCH_NS + 10**9 + pause
    second = [o._replace(stamp_ns=o.stamp_ns + pause) for o in observations
              if o.stamp_ns >= DEFAULT_EPOCH_NS + 10**9]
    second = [o for o in second if o.camera == 'camera1' or o.stamp_ns > resume + 100_000_000]
    fuser = Fuser(cameras)
    estimates = stream(fuser, first + second)
    assert fuser.session == 1 and fuser.stats['stamp_outlier'] == 0
    # Fused as a fresh start: camera1's first frames are history when camera2 comes back.
    later = [e for e in estimates if e.stamp_ns > resume]
    assert later == stream(Fuser(cameras), second) and len(later) > 20


# -- 1.3 max_gap follows the frame period -------------------------------------------------------

def test_the_max_gap_follows_the_frame_period():
    # 168 fps: a camera silent for 12 frames (71 ms, under the 0.1 s option) is stale after
    # 4.5 periods (27 ms); a straight line over 71 ms of a spiral is not interpolation.
    fps = 168.0
    cameras, scenario, observations = recording(1.0, 1 / 336, fps=fps, noise_px=0.0,
                                                scenario='spiral')
    stamps = sorted(o.stamp_ns for o in observations if o.camera == 'camera2')
    start, end = stamps[60], stamps[72]
    kept = [o for o in observations if not (o.camera == 'camera2' and start <= o.stamp_ns < end)]
    fuser = Fuser(cameras)
    estimates = stream(fuser, kept)
    period_ns = 1e9 / fps
    out = np.array([e.stamp_ns for e in estimates])
    assert not np.any((out > stamps[59] + 4.5 * period_ns + 1) & (out < end))
    assert fuser.stats['no_partner'] > 0
    assert errors(estimates, scenario).max() < 0.005  # and no bridged estimate is off
    assert fuser.gate.max_gap_for('camera2') == pytest.approx(4.5 * period_ns, rel=0.01)


def test_the_max_gap_option_is_an_upper_bound():
    cameras, _, observations = recording(1.0, 1 / 60, noise_px=0.0)
    fuser = Fuser(cameras)
    fuser.process(observations)
    assert fuser.gate.max_gap_for('camera1') == 100_000_000  # 4.5 periods is 150 ms at 30 fps
    fuser = Fuser(cameras, max_gap_ns=50_000_000)
    fuser.process(observations)
    assert fuser.gate.max_gap_for('camera1') == 50_000_000


# -- 1.4 pixels far outside the image -----------------------------------------------------------

def test_pixels_far_outside_the_image_are_dropped_and_counted():
    cameras, scenario, observations = recording(2.0, 1 / 60, noise_px=0.0)
    garbage = set(range(20, len(observations), 17))
    faulty = [o._replace(u=-1e6, v=1e6) if k in garbage else o
              for k, o in enumerate(observations)]
    estimates, stats = fuse(cameras, faulty)
    assert stats['outside_image'] == len(garbage)
    expected, _ = fuse(cameras, [o for k, o in enumerate(observations) if k not in garbage])
    assert estimates == expected


@pytest.mark.parametrize('u, margin, dropped', [
    (-0.05 * 640, None, False), (-0.15 * 640, None, True), (639 + 0.09 * 640, None, False),
    (-1.0, 0.0, True), (-1e9, math.inf, False),
])
def test_the_image_margin(u, margin, dropped):
    fuser = Fuser(default_rig(), image_margin=margin)
    fuser.update(Observation('camera1', DEFAULT_EPOCH_NS, u, 240.0))
    assert fuser.stats['outside_image'] == int(dropped)


# -- 1.5 API misuse ----------------------------------------------------------------------------

@pytest.mark.parametrize('field, value, reason', [
    ('u', 'abc', 'bad_pixel'), ('u', None, 'bad_pixel'), ('v', True, 'bad_pixel'),
    ('u', np.bool_(True), 'bad_pixel'), ('v', b'1', 'bad_pixel'), ('u', 1j, 'bad_pixel'),
    ('u', 10**400, 'non_finite'), ('v', -10**400, 'non_finite'), ('u', math.nan, 'non_finite'),
    ('stamp_ns', True, 'bad_stamp'), ('stamp_ns', np.bool_(False), 'bad_stamp'),
    ('stamp_ns', 1.7e18, 'bad_stamp'), ('stamp_ns', '1700000000000000000', 'bad_stamp'),
    ('stamp_ns', None, 'bad_stamp'), ('stamp_ns', 10**30, 'bad_stamp'),
    ('camera', ['camera1'], 'unknown_camera'), ('camera', None, 'unknown_camera'),
])
def test_api_misuse_is_dropped_with_its_reason(field, value, reason):
    fuser = Fuser(default_rig())
    good = Observation('camera1', DEFAULT_EPOCH_NS, 300.0, 200.0)
    assert fuser.update(good._replace(**{field: value})) is None
    assert fuser.stats[reason] == 1 and fuser.stats['observations'] == 1
    assert counts_add_up(fuser)


def test_numpy_values_are_valid_input():
    fuser = Fuser(default_rig())
    fuser.update(Observation('camera1', np.int64(DEFAULT_EPOCH_NS), np.float32(300.0),
                             np.int32(200)))
    assert fuser.stats['no_partner'] == 1


# -- the input gate -----------------------------------------------------------------------------

def gate_of(fuser):
    return fuser.gate


def test_the_period_is_robust_to_double_frames_and_missed_detections():
    fuser = Fuser(default_rig(), max_speed_mps=None)
    gate = gate_of(fuser)
    period = 5_952_381  # 168 fps
    rng = np.random.default_rng(1)
    stamp = DEFAULT_EPOCH_NS
    for k in range(200):
        stamp += period * (1 + int(rng.random() < 0.4)) + int(rng.integers(-50_000, 50_000))
        fuser.update(Observation('camera1', stamp, 300.0, 200.0))
        if k % 7 == 3:  # a double trigger, from 3 ns to 2 ms
            fuser.update(Observation('camera1', stamp + int(rng.choice([3, 20_000, 2_000_000])),
                                     300.0, 200.0))
        if k > 20:
            assert abs(gate.period_ns('camera1') - period) < 100_000, k
    assert gate.sync_tolerance_ns == 1_000_000  # a quarter period is 1.49 ms
    assert gate.baseline_floor_ns == 1_000_000


def test_held_observations_are_counted_until_decided():
    cameras, _, observations = recording(1.0, 1 / 60, noise_px=0.0)
    fuser = Fuser(cameras)
    stream(fuser, observations[:20])
    ahead = observations[20]._replace(stamp_ns=observations[20].stamp_ns + 10**12)
    assert fuser.off_timeline(ahead.stamp_ns) and not fuser.off_timeline(observations[20].stamp_ns)
    assert fuser.update(ahead) is None
    assert fuser.gate.held == 1 and counts_add_up(fuser) and fuser.stats['stamp_outlier'] == 0
    fuser.process([])  # the end of a recording decides: no camera agreed
    assert fuser.gate.held == 0 and fuser.stats['stamp_outlier'] == 1 and counts_add_up(fuser)


def test_a_held_observation_repeated_is_a_duplicate_and_a_third_timeline_an_outlier():
    cameras, _, observations = recording(1.0, 1 / 60, noise_px=0.0)
    fuser = Fuser(cameras)
    stream(fuser, observations[:20])
    jump = 10**12
    first, second = (o._replace(stamp_ns=o.stamp_ns + jump) for o in observations[20:22])
    assert first.camera != second.camera
    for observation in (first, first, first._replace(stamp_ns=first.stamp_ns + 5 * jump)):
        fuser.update(observation)
    # The repeat is a duplicate; the observation 5000 s further on is on neither timeline:
    # the one held before it was an outlier, and it is held in its turn.
    assert fuser.stats['duplicate'] == 1 and fuser.stats['stamp_outlier'] == 1
    assert fuser.gate.held == 1 and fuser.session == 0 and counts_add_up(fuser)
    fuser.update(second._replace(stamp_ns=second.stamp_ns + 5 * jump))  # the cameras agree
    assert fuser.session == 1 and fuser.gate.held == 0 and counts_add_up(fuser)


def test_the_gate_serves_any_estimator():
    # What another estimator sees: a new session flag, then admitted items in order.
    from pseudo_stereo_ros.timing import InputGate
    cameras, _, observations = recording(1.0, 1 / 60, noise_px=0.0)
    stats = Counter()
    gate = InputGate(cameras, stats=stats)
    ready = []
    for observation in observations[:10] + [o._replace(stamp_ns=o.stamp_ns - 10**9)
                                            for o in observations[10:14]]:
        admission = gate.admit(observation)
        if admission.new_session:
            ready.append('new session')
        ready.extend(item.observation.stamp_ns for item in admission.ready)
    assert ready[:10] == [o.stamp_ns for o in observations[:10]]
    assert ready[10] == 'new session' and gate.session == 1
    assert ready[11:] == [o.stamp_ns - 10**9 for o in observations[10:14]]
    assert stats['observations'] == 14 and stats['resets'] == 1


@pytest.mark.parametrize('options, match', [
    ({'image_margin': -0.1}, 'image_margin'), ({'image_margin': math.nan}, 'image_margin'),
    ({'max_speed_mps': -1.0}, 'max_speed_mps'), ({'max_speed_mps': math.nan}, 'max_speed_mps'),
    ({'workspace_min_m': (0.0, 0.0)}, 'workspace_min_m'),
    ({'workspace_min_m': (0.0, 0.0, 2.0), 'workspace_max_m': (1.0, 1.0, 1.0)}, 'on z'),
    ({'workspace_max_m': (1.0, math.nan, 1.0)}, 'workspace_max_m'),
    ({'sync_tolerance_ns': math.inf}, 'sync_tolerance_ns'),
])
def test_bad_options_are_refused(options, match):
    with pytest.raises(FuserConfigError, match=match):
        Fuser(default_rig(), **options)


# -- the plausibility gate ----------------------------------------------------------------------

def test_a_wrong_first_estimate_costs_at_most_one_correct_one():
    from pseudo_stereo_ros.plausibility import PlausibilityGate
    gate = PlausibilityGate(max_speed_mps=60.0)
    start = DEFAULT_EPOCH_NS
    assert gate.accept(start, (50.0, 0.0, 0.0))  # nothing to compare with: the seed
    accepted = [gate.accept(start + k * 5_000_000, (0.01 * k, 0.0, 1.0)) for k in range(1, 10)]
    assert accepted == [False] + [True] * 8
    assert gate.stats['implausible'] == 1
    # A single jump between good estimates is rejected, the next good one accepted.
    assert not gate.accept(start + 50_000_000, (5.0, 0.0, 1.0))
    assert gate.accept(start + 55_000_000, (0.11, 0.0, 1.0))
    # After a gap longer than the window the gate re-seeds anywhere.
    assert gate.accept(start + 10**9, (3.0, 2.0, 1.0))


def test_a_track_yields_to_a_run_of_three_agreeing_estimates_only():
    from pseudo_stereo_ros.plausibility import PlausibilityGate
    gate = PlausibilityGate(max_speed_mps=60.0)
    start = DEFAULT_EPOCH_NS
    for k in range(5):  # a track at 2 m/s, one estimate every 3 ms
        assert gate.accept(start + k * 3_000_000, (0.006 * k, 0.0, 1.0))
    # Two wrong estimates that agree with each other (one bad detection): both rejected ...
    assert not gate.accept(start + 15_000_000, (2.0, 0.0, 1.0))
    assert not gate.accept(start + 18_000_000, (2.01, 0.0, 1.0))
    assert gate.accept(start + 21_000_000, (0.042, 0.0, 1.0))
    # ... while a ball that really is elsewhere (the next ball) is accepted at its third.
    jump = [gate.accept(start + (24 + 3 * k) * 1_000_000, (-3.0 + 0.006 * k, 1.0, 1.0))
            for k in range(5)]
    assert jump == [False, False, True, True, True]
    assert gate.stats['implausible'] == 4


def test_track_options_reach_the_fuser(tmp_path, capsys):
    cameras, _, observations = recording(2.0, 1 / 60, noise_px=0.0)
    source = tmp_path / 'obs.csv'
    write_observations(source, observations)
    rig = [arg for camera in cameras
           for arg in ('--camera', f'{camera.name}={config_dir() / "rig" / camera.name}.yaml')]
    args = ['track', *rig, '--input', str(source), '--output', str(tmp_path / 'e.csv')]
    assert main(args + ['--workspace-min', '-1', '-1', '-1', '--workspace-max', '1.5', '3',
                        '3', '--image-margin', '0', '--max-speed', '30']) == 0
    message = capsys.readouterr().err
    assert 'implausible' in message and 'outside_image' not in message
    assert main(args + ['--workspace-min', '0', '0', '2', '--workspace-max', '1', '1', '1']) == 2
    error = capsys.readouterr().err
    assert 'workspace' in error and error.count('\n') == 1
    assert main(args + ['--max-speed', 'nan']) == 2
    assert '--max-speed' in capsys.readouterr().err


def test_a_late_observation_before_the_partners_history_is_not_paired_with_a_later_frame():
    # camera2 resumes (its history starts at t) after camera1's frame at t - 1/60 s has been
    # delivered late: no camera2 frame is near that frame, so nothing may pair it with camera2's
    # later frame as if simultaneous (that was a 1/60 s error, ~50 mm at 3 m/s).
    cameras, run, observations = recording(1.0, 1 / 60, noise_px=0.0)
    cam1 = [o for o in observations if o.camera == 'camera1']
    cam2 = [o for o in observations if o.camera == 'camera2']
    fuser = Fuser(cameras)
    stream(fuser, cam1[:10])  # camera1 alone: no partner yet
    late = cam1[10]
    resumed = next(o for o in cam2 if o.stamp_ns > late.stamp_ns)
    estimates = stream(fuser, [resumed, late] + [o for o in observations
                                                 if o.stamp_ns > resumed.stamp_ns])
    assert estimates, 'the fuser recovered after the outage'
    assert errors(estimates, run).max() < 0.01, [e for e in estimates
                                                 if e.stamp_ns == late.stamp_ns]
    assert counts_add_up(fuser)
