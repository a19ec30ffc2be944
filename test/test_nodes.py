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

from geometry_msgs.msg import PointStamped
import numpy as np
from pseudo_stereo_ros.calibration import CalibrationError, save_calibration
from pseudo_stereo_ros.detector_node import DetectorNode
from pseudo_stereo_ros.fuser_node import FuserNode
from pseudo_stereo_ros.fusion import fuse
from pseudo_stereo_ros.messages import (array_to_image, image_to_array, observation_to_point,
                                        point_to_xyz, stamp_to_ns)
from pseudo_stereo_ros.node_tools import StartupError
from pseudo_stereo_ros.rendering import BallRenderer
from pseudo_stereo_ros.simulation import (DEFAULT_EPOCH_NS, default_rig, make_scenario, observe,
                                          shutter_stamps, truth_at)
from pseudo_stereo_ros.virtual_camera_node import VirtualCameraNode
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import CameraInfo, Image

_COUNTER = itertools.count()


@pytest.fixture
def context():
    """Yield an rclpy context of this test only."""
    ctx = rclpy.Context()
    rclpy.init(args=[], context=ctx)
    yield ctx
    rclpy.try_shutdown(context=ctx)


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
    for count, observation in enumerate(observations, 1):
        publishers[observation.camera].publish(observation_to_point(observation))
        if not burst:
            assert harness.spin_until(lambda: fuser.fuser.stats['observations'] >= count)
    assert harness.spin_until(lambda: fuser.fuser.stats['observations'] >= len(observations))
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
    ([Parameter('method', value='best')], 'method'),
    ([Parameter('calibration_files', value=['a.yaml'])], 'calibration_files'),
    ([Parameter('sync_tolerance_s', value=0.2)], 'max_gap'),
])
def test_fuser_rejects_bad_parameters(context, namespace, overrides, match):
    with pytest.raises(StartupError, match=match):
        FuserNode(context=context, namespace=namespace, parameter_overrides=overrides)


def test_fuser_rejects_a_malformed_calibration_file(context, namespace, tmp_path):
    good = tmp_path / 'camera1.yaml'
    bad = tmp_path / 'camera2.yaml'
    save_calibration(default_rig()[0].calibration, good)
    bad.write_text('camera_name: camera2\nimage_width: 640\nimage_height: 480\n')
    with pytest.raises(CalibrationError, match="camera2.yaml: key 'camera_matrix'"):
        FuserNode(context=context, namespace=namespace, parameter_overrides=[
            Parameter('calibration_files', value=[str(good), str(bad)])])


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
        # Wrong encoding: dropped, counted, and the node keeps working.
        bad = Image(header=image.header, height=480, width=640, encoding='16UC1', step=1280)
        bad.data = bytes(1280 * 480)
        publisher.publish(bad)
        assert harness.spin_until(lambda: detector.stats['bad_image'] == 1)
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
    assert detector.stats['images'] == 4 and detector.stats['published'] == 2


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
