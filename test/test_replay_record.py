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
import queue
import re
import signal
import subprocess
import sys
import threading
import time

import numpy as np
from pseudo_stereo_ros.formats.bagio import (bag_message_counts, image_message, IMAGE_TYPE,
                                             iter_raw, point_message, read_observations,
                                             write_messages, write_observations)
from pseudo_stereo_ros.records import Observation
from pseudo_stereo_ros.ros import replay_node
from pseudo_stereo_ros.ros.record_node import RecordNode
from pseudo_stereo_ros.ros.replay_node import ReplayNode
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import qos_profile_sensor_data, QoSProfile

from geometry_msgs.msg import PointStamped  # noqa: I100 - message packages after rclpy
from rosgraph_msgs.msg import Clock

LFG = Path(__file__).resolve().parent / 'data' / 'lfg_table_tennis'
BIN = Path(sys.executable).parent


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
    # One /clock message goes out before each message: wait for both kinds, not for a time.
    while (time.monotonic() < deadline
           and (len(received) < len(expected) or len(clocks) < len(expected))):
        executor.spin_once(timeout_sec=0.05)
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


def _lines(process):
    """Return a queue that receives the process's output lines (read on a thread)."""
    lines = queue.Queue()

    def read():
        for line in process.stdout:
            lines.put(line)
        lines.put(None)
    threading.Thread(target=read, daemon=True).start()
    return lines


def _wait_for_line(lines, pattern, seen, timeout_s=30.0):
    """Collect lines into ``seen`` until one matches; return the match (None at EOF/time-out)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            line = lines.get(timeout=max(0.0, deadline - time.monotonic()))
        except queue.Empty:
            return None
        if line is None:
            return None
        seen.append(line)
        match = re.search(pattern, line)
        if match:
            return match
    return None


def test_replay_bad_params_file_exits_1_with_one_line(tmp_path):
    params = tmp_path / 'bad.yaml'
    params.write_text('/**/replay:\n  ros__parameters:\n    rate: [2.0\n')
    result = subprocess.run([str(BIN / 'replay'), '--ros-args', '--params-file', str(params)],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 1
    assert 'Traceback' not in result.stderr
    # rcl logs its own line first; ours names the file.
    ours = [line for line in result.stderr.splitlines() if '[replay]' in line]
    assert len(ours) == 1 and 'cannot start' in ours[0] and str(params) in ours[0], result.stderr


def _points_bag(path, count, period_ns):
    stamp0 = 1_721_679_791_000_000_000
    write_messages(path, (('/cam/ball/image_point', 'geometry_msgs/msg/PointStamped',
                           stamp0 + k * period_ns, point_message(stamp0 + k * period_ns, 'cam',
                                                                 float(k), 0.0, 0.0))
                          for k in range(count)))
    return path


@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM])
def test_replay_stopped_mid_playback_exits_cleanly(tmp_path, sig):
    """Ctrl-C or SIGTERM while the worker publishes: exit 0, a summary, no traceback."""
    bag = _points_bag(tmp_path / 'long', 600, 50_000_000)  # 30 s of playback
    replay = subprocess.Popen(
        [str(BIN / 'replay'), '--ros-args', '-p', f'bag:={bag}',
         '-p', 'wait_for_subscribers_s:=0.0'],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    seen = []
    try:
        lines = _lines(replay)
        assert _wait_for_line(lines, r'playing .*: 600 messages', seen), ''.join(seen)
        replay.send_signal(sig)
        replay.wait(timeout=30)
        _wait_for_line(lines, r'(?!)', seen)  # the rest of the output, up to its end
    finally:
        if replay.poll() is None:
            replay.kill()
    output = ''.join(seen)
    assert replay.returncode == 0, output
    # (rcl may add 'Failed to publish log message to rosout' when a log line races the
    # signal: that is not an error of the replay.)
    assert 'Traceback' not in output and 'RCLError' not in output, output
    played = re.search(r'played (\d+) messages', output)
    assert played and int(played.group(1)) < 600, output


def _damaged_in_the_second_chunk(path):
    """Write a bag of three 600 kB images (two mcap chunks); break the second chunk's CRC."""
    stamp0 = 1_721_679_791_000_000_000
    pixels = np.zeros((1, 600_000), np.uint8)
    write_messages(path, (('/cam/image_raw', IMAGE_TYPE, stamp0 + k * 10_000_000,
                           image_message(stamp0 + k * 10_000_000, 'cam', pixels, 'mono8'))
                          for k in range(3)))
    mcap = next(Path(path).glob('*.mcap'))
    data = bytearray(mcap.read_bytes())
    offset, chunks = 8, []
    while offset + 9 <= len(data) and len(chunks) < 2:
        opcode, length = data[offset], int.from_bytes(data[offset + 1:offset + 9], 'little')
        if opcode == 0x06:
            chunks.append(offset)
        offset += 9 + length
    assert len(chunks) == 2, 'rosbags no longer starts a chunk after 1 MiB'
    # Chunk record: start, end, uncompressed size (3 x uint64), then the uint32 CRC (0 = none).
    data[chunks[1] + 9 + 24:chunks[1] + 9 + 28] = (12345).to_bytes(4, 'little')
    mcap.write_bytes(bytes(data))
    return path


