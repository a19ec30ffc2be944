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
Property-based tests of the core fuser on random streams (hypothesis).

Two families of streams go through the ``update`` of every method's fuser
(:func:`make_fuser`: paper, naive, trajectory) one observation at a time, as
the fuser node feeds it:

- *garbage*: any camera name, any stamp (ints of any size, floats, bools,
  None, strings) and any pixel (NaN, infinities, huge ints, strings, None,
  bools, values far outside the image).  Properties: no exception, no NaN
  or infinite estimate, and the counts add up (every observation gives an
  estimate, one drop reason, or is held by the gate).
- *valid but messy*: two or three free-running cameras at 25-250 fps with
  any phase from 0 to a period, stamp jitter, missed detections, pixel
  noise, duplicates, swapped neighbours, double triggers (a frame delivered
  again 1 ns to 30% of a period later) and single bad stamps (0, negative,
  1e6 s ahead).  Properties: as above, and no estimate is farther from the
  truth than the plausibility gate lets an estimate move in one frame
  period of the slowest camera (``max_speed_mps`` x period), the bound
  that separates a noisy estimate from a gross one.
"""

import math

from hypothesis import given, HealthCheck, settings, strategies as st
import numpy as np
from pseudo_stereo_ros.camera import Camera
from pseudo_stereo_ros.fusion import DROP_REASONS, make_fuser
from pseudo_stereo_ros.records import Observation
from pseudo_stereo_ros.sim.scenarios import (DEFAULT_EPOCH_NS, default_rig, look_at_calibration,
                                             make_scenario, observe, truth_at)
from pseudo_stereo_ros.trajectory import DROP_REASONS as TRAJECTORY_DROP_REASONS

DEFAULT_MAX_SPEED_MPS = 60.0  # the fuser's default max_speed_mps (checked below)

METHODS = st.sampled_from(['paper', 'naive', 'trajectory'])
# Counts of the trajectory method that are no drop reason (see its module docstring).
TRAJECTORY_INFO = {'breaks', 'outlier', 'predicted', 'restarts'}

SETTINGS = settings(max_examples=60, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


def _rig(count):
    cameras = default_rig()
    if count == 3:
        cameras.append(Camera(look_at_calibration('camera3', (1.5, -3.0, 2.5), (1.5, 1.0, 0.8))))
    return cameras


def _check_counts(fuser, returned):
    stats = fuser.stats
    reasons, info = DROP_REASONS, set()
    if fuser.method == 'trajectory':
        reasons, info = TRAJECTORY_DROP_REASONS, TRAJECTORY_INFO
    assert fuser.drop_reasons == reasons
    assert fuser.unaccounted() == 0, dict(stats)
    assert sum(fuser.dropped().values()) == sum(stats[key] for key in reasons)
    assert stats['estimates'] == returned
    assert set(stats) <= set(reasons) | {'observations', 'estimates', 'resets', 'late'} | info


def _feed(fuser, stream):
    estimates = []
    for observation in stream:
        estimate = fuser.update(observation)
        if estimate is not None:
            assert all(math.isfinite(value) for value in estimate[2:5]), estimate
            estimates.append(estimate)
    return estimates


NAMES = st.sampled_from(['camera1', 'camera2', 'camera3', '', 'cam-1'])
STAMPS = st.one_of(
    st.integers(DEFAULT_EPOCH_NS - 10**9, DEFAULT_EPOCH_NS + 10**9),
    st.integers(), st.integers(-10**400, 10**400), st.floats(allow_nan=True),
    st.booleans(), st.none(), st.text(max_size=3))
PIXELS = st.one_of(
    st.floats(-100.0, 800.0), st.floats(allow_nan=True, allow_infinity=True),
    st.integers(-10**400, 10**400), st.booleans(), st.none(), st.text(max_size=3))


@SETTINGS
@given(st.lists(st.tuples(NAMES, STAMPS, PIXELS, PIXELS), max_size=300), METHODS)
def test_garbage_never_raises_nor_gives_nan_and_counts_add_up(rows, method):
    fuser = make_fuser(_rig(3), method=method)
    estimates = _feed(fuser, [Observation(*row) for row in rows])
    _check_counts(fuser, len(estimates))
    assert fuser.stats['observations'] == len(rows)
    # The offline path as well (it sorts by stamp, whatever the stamps are).
    offline = make_fuser(_rig(3), method=method)
    offline.process([Observation(*row) for row in rows])
    assert offline.gate.held == 0
    assert offline.stats['observations'] == len(rows)


@st.composite
def messy_streams(draw):
    """Return (cameras, scenario, clean observations, messy stream, slowest period [s])."""
    count = draw(st.sampled_from([2, 2, 3]))
    cameras = _rig(count)
    fps = [draw(st.floats(25.0, 250.0)) for _ in range(count)]
    if draw(st.booleans()):
        fps = [fps[0]] * count  # one rate for the rig, the common case
    phases = [0.0] + [draw(st.floats(0.0, 1.0)) / f for f in fps[1:]]
    if draw(st.booleans()):
        # Near-simultaneous shutters, where a collapsed tolerance or baseline hurts most.
        phases = [0.0] + [draw(st.floats(0.0, 1e-3)) for _ in fps[1:]]
    jitter = draw(st.floats(0.0, 0.02))  # fraction of a period
    seed = draw(st.integers(0, 2**16))
    rng = np.random.default_rng(seed)
    duration = 0.6
    stamps = []
    for f, phase in zip(fps, phases):
        nominal = phase + np.arange(0.0, duration - phase, 1.0 / f)
        noisy = nominal + rng.uniform(-jitter, jitter, len(nominal)) / f
        stamps.append(np.unique(DEFAULT_EPOCH_NS + np.round(noisy * 1e9).astype(np.int64)))
    scenario = make_scenario(draw(st.sampled_from(['turntable', 'spiral', 'straight'])))
    clean = observe(scenario, cameras, stamps, noise_px=draw(st.floats(0.0, 0.5)),
                    dropout=draw(st.floats(0.0, 0.3)), seed=seed)
    stream = list(clean)
    # Faults at positions chosen by hypothesis (so that it can shrink them).
    faults = draw(st.lists(st.tuples(
        st.sampled_from(['duplicate', 'swap', 'double', 'zero', 'negative', 'ahead']),
        st.floats(0.0, 1.0), st.floats(0.0, 1.0)), max_size=6))
    for kind, where, amount in faults:
        if len(stream) < 3:
            break
        k = min(int(where * len(stream)), len(stream) - 2)
        observation = stream[k]
        if kind == 'duplicate':
            stream.insert(k + 1, observation)
        elif kind == 'swap':
            stream[k], stream[k + 1] = stream[k + 1], stream[k]
        elif kind == 'double':
            camera = next(c for c in cameras if c.name == observation.camera)
            period_ns = 1e9 / fps[cameras.index(camera)]
            delay = max(1, int(amount * 0.3 * period_ns))
            stamp = observation.stamp_ns + delay
            pixel = camera.project(truth_at(scenario, [stamp]))[0]
            if amount > 0.5:
                pixel = (observation.u, observation.v)  # the same frame delivered twice
            stream.insert(k + 1, observation._replace(stamp_ns=stamp, u=float(pixel[0]),
                                                      v=float(pixel[1])))
        else:
            bad = {'zero': 0, 'negative': -1 - int(amount * 1e9),
                   'ahead': observation.stamp_ns + 10**15}[kind]
            stream.insert(k + 1, observation._replace(stamp_ns=bad))
    return cameras, scenario, clean, stream, 1.0 / min(fps)


@SETTINGS
@given(messy_streams(), METHODS)
def test_messy_valid_streams_give_no_gross_estimate(case, method):
    cameras, scenario, _, stream, slowest_period_s = case
    fuser = make_fuser(cameras, method=method)
    estimates = _feed(fuser, stream)
    _check_counts(fuser, len(estimates))
    if not estimates:
        return
    stamps = np.array([e.stamp_ns for e in estimates], dtype=np.int64)
    truth = truth_at(scenario, stamps)
    errors = np.linalg.norm(np.array([e[2:5] for e in estimates]) - truth, axis=1)
    bound = DEFAULT_MAX_SPEED_MPS * slowest_period_s
    assert errors.max() < bound, (errors.max(), bound)
    assert fuser.plausibility.max_speed_mps == DEFAULT_MAX_SPEED_MPS
