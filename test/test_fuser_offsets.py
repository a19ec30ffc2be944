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
The fuser node's time offsets: configured ones applied on arrival, online ones estimated.

Points are published in the order of their raw stamps (as they would arrive), with camera2's
stamps 7 or 10 ms early; the node must put them on the common clock itself.
"""

import itertools
import os
import time

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped
import numpy as np
from pseudo_stereo_ros.evaluation.time_offsets import simulate_flights
from pseudo_stereo_ros.fusion import fuse
from pseudo_stereo_ros.offsets import apply_time_offsets
from pseudo_stereo_ros.ros.fuser_node import FuserNode
from pseudo_stereo_ros.ros.messages import observation_to_point, point_to_xyz
from pseudo_stereo_ros.ros.node_tools import StartupError
from pseudo_stereo_ros.sim.scenarios import default_rig
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
import yaml

_COUNTER = itertools.count()


@pytest.fixture
def namespace():
    return f'/offsets{os.getpid()}_{next(_COUNTER)}'


def _run(context, namespace, overrides, observations, *, pause_after=None, pause_s=0.0,
         pause_until=None):
    """
    Publish observations in order; return (node, received (stamp, x, y, z), diagnostics).

    After ``pause_after`` observations, spin ``pause_s`` seconds of wall time, or until
    ``pause_until(diagnostics)`` is true (at most ``pause_s``).
    """
    fuser = FuserNode(context=context, namespace=namespace, parameter_overrides=overrides)
    probe = rclpy.create_node('probe', namespace=namespace, context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(fuser)
    executor.add_node(probe)
    received, diagnostics = [], []
    probe.create_subscription(PointStamped, 'ball/position',
                              lambda msg: received.append(point_to_xyz(msg)), 1000)
    probe.create_subscription(DiagnosticArray, '/diagnostics', diagnostics.append, 10)
    publishers = {name: probe.create_publisher(PointStamped, f'{name}/ball/image_point', 500)
                  for name in ('camera1', 'camera2')}

    def spin_until(predicate, timeout_s=10.0):
        deadline = time.monotonic() + timeout_s
        while not predicate() and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.01)
        return predicate()

    try:
        assert spin_until(lambda: all(p.get_subscription_count() for p in publishers.values()))
        for count, observation in enumerate(observations, 1):
            publishers[observation.camera].publish(observation_to_point(observation))
            assert spin_until(lambda: fuser.fuser.stats['observations']
                              + len(fuser.buffer) >= count)
            if count == pause_after:  # wall time for the estimation timer
                spin_until(lambda: pause_until is not None and pause_until(diagnostics), pause_s)
        spin_until(lambda: not len(fuser.buffer), 2.0)
        spin_until(lambda: False, 0.1)
    finally:
        executor.shutdown()
        probe.destroy_node()
        fuser.destroy_node()
    return fuser, received, diagnostics


def test_configured_offsets_are_applied_on_arrival(context, namespace):
    cameras = default_rig()
    recording = simulate_flights(cameras, offsets_s={'camera2': 0.007}, fps=30.0,
                                 scenarios=('spiral',))
    fuser, received, _ = _run(context, namespace, [
        Parameter('time_offsets_s', value=[0.0, 0.007]),
        Parameter('time_offset_update_period_s', value=0.0)], recording.observations)
    expected, _ = fuse(cameras, apply_time_offsets(recording.observations, recording.offsets_s))
    # Stamped on the common clock, in stamp order (the reorder window grew by the 7 ms spread),
    # exactly the core's estimates on corrected observations.
    assert fuser.buffer.window_ns == 7_000_000
    assert [r[0] for r in received] == [e.stamp_ns for e in expected]
    np.testing.assert_allclose([r[1:] for r in received], [(e.x, e.y, e.z) for e in expected],
                               atol=1e-9)


def test_online_estimate_is_reported_and_applied_without_going_back(context, namespace):
    cameras = default_rig()
    recording = simulate_flights(cameras, offsets_s={'camera2': 0.010}, fps=30.0,
                                 noise_px=0.3, seed=3, scenarios=('spiral', 'bounce'))
    split = sum(1 for o in recording.observations
                if o.stamp_ns < recording.flights[1][0])  # the spiral, then a pause
    fuser, received, diagnostics = _run(context, namespace, [
        Parameter('estimate_time_offsets', value=True),
        Parameter('time_offset_update_period_s', value=0.2),
        Parameter('time_offset_max_slew', value=0.05),
        Parameter('diagnostics_period_s', value=0.2)],
        recording.observations, pause_after=split, pause_s=30.0,
        # The estimate runs in a worker process: the pause lasts until it is reported.
        pause_until=lambda arrays: any(kv.key == 'time offset camera2 estimate [ms]'
                                       for array in arrays for status in array.status
                                       for kv in status.values))
    estimate = fuser.offset_estimator.latest
    assert abs(estimate.offsets_s['camera2'] - 0.010) < 0.5e-3
    # Applied: slewed to the estimate (0.05 s per s: 10 ms within 0.2 s of stamps); the last
    # update may come after the last point, so within the estimate's error, not exactly.
    assert abs(fuser._applied_ns['camera2'] / 1e9 - 0.010) < 0.5e-3
    stamps = [r[0] for r in received]
    assert all(b >= a for a, b in zip(stamps, stamps[1:])), 'an output went back in time'
    assert len(received) > 0.8 * len(recording.observations)
    values = {kv.key: kv.value for array in diagnostics for status in array.status
              for kv in status.values}
    assert abs(float(values['time offset camera2 estimate [ms]']) - 10.0) < 0.5
    assert float(values['time offset camera2 uncertainty [ms]']) < 0.5
    assert values['time offset camera2 status'] == 'applied'
    # Once the slew is done, the node's estimates are the core's with the estimated offset
    # applied (which keeps being re-estimated while the second flight comes in: within 0.5 ms,
    # 1.5 mm of motion at 3 m/s).
    applied = fuser._applied_ns['camera2'] / 1e9
    expected, _ = fuse(cameras, apply_time_offsets(recording.observations, {'camera2': applied}))
    late = [e for e in expected if e.stamp_ns >= recording.flights[1][0] + 300_000_000]
    out = np.array([r[0] for r in received])
    assert len(late) > 20
    for e in late:
        nearest = int(np.argmin(np.abs(out - e.stamp_ns)))
        assert abs(out[nearest] - e.stamp_ns) < 500_000
        assert np.linalg.norm(np.subtract(received[nearest][1:], (e.x, e.y, e.z))) < 2e-3


@pytest.mark.parametrize('value, match', [([0.0, 0.1, 0.2], 'time_offsets_s: 3 values'),
                                          ([float('nan'), 0.0], 'time_offsets_s')])
def test_bad_offsets_parameter_stops_the_node(context, namespace, value, match):
    with pytest.raises(StartupError, match=match):
        FuserNode(context=context, namespace=namespace,
                  parameter_overrides=[Parameter('time_offsets_s', value=value)])


def test_config_fuser_yaml_lists_every_parameter_and_starts_the_node(context, namespace,
                                                                     repo_dir):
    # config/fuser.yaml is the documented parameter set: every parameter the node declares is
    # in it (with a comment), and its values start the node (types as declared).
    document = yaml.safe_load((repo_dir / 'config' / 'fuser.yaml').read_text())
    values = document['/**/fuser']['ros__parameters']
    fuser = FuserNode(context=context, namespace=namespace, parameter_overrides=[
        Parameter(name, value=value) for name, value in values.items()])
    try:
        declared = set(fuser._parameters) - {'use_sim_time', 'start_type_description_service'}
    finally:
        fuser.destroy_node()
    assert declared - set(values) == set(), 'declared but not in config/fuser.yaml'
    assert set(values) - declared == set(), 'in config/fuser.yaml but not declared'
