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

"""In-process tests of the nodes: own context, unique namespace, parameter_overrides."""

import itertools
import os
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PointStamped
import numpy as np
from pseudo_stereo_ros.calibration import CalibrationError, save_calibration
from pseudo_stereo_ros.fusion import fuse
from pseudo_stereo_ros.records import Observation
from pseudo_stereo_ros.ros import bringup
from pseudo_stereo_ros.ros.detector_node import DetectorNode
from pseudo_stereo_ros.ros.fuser_node import FuserNode, INPUT_QUEUE_DEPTH
from pseudo_stereo_ros.ros.messages import (array_to_image, estimate_to_point, image_to_array,
                                            observation_to_point, point_to_xyz, stamp_to_ns)
from pseudo_stereo_ros.ros.monitor_node import MonitorNode
from pseudo_stereo_ros.ros.node_tools import StartupError
from pseudo_stereo_ros.ros.virtual_camera_node import VirtualCameraNode
from pseudo_stereo_ros.sim.rendering import BallRenderer
from pseudo_stereo_ros.sim.scenarios import (DEFAULT_EPOCH_NS, default_rig, make_scenario, observe,
                                             shutter_stamps, truth_at)
import pytest
import rclpy
from rclpy.exceptions import InvalidParameterValueException
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import qos_profile_sensor_data
from rclpy.serialization import serialize_message
from sensor_msgs.msg import CameraInfo, Image
from visualization_msgs.msg import Marker

_COUNTER = itertools.count()


@pytest.fixture
def namespace():
    """Return a namespace no other test (or process) uses."""
    return f'/t{os.getpid()}_{next(_COUNTER)}'


class Harness:
    """Nodes under test plus a probe node, spun by one executor with deadlines."""

    def __init__(self, context, namespace, *nodes):
        self.probe = rclpy.create_node('probe', namespace=namespace, context=context)
        self.executor = SingleThreadedExecutor(context=context)
        self.nodes = nodes
        for node in (self.probe,) + nodes:
            self.executor.add_node(node)

    def spin_until(self, predicate, timeout_s=5.0):
        deadline = time.monotonic() + timeout_s
        while not predicate() and time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.01)
        return predicate()

    def spin_for(self, seconds):
        self.spin_until(lambda: False, seconds)

    def close(self):
        self.executor.shutdown()
        for node in (self.probe,) + self.nodes:
            node.destroy_node()


def _observations(scenario='spiral', noise_px=0.0):
    cameras = default_rig()
    run = make_scenario(scenario)
    stamps = [shutter_stamps(30.0, run.duration_s, phase_s=i / 60.0) for i in range(2)]
    return cameras, run, observe(run, cameras, stamps, noise_px=noise_px)


def _feed_points(harness, observations, received, *, burst=False):
    publishers = {}
    for name in ('camera1', 'camera2'):
        publishers[name] = harness.probe.create_publisher(PointStamped,
                                                          f'{name}/ball/image_point', 500)
    assert harness.spin_until(lambda: all(p.get_subscription_count() for p in
                                          publishers.values()))
    fuser = harness.nodes[0]

    def taken():  # every message the fuser took: observations, malformed ones, failed ones
        return (fuser.fuser.stats['observations'] + fuser.node_stats['malformed']
                + fuser.node_stats['internal_error'])

    for count, observation in enumerate(observations, 1):
        if isinstance(observation, Observation):
            publishers[observation.camera].publish(observation_to_point(observation))
        else:  # (camera, bytes): published as they are
            publishers[observation[0]].publish(observation[1])
        # Bursts of at most 50 points, whatever the scenario.
        if not burst or count % 50 == 0:
            assert harness.spin_until(lambda: taken() >= count)
    assert harness.spin_until(lambda: taken() >= len(observations))
    harness.spin_for(0.05)  # the reorder window's last hold


def _positions_subscription(harness):
    received = []
    harness.probe.create_subscription(PointStamped, 'ball/position',
                                      lambda msg: received.append(point_to_xyz(msg)), 500)
    return received


