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
Live: replay -> detector nodes -> fuser node gives what offline ``track --bag`` gives.

All nodes run in this process with one context and one executor (images
then never cross a DDS transport, so none is lost to fragmentation).  The
replay plays the synthetic image bag at its recorded rate: one frame every
16.7 ms, far more than a detection takes, so the detectors see every frame
in order and the fuser's reorder window only guards the hand-over.
"""

import os
from pathlib import Path
import time

import numpy as np
from pseudo_stereo_ros.cli.main import main
from pseudo_stereo_ros.formats.bagio import read_positions
from pseudo_stereo_ros.ros.detector_node import DetectorNode
from pseudo_stereo_ros.ros.fuser_node import FuserNode
from pseudo_stereo_ros.ros.messages import point_to_xyz
from pseudo_stereo_ros.ros.replay_node import ReplayNode
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter

from geometry_msgs.msg import PointStamped  # noqa: I100 - message packages after rclpy

SYNTHETIC = Path(__file__).resolve().parent / 'data' / 'synthetic_images'
BAG = SYNTHETIC / 'spiral'
CAMERAS = ('camera1', 'camera2')


def _spin_until(executor, predicate, timeout_s):
    deadline = time.monotonic() + timeout_s
    while not predicate() and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.01)
    return predicate()


def test_replay_through_detectors_and_fuser_equals_offline_track(tmp_path, context):
    offline_bag = tmp_path / 'offline'
    assert main(['track', '--bag', str(BAG), '--output-bag', str(offline_bag),
                 *[arg for name in CAMERAS
                   for arg in ('--camera', f'{name}={SYNTHETIC / f"{name}.yaml"}')]]) == 0
    expected = read_positions(offline_bag)
    assert len(expected) >= 58

    namespace = f'/live{os.getpid()}'
    fuser = FuserNode(context=context, namespace=namespace, parameter_overrides=[
        Parameter('camera_names', value=list(CAMERAS)),
        Parameter('calibration_files', value=[str(SYNTHETIC / f'{n}.yaml') for n in CAMERAS]),
        Parameter('reorder_window_s', value=0.05)])
    detectors = [DetectorNode(context=context, namespace=f'{namespace}/{name}')
                 for name in CAMERAS]
    probe = rclpy.create_node('probe', namespace=namespace, context=context)
    received = []
    probe.create_subscription(PointStamped, 'ball/position',
                              lambda msg: received.append(point_to_xyz(msg)), 500)
    executor = SingleThreadedExecutor(context=context)
    nodes = [fuser, *detectors, probe]
    for node in nodes:
        executor.add_node(node)
    replay = None
    try:
        # Every link of the chain is matched before the first frame goes out.
        assert _spin_until(executor, lambda: all(
            probe.count_subscribers(f'{namespace}/{name}/ball/image_point') >= 1
            for name in CAMERAS) and probe.count_publishers(f'{namespace}/ball/position') >= 1,
            10.0)
        replay = ReplayNode(context=context, parameter_overrides=[
            Parameter('bag', value=str(BAG)),
            Parameter('topics', value=[f'/{name}/image_raw' for name in CAMERAS]),
            Parameter('remap', value=[f'/{name}/image_raw:={namespace}/{name}/image_raw'
                                      for name in CAMERAS]),
            Parameter('publish_clock', value=False),
            Parameter('wait_for_subscribers_s', value=10.0)])
        executor.add_node(replay)
        nodes.append(replay)
        assert _spin_until(executor, lambda: replay.finished.is_set()
                           and len(received) >= len(expected), 30.0)
        _spin_until(executor, lambda: False, 0.1)  # nothing more may come
    finally:
        executor.shutdown()
        for node in nodes:
            node.destroy_node()

    assert replay.published == 61 and replay.dropped == 0
    assert [d.stats['images'] for d in detectors] == [31, 30]
    assert [d.stats['published'] for d in detectors] == [31, 30]
    assert fuser.buffer.stats['late'] == 0
    assert [r[0] for r in received] == [e[0] for e in expected]
    np.testing.assert_allclose([r[1:] for r in received], [e[1:] for e in expected],
                               rtol=0, atol=1e-9)
