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
What ``publish()`` of an image point costs, by QoS, with a subscriber in another process.

Publishes serialized PointStamped messages (``messages.point_encoder``, as
the camera_detector does) at a camera's pace and prints the wall and CPU
time of each ``publish()`` call (median, p90) and the hop to a subscriber
process (stamp at publication -> its callback).  QoS as ``rel-100``
(reliable, keep last 100: the camera_detector's; the fuser's is 1,000),
``be-1`` (best effort, keep last 1), ...; ``none`` for no subscriber.
Fast DDS options go in the environment (``FASTDDS_BUILTIN_TRANSPORTS=UDPv4``,
``RMW_FASTRTPS_PUBLICATION_MODE=ASYNCHRONOUS``).  Example::

    ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST python tools/publish_cost.py rel-100 rel-100
"""

import argparse
import json
import os
from pathlib import Path
import subprocess
import sys
import tempfile
import time

from geometry_msgs.msg import PointStamped
import numpy as np
from pseudo_stereo_ros.ros.messages import point_encoder
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy


def qos_profile(name: str) -> QoSProfile:
    """Return the profile of ``rel-N`` (reliable, keep last N) or ``be-N`` (best effort)."""
    reliability, depth = name.split('-')
    return QoSProfile(depth=int(depth), history=HistoryPolicy.KEEP_LAST,
                      reliability=(ReliabilityPolicy.RELIABLE if reliability == 'rel'
                                   else ReliabilityPolicy.BEST_EFFORT))


def subscriber(topic: str, qos: str, out: str, seconds: float) -> None:
    """Note (stamp, received) [ns] of every message for ``seconds``; write them to ``out``."""
    rclpy.init()
    node = rclpy.create_node('publish_cost_subscriber')
    got = []

    def on_point(msg):
        got.append((msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec, time.time_ns()))

    node.create_subscription(PointStamped, topic, on_point, qos_profile(qos))
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        executor.spin_once(timeout_sec=0.1)
    Path(out).write_text(json.dumps(got))


def publisher(pub_qos: str, sub_qos: str, seconds: float, rate_hz: float) -> str:
    """Publish at ``rate_hz`` for ``seconds``; return the result line."""
    topic = f'/publish_cost_{os.getpid()}'
    out = Path(tempfile.mkdtemp()) / 'received.json'
    process = None
    if sub_qos != 'none':
        process = subprocess.Popen([sys.executable, __file__, '--subscriber', topic, sub_qos,
                                    str(out), str(seconds + 8.0)])
    rclpy.init()
    node = rclpy.create_node('publish_cost_publisher')
    pub = node.create_publisher(PointStamped, topic, qos_profile(pub_qos))
    encode = point_encoder('camera1')
    deadline = time.monotonic() + 8.0
    while process and pub.get_subscription_count() == 0 and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(1.0)  # the reader's side of the match
    wall, cpu = [], []
    period = 1.0 / rate_hz
    due = time.monotonic() + period
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        time.sleep(max(due - time.monotonic(), 0.0))
        due += period
        data = encode(time.time_ns(), 1.0, 2.0, 0.0)
        cpu_start, start = time.thread_time(), time.perf_counter()
        pub.publish(data)
        wall.append(time.perf_counter() - start)
        cpu.append(time.thread_time() - cpu_start)
    node.destroy_node()
    rclpy.try_shutdown()
    wall_ms, cpu_ms = np.array(wall) * 1e3, np.array(cpu) * 1e3
    line = (f'{pub_qos:>8s} -> {sub_qos:<8s} {rate_hz:g} Hz: publish() wall p50 '
            f'{np.median(wall_ms):.3f} p90 {np.percentile(wall_ms, 90):.3f} ms, CPU p50 '
            f'{np.median(cpu_ms):.3f} p90 {np.percentile(cpu_ms, 90):.3f} ms')
    if process is not None:
        process.wait()
        hop_ms = np.array([(b - a) / 1e6 for a, b in json.loads(out.read_text())])
        line += (f'; hop n={hop_ms.size} p50 {np.median(hop_ms):.3f} '
                 f'p90 {np.percentile(hop_ms, 90):.3f} ms')
    return line


def main(argv=None) -> int:
    """Run the publisher (and its subscriber process); print one line."""
    if argv is None:
        argv = sys.argv[1:]
    if argv and argv[0] == '--subscriber':
        topic, qos, out, seconds = argv[1:]
        subscriber(topic, qos, out, float(seconds))
        return 0
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('pub_qos', help='rel-N or be-N')
    parser.add_argument('sub_qos', help='rel-N, be-N or none')
    parser.add_argument('--seconds', type=float, default=5.0)
    parser.add_argument('--rate', type=float, default=30.0, help='messages per second')
    options = parser.parse_args(argv)
    print(publisher(options.pub_qos, options.sub_qos, options.seconds, options.rate))
    return 0


if __name__ == '__main__':
    sys.exit(main())