@pytest.mark.parametrize('burst', [False, True])
def test_fuser_node_equals_core_fuse(context, namespace, burst):
    cameras, _, observations = _observations()
    fuser = FuserNode(context=context, namespace=namespace)
    harness = Harness(context, namespace, fuser)
    try:
        received = _positions_subscription(harness)
        _feed_points(harness, observations, received, burst=burst)
        expected, _ = fuse(cameras, observations)
        assert harness.spin_until(lambda: len(received) >= len(expected))
        harness.spin_for(0.05)
    finally:
        harness.close()
    # One position per shutter event after warm-up, stamped with the event.
    assert len(expected) >= len(observations) - 3
    assert [r[0] for r in received] == [e.stamp_ns for e in expected]
    np.testing.assert_allclose([r[1:] for r in received], [(e.x, e.y, e.z) for e in expected],
                               rtol=0, atol=1e-9)


def test_fuser_node_trajectory_equals_core_fuse(context, namespace):
    # method best (the alias of trajectory): the node publishes exactly what
    # make_fuser(method='trajectory').process gives (noisy bounces: impacts, pending
    # detections and velocity jumps included).
    cameras, _, observations = _observations('bounce', noise_px=0.3)
    fuser = FuserNode(context=context, namespace=namespace,
                      parameter_overrides=[Parameter('method', value='best')])
    harness = Harness(context, namespace, fuser)
    try:
        received = _positions_subscription(harness)
        _feed_points(harness, observations, received)
        expected, stats = fuse(cameras, observations, method='trajectory')
        assert harness.spin_until(lambda: len(received) >= len(expected))
        harness.spin_for(0.05)
    finally:
        harness.close()
    assert stats['breaks'] >= 1
    assert [r[0] for r in received] == [e.stamp_ns for e in expected]
    np.testing.assert_allclose([r[1:] for r in received], [(e.x, e.y, e.z) for e in expected],
                               rtol=0, atol=1e-9)


def test_fuser_node_stops_on_a_stale_camera_and_resumes(context, namespace):
    cameras, _, observations = _observations('turntable')
    stamps = sorted({o.stamp_ns for o in observations if o.camera == 'camera2'})
    gap_start, gap_end = stamps[20], stamps[40]  # camera2 silent for 0.67 s
    kept = [o for o in observations
            if not (o.camera == 'camera2' and gap_start <= o.stamp_ns < gap_end)]
    fuser = FuserNode(context=context, namespace=namespace,
                      parameter_overrides=[Parameter('max_gap_s', value=0.1)])
    harness = Harness(context, namespace, fuser)
    try:
        received = _positions_subscription(harness)
        _feed_points(harness, kept, received)
        expected, _ = fuse(cameras, kept, max_gap_ns=100_000_000)
        assert harness.spin_until(lambda: len(received) >= len(expected))
    finally:
        harness.close()
    out = np.array([r[0] for r in received])
    assert list(out) == [e.stamp_ns for e in expected]
    last_before = stamps[19]
    stale = (out > last_before + 100_000_000) & (out < gap_end)
    assert not stale.any()  # nothing from a partner older than max_gap
    assert (out >= gap_end).sum() > 30  # and it resumes


@pytest.mark.parametrize('overrides, match', [
    ([Parameter('camera_names', value=['camera1'])], 'camera_names'),
    ([Parameter('camera_names', value=['camera1', 'camera1'])], 'camera_names'),
    ([Parameter('method', value='kalman')], 'method'),
    ([Parameter('calibration_files', value=['a.yaml'])], 'calibration_files'),
    ([Parameter('sync_tolerance_s', value=0.2)], 'max_gap'),
    ([Parameter('world_frame', value='')], 'world_frame'),
    ([Parameter('workspace_min_m', value=[0.0, 0.0])], 'workspace_min_m'),
    ([Parameter('workspace_min_m', value=[0.0, 0.0, 2.0]),
      Parameter('workspace_max_m', value=[1.0, 1.0, 1.0])], 'workspace_min_m'),
])
def test_fuser_rejects_bad_parameters(context, namespace, overrides, match):
    with pytest.raises(StartupError, match=match):
        FuserNode(context=context, namespace=namespace, parameter_overrides=overrides)