def test_replay_damage_found_during_playback_exits_1(tmp_path):
    """Start-up reads the index only; damage found while playing stops it with status 1."""
    bag = _damaged_in_the_second_chunk(tmp_path / 'damaged')
    assert bag_message_counts(bag) == {'/cam/image_raw': (IMAGE_TYPE, 3)}
    result = subprocess.run(
        [str(BIN / 'replay'), '--ros-args', '-p', f'bag:={bag}', '-p',
         'wait_for_subscribers_s:=0.0'], capture_output=True, text=True, timeout=60)
    assert result.returncode == 1, result.stderr
    assert 'Traceback' not in result.stderr
    # It started (no "cannot start": the message data was not read at start-up) and played
    # the first chunk's two images before the damage.
    assert 'cannot start' not in result.stderr, result.stderr
    assert 'playback stopped' in result.stderr and 'checksum' in result.stderr, result.stderr
    assert 'played 2 messages' in result.stderr, result.stderr


def test_replay_start_up_reads_no_message(tmp_path, context, monkeypatch):
    bag, _ = _small_bag(tmp_path)
    taken = []

    def counting_iter_raw(*args, **kwargs):
        for item in iter_raw(*args, **kwargs):
            taken.append(item)
            yield item
    monkeypatch.setattr(replay_node, 'iter_raw', counting_iter_raw)
    # No subscriber: playback waits for one, so nothing after construction has read yet.
    replay = ReplayNode(context=context, parameter_overrides=[
        rclpy.parameter.Parameter('bag', value=str(bag)),
        rclpy.parameter.Parameter('wait_for_subscribers_s', value=60.0),
    ])
    try:
        assert taken == []
        assert replay.published == 0
    finally:
        replay.destroy_node()


def test_record_matches_best_effort_and_reliable_publishers(tmp_path, context):
    """
    Explicit types: a best-effort publisher that starts after the recorder is recorded.

    And on a topic first seen with a reliable publisher, a best-effort one that appears later
    is recorded too (the recorder subscribes again, best effort).
    """
    prefix = f'/be{os.getpid()}'
    late, mixed = f'{prefix}a/ball/image_point', f'{prefix}b/ball/image_point'
    feeder = rclpy.create_node('feeder', context=context)
    reliable = feeder.create_publisher(PointStamped, mixed, QoSProfile(depth=100))
    recorder = RecordNode(context=context, parameter_overrides=[
        rclpy.parameter.Parameter('bag', value=str(tmp_path / 'rec')),
        rclpy.parameter.Parameter('topics', value=[late, mixed]),
        rclpy.parameter.Parameter('types', value=['geometry_msgs/msg/PointStamped'] * 2),
    ])
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(recorder)
    executor.add_node(feeder)
    camera_pub = feeder.create_publisher(PointStamped, late, qos_profile_sensor_data)
    mixed_pub = feeder.create_publisher(PointStamped, mixed, qos_profile_sensor_data)
    publishers = {'late': camera_pub, 'reliable': reliable, 'mixed': mixed_pub}
    try:
        deadline = time.monotonic() + 20.0
        while (time.monotonic() < deadline
               and any(p.get_subscription_count() != 1 for p in publishers.values())):
            executor.spin_once(timeout_sec=0.05)
        assert {name: p.get_subscription_count() for name, p in publishers.items()} == {
            'late': 1, 'reliable': 1, 'mixed': 1}
        # Best effort may drop a message in theory: publish until enough arrived.
        sent = dict.fromkeys(publishers, 0)
        deadline = time.monotonic() + 20.0
        while time.monotonic() < deadline and min(recorder.counts.values()) < 20:
            for k, (name, publisher) in enumerate(publishers.items()):
                msg = PointStamped()
                msg.header.stamp.sec, msg.header.stamp.nanosec = 1_721_679_791, sent[name]
                msg.point.x, msg.point.y = float(sent[name]), float(k)
                publisher.publish(msg)
                sent[name] += 1
            executor.spin_once(timeout_sec=0.01)
    finally:
        executor.shutdown()
        recorder.destroy_node()
        feeder.destroy_node()
    camera_a, camera_b = late.split('/')[1], mixed.split('/')[1]
    sources = {(o.camera, int(o.v)) for o in read_observations(tmp_path / 'rec',
                                                               [camera_a, camera_b])}
    assert sources == {(camera_a, 0), (camera_b, 1), (camera_b, 2)}


@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM])
def test_record_stopped_mid_recording_keeps_everything(tmp_path, context, sig):
    """Every message the recorder took is in the bag; the bag opens after the signal."""
    topic = f'/rec{os.getpid()}/ball/image_point'
    camera = topic.split('/')[1]
    out = tmp_path / 'recorded'
    recorder = subprocess.Popen(
        [str(BIN / 'record'), '--ros-args', '-p', f'bag:={out}', '-p', f'topics:=[{topic}]',
         '-p', 'types:=[geometry_msgs/msg/PointStamped]'],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines = _lines(recorder)
    seen = []
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

        sent = 0
        for _ in range(200):
            publish(sent)
            sent += 1
        # The recorder has taken messages: stop it while more keep coming.
        assert _wait_for_line(lines, 'first message', seen), ''.join(seen)
        for _ in range(200):
            publish(sent)
            sent += 1
            if sent == 250:
                recorder.send_signal(sig)
        recorder.wait(timeout=30)
        _wait_for_line(lines, r'(?!)', seen)  # the rest of the output, up to its end
    finally:
        if recorder.poll() is None:
            recorder.kill()
        node.destroy_node()
    output = ''.join(seen)
    assert recorder.returncode == 0, output
    assert 'Traceback' not in output
    taken = re.search(r'recorded (\d+) messages', output)
    assert taken, output
    recorded = read_observations(out, [camera])
    indices = [int(o.u) for o in recorded]
    # What the recorder took, in order from the first, nothing lost, nothing invented.
    assert len(indices) == int(taken.group(1))
    assert indices == list(range(len(indices)))
    assert 1 <= len(indices) <= sent
