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

"""The replay and record executables: in-process playback, and record stopped mid-recording."""

import os
from pathlib import Path
import signal
import subprocess
import sys
import time

from pseudo_stereo_ros.bagio import read_observations, write_observations
from pseudo_stereo_ros.fusion import Observation
from pseudo_stereo_ros.replay_node import ReplayNode
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile

from geometry_msgs.msg import PointStamped  # noqa: I100 - message packages after rclpy
from rosgraph_msgs.msg import Clock

LFG = Path(__file__).resolve().parent / 'data' / 'lfg_table_tennis'
BIN = Path(sys.executable).parent


@pytest.fixture
def context():
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    yield ctx
    rclpy.try_shutdown(context=ctx)


def _small_bag(tmp_path, count=40):
    observations = sorted(read_observations(LFG / 'n3_p1_v14'), key=lambda o: o.stamp_ns)
    observations = observations[:count]
    write_observations(tmp_path / 'small', observations)
    return tmp_path / 'small', observations


def test_replay_in_process(tmp_path, context):
    """Header stamps and points come out as recorded, remapped, in order, with /clock."""
    bag, observations = _small_bag(tmp_path)
    namespace = f'/t{os.getpid()}'
    replay = ReplayNode(context=context, parameter_overrides=[
        rclpy.parameter.Parameter('bag', value=str(bag)),
        rclpy.parameter.Parameter('rate', value=20.0),
        rclpy.parameter.Parameter('topics', value=['/camera_1/ball/image_point',
                                                   '/camera_2/ball/image_point']),
        rclpy.parameter.Parameter('remap', value=[
            f'/camera_1/ball/image_point:={namespace}/a',
            f'/camera_2/ball/image_point:={namespace}/b']),
        rclpy.parameter.Parameter('wait_for_subscribers_s', value=5.0),
    ])
    listener = rclpy.create_node('listener', context=context)
    received, clocks = [], []
    for name, camera in (('a', 'camera_1'), ('b', 'camera_2')):
        listener.create_subscription(
            PointStamped, f'{namespace}/{name}',
            lambda msg, c=camera: received.append(Observation(
                c, msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec,
                msg.point.x, msg.point.y)), QoSProfile(depth=100))
    listener.create_subscription(Clock, '/clock', clocks.append, QoSProfile(depth=100))
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(replay)
    executor.add_node(listener)
    expected = [o for o in observations if o.camera != 'camera_3']
    deadline = time.monotonic() + 20.0
    while time.monotonic() < deadline and len(received) < len(expected):
        executor.spin_once(timeout_sec=0.05)
    for _ in range(10):
        executor.spin_once(timeout_sec=0.01)
    assert replay.finished.wait(5.0)
    executor.shutdown()
    replay.destroy_node()
    listener.destroy_node()
    # Each topic in order (the executor may interleave two topics' callbacks differently).
    for camera in ('camera_1', 'camera_2'):
        assert ([o for o in received if o.camera == camera]
                == [o for o in expected if o.camera == camera])
    assert len(clocks) >= len(expected)
    clock_ns = [c.clock.sec * 1_000_000_000 + c.clock.nanosec for c in clocks]
    assert clock_ns == sorted(clock_ns)
    assert clock_ns[0] == expected[0].stamp_ns


def test_replay_bad_bag_exits_non_zero(tmp_path):
    bad = tmp_path / 'bad.mcap'
    bad.write_bytes(b'not a bag' * 10)
    result = subprocess.run([str(BIN / 'replay'), '--ros-args', '-p', f'bag:={bad}'],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 1
    assert 'not a readable ROS 2 bag' in result.stderr
    assert 'Traceback' not in result.stderr


@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM])
def test_record_stopped_mid_recording_keeps_everything(tmp_path, context, sig):
    """Every message the recorder acknowledged is in the bag; the bag opens after the signal."""
    topic = f'/rec{os.getpid()}/ball/image_point'
    camera = topic.split('/')[1]
    out = tmp_path / 'recorded'
    recorder = subprocess.Popen(
        [str(BIN / 'record'), '--ros-args', '-p', f'bag:={out}', '-p', f'topics:=[{topic}]',
         '-p', 'types:=[geometry_msgs/msg/PointStamped]'],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    node = rclpy.create_node('feeder', context=context)
    publisher = node.create_publisher(PointStamped, topic, QoSProfile(depth=1000))
    try:
        deadline = time.monotonic() + 20.0
        while publisher.get_subscription_count() == 0 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert publisher.get_subscription_count() == 1, 'the recorder did not subscribe'

        def publish(k):
            msg = PointStamped()
            msg.header.stamp.sec, msg.header.stamp.nanosec = 1_721_679_791, k * 1000
            msg.header.frame_id = camera
            msg.point.x, msg.point.y = float(k), 0.5 * k
            publisher.publish(msg)

        acked = 200
        for k in range(acked):
            publish(k)
        assert publisher.wait_for_all_acked(rclpy.duration.Duration(seconds=10.0))
        # Keep publishing while the recorder is stopped: it is mid-recording.
        sent = acked
        stop_at = time.monotonic() + 0.3
        signalled = False
        while time.monotonic() < stop_at + 0.3:
            publish(sent)
            sent += 1
            if not signalled and time.monotonic() > stop_at:
                recorder.send_signal(sig)
                signalled = True
            time.sleep(0.002)
        output, _ = recorder.communicate(timeout=30)
    finally:
        if recorder.poll() is None:
            recorder.kill()
        node.destroy_node()
    assert recorder.returncode == 0, output
    assert 'Traceback' not in output
    recorded = read_observations(out, [camera])
    indices = [int(o.u) for o in recorded]
    # Every acknowledged message, then a contiguous run of the later ones, nothing invented.
    assert indices == list(range(len(indices)))
    assert acked <= len(indices) <= sent