def test_fuser_rejects_a_malformed_calibration_file(context, namespace, tmp_path):
    good = tmp_path / 'camera1.yaml'
    bad = tmp_path / 'camera2.yaml'
    save_calibration(default_rig()[0].calibration, good)
    bad.write_text('camera_name: camera2\nimage_width: 640\nimage_height: 480\n')
    # The message names the parameter entry, the file and the key.
    with pytest.raises(StartupError, match=r'parameter calibration_files\[1\] \(camera camera2\)'
                       r": .*camera2.yaml: key 'camera_matrix'") as error:
        FuserNode(context=context, namespace=namespace, parameter_overrides=[
            Parameter('calibration_files', value=[str(good), str(bad)])])
    assert isinstance(error.value.__cause__, CalibrationError)
    with pytest.raises(StartupError, match=r'calibration_files\[0\] \(camera camera1\): .*none'):
        FuserNode(context=context, namespace=namespace, parameter_overrides=[
            Parameter('calibration_files', value=[str(tmp_path / 'none.yaml'), str(good)])])


def _image_publisher(harness):
    publisher = harness.probe.create_publisher(Image, 'image_raw', 10)
    points = []
    harness.probe.create_subscription(PointStamped, 'ball/image_point', points.append, 10)
    assert harness.spin_until(lambda: publisher.get_subscription_count() > 0)
    return publisher, points


def test_detector_node_publishes_the_centroid_with_the_image_header(context, namespace):
    camera = default_rig()[0]
    renderer = BallRenderer(camera, radius_m=0.03, noise_std=2.0, seed=1)
    detector = DetectorNode(context=context, namespace=namespace)
    harness = Harness(context, namespace, detector)
    try:
        publisher, points = _image_publisher(harness)
        position = (1.2, 0.8, 1.1)
        stamp = DEFAULT_EPOCH_NS + 123_456_789
        image = array_to_image(renderer.render(position), 'bgr8', stamp, 'camera1_optical')
        publisher.publish(image)
        assert harness.spin_until(lambda: len(points) == 1)
        # Wrong encoding, and empty images (OpenCV asserts on them): dropped, counted, and the
        # node keeps working.
        bad = Image(header=image.header, height=480, width=640, encoding='16UC1', step=1280)
        bad.data = bytes(1280 * 480)
        publisher.publish(bad)
        publisher.publish(Image(header=image.header, encoding='bgr8'))
        publisher.publish(Image(header=image.header, height=480, width=0, encoding='mono8'))
        assert harness.spin_until(lambda: detector.stats['bad_image'] == 3)
        # A frame without a ball: counted, nothing published.
        publisher.publish(array_to_image(renderer.render(None), 'bgr8', stamp + 1, 'c'))
        assert harness.spin_until(lambda: detector.stats['no_ball'] == 1)
        rgb = array_to_image(renderer.render(position)[:, :, ::-1], 'rgb8', stamp + 2, 'c')
        publisher.publish(rgb)
        assert harness.spin_until(lambda: len(points) == 2)
        harness.spin_for(0.05)
    finally:
        harness.close()
    assert points[0].header == image.header
    truth = camera.project(np.array(position))[0]
    assert np.hypot(points[0].point.x - truth[0], points[0].point.y - truth[1]) < 0.25
    assert points[0].point.z == 0.0
    assert len(points) == 2 and stamp_to_ns(points[1].header.stamp) == stamp + 2
    assert detector.stats['images'] == 6 and detector.stats['published'] == 2


def test_detector_rejects_bad_parameters(context, namespace):
    with pytest.raises(StartupError, match='choice'):
        DetectorNode(context=context, namespace=namespace,
                     parameter_overrides=[Parameter('choice', value='brightest')])
    with pytest.raises(StartupError, match='min_area_px'):
        DetectorNode(context=context, namespace=namespace, parameter_overrides=[
            Parameter('min_area_px', value=50.0), Parameter('max_area_px', value=10.0)])


def test_virtual_camera_stamps_frames_at_exact_shutter_times(context, namespace):
    epoch = time.time_ns() + 100_000_000
    camera = VirtualCameraNode(context=context, namespace=namespace, parameter_overrides=[
        Parameter('epoch_ns', value=epoch), Parameter('phase_s', value=0.005),
        Parameter('fps', value=30.0), Parameter('scenario', value='turntable'),
        Parameter('ground_truth_topic', value='ball/ground_truth')])
    harness = Harness(context, namespace, camera)
    images, infos, truths = [], [], []
    harness.probe.create_subscription(Image, 'image_raw', images.append, qos_profile_sensor_data)
    harness.probe.create_subscription(CameraInfo, 'camera_info', infos.append,
                                      qos_profile_sensor_data)
    harness.probe.create_subscription(PointStamped, 'ball/ground_truth', truths.append, 50)
    try:
        assert harness.spin_until(lambda: len(images) >= 6 and len(truths) >= 6, 5.0)
        harness.spin_for(0.02)
    finally:
        harness.close()
    stamps = [stamp_to_ns(m.header.stamp) for m in images]
    indices = [round((s - epoch - 5_000_000) * 30 / 1e9) for s in stamps]
    assert stamps == [epoch + 5_000_000 + round(k * 1e9 / 30) for k in indices]
    assert indices == list(range(indices[0], indices[0] + len(indices)))
    assert set(stamps) <= {stamp_to_ns(m.header.stamp) for m in infos} | {stamps[-1]}
    truth_by_stamp = {point_to_xyz(m)[0]: point_to_xyz(m)[1:] for m in truths}
    scenario = make_scenario('turntable')
    for msg, stamp in zip(images, stamps):
        expected = truth_at(scenario, [stamp], epoch_ns=epoch)[0]
        np.testing.assert_allclose(truth_by_stamp[stamp], expected, atol=1e-12)
        assert msg.encoding == 'bgr8' and (msg.width, msg.height) == (640, 480)
    pixels = image_to_array(images[-1])
    assert pixels.shape == (480, 640, 3)


def test_monitor_keeps_only_the_newest_max_history_entries(context, namespace):
    # A monitor left running must not grow without bound: every store keeps its newest entries.
    limit = 5
    cameras, run, observations = _observations()
    paper, _ = fuse(cameras, observations)
    naive, _ = fuse(cameras, observations, method='naive')
    monitor = MonitorNode(context=context, namespace=namespace, parameter_overrides=[
        Parameter('max_history', value=limit), Parameter('report_period_s', value=0.0)])
    harness = Harness(context, namespace, monitor)
    try:
        points = {name: harness.probe.create_publisher(PointStamped, f'{name}/ball/image_point',
                                                       500) for name in ('camera1', 'camera2')}
        position = harness.probe.create_publisher(PointStamped, 'ball/position', 500)
        truth = harness.probe.create_publisher(PointStamped, '/ball/ground_truth', 500)
        assert harness.spin_until(lambda: all(p.get_subscription_count() for p in
                                              [*points.values(), position, truth]))
        for count, observation in enumerate(observations, 1):
            points[observation.camera].publish(observation_to_point(observation))
            assert harness.spin_until(lambda: sum(
                monitor.counts[f'{name}/ball/image_point'] for name in points) >= count)
        true_points = truth_at(run, [e.stamp_ns for e in paper])
        for estimate, true_point in zip(paper, true_points):
            truth.publish(estimate_to_point(estimate._replace(x=true_point[0], y=true_point[1],
                                                              z=true_point[2]), 'world'))
            position.publish(estimate_to_point(estimate, 'world'))
        assert harness.spin_until(lambda: monitor.counts['ball/position'] >= len(paper)
                                  and paper[-1].stamp_ns in monitor.truth)
        summary = monitor.summary()
    finally:
        harness.close()
    assert len(paper) > 10 * limit and len(naive) > 10 * limit
    newest = [e.stamp_ns for e in paper[-limit:]]
    assert list(monitor.paper) == newest
    assert list(monitor.truth) == newest
    assert list(monitor.naive_estimates) == [e.stamp_ns for e in naive[-limit:]]
    assert len(monitor.latency_ns) == limit and len(monitor.point_latency_ns) == limit
    assert summary['matched'] == {'paper': limit, 'naive': limit}
    assert summary['positions'] == len(paper)  # counts (rates) still cover the whole run
    # The error is the mean over the kept (newest) estimates only.
    expected_mm = 1e3 * np.linalg.norm(
        [(e.x, e.y, e.z) for e in paper[-limit:]] - true_points[-limit:], axis=1).mean()
    assert summary['error_mm']['paper'] == pytest.approx(expected_mm, rel=1e-9)


def test_monitor_rejects_max_history_below_one(context, namespace):
    with pytest.raises(InvalidParameterValueException, match='max_history'):
        MonitorNode(context=context, namespace=namespace,
                    parameter_overrides=[Parameter('max_history', value=0)])


@pytest.mark.parametrize('throttle_s, logged', [(1000.0, 1), (0.0, 3)])
def test_detector_throttles_the_bad_image_error(context, namespace, throttle_s, logged):
    detector = DetectorNode(context=context, namespace=namespace, parameter_overrides=[
        Parameter('error_throttle_s', value=throttle_s)])
    errors = []

    class Logger:
        def error(self, text):
            errors.append(text)

    detector.get_logger = Logger
    harness = Harness(context, namespace, detector)
    try:
        publisher, _ = _image_publisher(harness)
        for _ in range(3):
            publisher.publish(Image(encoding='bgr8'))  # empty
        assert harness.spin_until(lambda: detector.stats['bad_image'] == 3)
    finally:
        harness.close()
    # One line per throttle period, with the running count; every image is counted.
    assert len(errors) == logged
    assert errors[0].startswith('image dropped: empty image') and '(1 so far)' in errors[0]


def _number(text):
    try:
        return float(text)
    except ValueError:
        return text  # a status word (e.g. a time offset's 'no estimate yet')


def _diagnostics(msg, name):
    """Return the values of the status of node ``name`` in a DiagnosticArray, or None."""
    for status in msg.status:
        if status.name.startswith(f'{name}: '):
            return status, {item.key: _number(item.value) for item in status.values}
    return None


def _drops(values):
    return sum(value for key, value in values.items() if key.startswith('dropped: '))


def _late(values):
    """Return the values of every diagnostics key about late points."""
    return [value for key, value in values.items() if 'late' in key]


def _feed_and_report(context, namespace, points, overrides=()):
    """
    Feed ``points`` to a new fuser node; return it, the positions and its last full report.

    The report is the fuser's /diagnostics values once it has counted every point
    (``points`` may hold ``(camera, bytes)`` items: published as they are, not points).
    """
    count = sum(isinstance(point, Observation) for point in points)
    name = f'fuser{next(_COUNTER)}'  # /diagnostics is global: a name of this test's own
    fuser = FuserNode(context=context, namespace=namespace, node_name=name, parameter_overrides=[
        Parameter('diagnostics_period_s', value=0.05), *overrides])
    harness = Harness(context, namespace, fuser)
    reports = []
    harness.probe.create_subscription(DiagnosticArray, '/diagnostics',
                                      lambda msg: reports.append(_diagnostics(msg, name)), 10)
    try:
        received = _positions_subscription(harness)
        _feed_points(harness, points, received)
        assert harness.spin_until(lambda: any(
            r and r[1]['observations'] == count for r in reports))
    finally:
        harness.close()
    _, values = next(r for r in reports if r and r[1]['observations'] == count)
    return fuser, received, values


def test_fuser_publishes_diagnostics_and_the_trail_marker(context, namespace):
    cameras, _, observations = _observations()
    name = f'fuser{next(_COUNTER)}'  # /diagnostics is global: a name of this test's own
    fuser = FuserNode(context=context, namespace=namespace, node_name=name, parameter_overrides=[
        Parameter('diagnostics_period_s', value=0.05), Parameter('marker_period_s', value=0.05),
        Parameter('trail_length', value=20)])
    harness = Harness(context, namespace, fuser)
    reports, markers = [], []
    harness.probe.create_subscription(DiagnosticArray, '/diagnostics',
                                      lambda msg: reports.append(_diagnostics(msg, name)), 10)
    harness.probe.create_subscription(Marker, 'ball/marker', markers.append, 10)
    expected, _ = fuse(cameras, observations)
    try:
        received = _positions_subscription(harness)
        _feed_points(harness, observations, received)
        assert harness.spin_until(
            lambda: any(r and r[1]['estimates'] == len(expected) for r in reports)
            and any(stamp_to_ns(m.header.stamp) == expected[-1].stamp_ns for m in markers))
    finally:
        harness.close()
    status, values = next(r for r in reports if r and r[1]['estimates'] == len(expected))
    assert status.level == DiagnosticStatus.OK
    assert values['observations'] == len(observations)
    # Every observation gives an estimate or exactly one drop reason.
    assert values['estimates'] + _drops(values) == len(observations)
    assert _late(values) == [0]
    # The node's own work per point (callback -> published) in each period with points.
    key = 'point received -> published {} [ms]'
    timed = [v for _, v in filter(None, reports) if key.format('p50') in v]
    assert timed
    assert all(0 < v[key.format('p50')] <= v[key.format('p99')] <= v[key.format('max')]
               for v in timed)
    # The periods' maxima are the node's own measurement: their largest is the run's largest.
    assert max(v[key.format('max')] for v in timed) == pytest.approx(
        max(fuser.processing_times_s) * 1e3, rel=1e-5)
    # Camera 2's shutter is 1/60 s after camera 1's, camera 1's next 1/60 s after that.
    for key in ('camera1->camera2', 'camera2->camera1'):
        assert values[f'delta {key} mean [ms]'] == pytest.approx(1e3 / 60, abs=1e-3)
    marker = next(m for m in markers if stamp_to_ns(m.header.stamp) == expected[-1].stamp_ns)
    assert marker.header.frame_id == 'world' and marker.type == Marker.LINE_STRIP
    np.testing.assert_allclose([(p.x, p.y, p.z) for p in marker.points],
                               [(e.x, e.y, e.z) for e in expected[-20:]], rtol=0, atol=1e-9)


def test_fuser_counts_a_late_point_once_with_the_default_window(context, namespace):
    cameras, run, observations = _observations()
    # Camera 2's point of one event arrives after camera 1's next one (a slower detector).
    k = next(i for i in range(len(observations) // 2, len(observations) - 1)
             if observations[i].camera == 'camera2' and observations[i + 1].camera == 'camera1')
    late = observations[k]
    arrival = observations[:k] + [observations[k + 1], late] + observations[k + 2:]
    fuser, received, values = _feed_and_report(context, namespace, arrival)
    assert fuser.buffer.window_ns == 0
    assert values['estimates'] + _drops(values) == len(arrival)  # not counted as a drop
    assert _late(values) == [1]  # and reported once
    assert values['estimates'] == len(received)
    # Not dropped: estimated at its own event, as close to the truth as the other estimates.
    expected, _ = fuse(cameras, observations)
    assert sorted(r[0] for r in received) == [e.stamp_ns for e in expected]
    errors = {r[0]: np.linalg.norm(np.subtract(r[1:], truth_at(run, [r[0]])[0]))
              for r in received}
    assert errors[late.stamp_ns] <= max(errors.values())
    assert errors[late.stamp_ns] < 0.005


def test_fuser_starts_a_new_session_when_a_replay_loops(context, namespace):
    cameras, _, observations = _observations()
    looped = observations + observations  # the bag played twice: stamps jump back
    _, received, values = _feed_and_report(context, namespace, looped)
    expected, _ = fuse(cameras, observations)
    assert [r[0] for r in received] == [e.stamp_ns for e in expected] * 2
    np.testing.assert_allclose([r[1:] for r in received],
                               [(e.x, e.y, e.z) for e in expected] * 2, rtol=0, atol=1e-9)
    # A new session, not a second pass of late points; the timing statistics stay right.
    assert _late(values) == [0]
    assert values['new sessions (time jumped or paused)'] == 1
    assert values['delta camera1->camera2 mean [ms]'] == pytest.approx(1e3 / 60, abs=1e-3)


def test_fuser_node_drops_one_bad_stamp_without_a_new_session(context, namespace):
    # One point stamped 0 (a camera's bad stamp) used to start a new session and lose the next
    # estimates; the core decides it is that camera's outlier, and the node asks the core.
    cameras, _, observations = _observations()
    k = len(observations) // 2
    faulty = observations[:k] + [observations[k]._replace(stamp_ns=0)] + observations[k:]
    fuser, received, values = _feed_and_report(context, namespace, faulty, [
        Parameter('image_margin', value=0.2), Parameter('max_speed_mps', value=30.0),
        Parameter('workspace_min_m', value=[-5.0, -5.0, -1.0]),
        Parameter('workspace_max_m', value=[5.0, 5.0, 4.0])])
    expected, _ = fuse(cameras, observations)
    assert [r[0] for r in received] == [e.stamp_ns for e in expected]
    assert values['dropped: stamp_outlier'] == 1
    assert values['estimates'] + _drops(values) == len(faulty)
    # The node's parameters reach the core.
    assert fuser.fuser.gate.image_margin == 0.2
    assert fuser.fuser.plausibility.max_speed_mps == 30.0
    assert fuser.fuser.plausibility.workspace_max_m == (5.0, 5.0, 4.0)


def test_fuser_node_drops_malformed_messages_and_counts_them(context, namespace):
    # The fuser takes its points as raw bytes (messages.decode_point): bytes that are not a
    # PointStamped are dropped and counted, the node keeps fusing the others.
    cameras, _, observations = _observations()
    good = serialize_message(observation_to_point(observations[0]))
    garbage = [b'\0\1\0\0' + b'x' * 5, b'\xff' * 60, good[:30]]
    k = len(observations) // 2
    points = observations[:k] + [('camera1', data) for data in garbage] + observations[k:]
    fuser, received, values = _feed_and_report(context, namespace, points)
    expected, _ = fuse(cameras, observations)
    assert [r[0] for r in received] == [e.stamp_ns for e in expected]
    np.testing.assert_allclose([r[1:] for r in received], [(e.x, e.y, e.z) for e in expected],
                               rtol=0, atol=1e-9)
    assert fuser.node_stats['malformed'] == values['dropped: malformed message'] == 3
    assert values['estimates'] + _drops(values) - 3 == len(observations)


def test_fuser_node_reports_every_drop_reason_of_its_method(context, namespace):
    # A sixth of the detections 0-80 px off: trajectory drops some as 'pending' (a detection
    # waiting in the place of one judged stray), a reason of its own that the paper method
    # lacks. The diagnostics listed only the paper method's reasons, so these went missing
    # and the counts stopped adding up.
    cameras, _, observations = _observations()
    rng = np.random.default_rng(5)
    for k in rng.choice(len(observations), len(observations) // 6, replace=False):
        o = observations[k]
        observations[k] = o._replace(u=o.u + rng.uniform(-80, 80), v=o.v + rng.uniform(-80, 80))
    fuser, received, values = _feed_and_report(context, namespace, observations, [
        Parameter('method', value='trajectory')])
    assert fuser.fuser.stats['pending'] >= 1
    assert values['dropped: pending'] == fuser.fuser.stats['pending']
    assert values['estimates'] + _drops(values) == len(observations)
    assert values['estimates'] == len(received)


@pytest.mark.parametrize('depth', [None, 7])
def test_fuser_qos_depth_reaches_its_subscriptions(context, namespace, depth):
    overrides = [] if depth is None else [Parameter('qos_depth', value=depth)]
    fuser = FuserNode(context=context, namespace=namespace, parameter_overrides=overrides)
    try:
        depths = {s.topic_name: s.qos_profile.depth for s in fuser.subscriptions
                  if s.topic_name.endswith('/ball/image_point')}
    finally:
        fuser.destroy_node()
    assert len(depths) == 2
    assert set(depths.values()) == {INPUT_QUEUE_DEPTH if depth is None else depth}


def test_fuser_node_survives_a_method_that_fails_on_a_point(context, namespace):
    # A bug in a method (an exception from update) must not end the node: that point is
    # dropped and counted, the others are fused.
    cameras, _, observations = _observations()
    fuser = FuserNode(context=context, namespace=namespace)
    bad_stamp = observations[len(observations) // 2].stamp_ns
    update = fuser.fuser.update

    def failing(observation):
        if observation.stamp_ns == bad_stamp:
            raise IndexError('index 256 is out of bounds')
        return update(observation)

    fuser.fuser.update = failing
    harness = Harness(context, namespace, fuser)
    try:
        received = _positions_subscription(harness)
        _feed_points(harness, observations, received)
        harness.spin_for(0.05)
    finally:
        harness.close()
    assert fuser.node_stats['internal_error'] == 1
    stamps = [r[0] for r in received]
    assert bad_stamp not in stamps and stamps == sorted(stamps)
    assert len(received) >= len(observations) - 5  # all but the warm-up and the failed point


def test_bringup_real_refuses_the_simulated_calibration(capsys, tmp_path):
    # --real is the device source: each camera needs its device (none here: retried).
    assert bringup.main(['--real', '--duration', '2']) == 2
    assert 'source device needs its device' in capsys.readouterr().err
    devices = ['--real', '--camera', 'camera1=/dev/video_none1', '--camera',
               'camera2=/dev/video_none2']
    assert bringup.main(devices + ['--duration', '2']) == 1  # before: ran on the sim rig
    assert "need the real cameras' calibrations" in capsys.readouterr().err
    assert bringup.main(devices + ['--calibration', 'camera1=a.yaml']) == 2
    assert 'none for camera2' in capsys.readouterr().err
    assert bringup.main(devices + ['--calibration', 'camera3=a.yaml']) == 2
    assert 'not one of the cameras' in capsys.readouterr().err
    # Given per camera (here: files of another rig), the fuser starts with them.
    rig = [str(tmp_path / f'{name}.yaml') for name in ('camera1', 'camera2')]
    for camera, path in zip(default_rig(), rig):
        save_calibration(camera.calibration, path)
    broken = tmp_path / 'broken.yaml'
    broken.write_text('camera_name: [x\n')
    assert bringup.main(devices + ['--calibration', f'camera1={rig[0]}',
                                   '--calibration', f'camera2={broken}']) == 1
    assert 'calibration_files[1] (camera camera2)' in capsys.readouterr().err
    assert bringup.main(devices + ['--calibration', f'camera1={rig[0]}',
                                   '--calibration', f'camera2={rig[1]}', '--duration',
                                   '0.01']) == 0


def test_bringup_reports_a_malformed_params_file_in_one_line(capfd, tmp_path):
    bad = tmp_path / 'bad.yaml'
    bad.write_text('/**/fuser:\n  ros__parameters:\n    method: [paper\n')
    assert bringup.main(['--params-file', str(bad)]) == 1
    err = capfd.readouterr().err
    assert 'cannot start' in err and 'bad.yaml' in err and 'Traceback' not in err


# -- issue 12: camera names that are not ROS names stop a node with one line --------------------


def _rig_files():
    from pseudo_stereo_ros.rig import config_dir
    return [str(config_dir() / 'rig' / f'{name}.yaml') for name in ('camera1', 'camera2')]


@pytest.mark.parametrize('name', ['cam-1', 'cam 1', '22276213'])
def test_fuser_refuses_camera_names_that_are_not_ros_names(context, namespace, name):
    # Before: rclpy's InvalidTopicNameException (26 lines) from create_subscription.
    overrides = [Parameter('camera_names', value=[name, 'camera2']),
                 Parameter('calibration_files', value=_rig_files())]
    with pytest.raises(StartupError) as info:
        FuserNode(namespace=namespace, context=context, parameter_overrides=overrides)
    message = str(info.value)
    assert message.startswith('parameter camera_names: ') and '\n' not in message
    assert f'{name!r} is not a valid ROS name' in message


def test_monitor_refuses_camera_names_that_are_not_ros_names(context, namespace):
    overrides = [Parameter('camera_names', value=['camera1', 'cam-2']),
                 Parameter('compare_naive', value=False)]
    with pytest.raises(StartupError,
                       match="parameter camera_names: camera name 'cam-2' is not a valid"):
        MonitorNode(namespace=namespace, context=context, parameter_overrides=overrides)


@pytest.mark.parametrize('cameras', [['22276213', '22276209'], ['cam 1', 'cam2']])
def test_bringup_refuses_camera_names_that_are_not_ros_names(capsys, cameras):
    # Before: rclpy's InvalidNamespaceException from the first virtual camera node.
    assert bringup.main(['--cameras', *cameras, '--duration', '0.01']) == 2
    err = capsys.readouterr().err
    assert err.startswith('bringup: error: --cameras: ') and err.count('\n') == 1, err
    assert f'{cameras[0]!r} is not a valid ROS name' in err


def test_the_camera_name_rule_is_stricter_than_rcl():
    # Every name the core accepts is a valid namespace and image point topic for rclpy; the core
    # refuses only what rclpy refuses, plus a leading underscore (hidden topics), a '/' (one
    # token), names over 100 characters and '' (the root namespace for rclpy, no name here).
    import random

    from pseudo_stereo_ros.errors import RigError
    from pseudo_stereo_ros.rig import check_camera_name
    from rclpy.exceptions import NameValidationException
    from rclpy.validate_namespace import validate_namespace
    from rclpy.validate_topic_name import validate_topic_name

    def rcl_accepts(name):
        try:
            validate_namespace(f'/{name}')
            validate_topic_name(f'{name}/ball/image_point')
        except NameValidationException:
            return False
        return True

    rng = random.Random(12)
    names = [''.join(rng.choice('aZ9_-/ .é~{}0') for _ in range(rng.randrange(0, 6)))
             for _ in range(3000)] + ['a' * 100, 'a' * 101]
    accepted = 0
    for name in names:
        try:
            check_camera_name(name)
            ours = True
        except RigError:
            ours = False
        rcl = rcl_accepts(name)
        assert not ours or rcl, name
        assert ours or not rcl or not name or name.startswith('_') or '/' in name \
            or len(name) > 100, name
        accepted += ours
    assert accepted > 100
