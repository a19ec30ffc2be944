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
``record``: write the listed topics to an mcap bag, without rosbag2.

Messages are taken serialized (``raw=True``) and written as they arrive with
rosbags' Writer, log time = receive time on the node's clock.  Types come
from the ``types`` parameter (same order as ``topics``) or, when it is
empty, from the ROS graph: a topic is subscribed as soon as a publisher
shows it.  rclpy turns SIGINT and SIGTERM into a shutdown; the node then
closes the bag, so every message received is in it.
"""

from pathlib import Path

from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosbags.rosbag2 import StoragePlugin, Writer, WriterError

from .bagio import typestore
from .node_tools import declare, run_node, StartupError
from .replay_node import message_class

__all__ = ['RecordNode', 'main']


class RecordNode(Node):
    """Subscribes topics serialized and appends every message to an mcap bag."""

    def __init__(self, **kwargs):
        super().__init__('record', **kwargs)
        self.bag = declare(self, 'bag', '', 'the bag directory to create (must not exist)',
                           read_only=True)
        topics = declare(self, 'topics', [''], 'topics to record', read_only=True)
        types = declare(self, 'types', [''],
                        'their message types, same order (empty: discovered from the graph)',
                        read_only=True)
        self.depth = declare(self, 'qos_depth', 1000, 'subscription queue depth', min_value=1,
                             read_only=True)
        self.topics = [topic for topic in topics if topic]
        types = [t for t in types if t]
        if not self.bag:
            raise StartupError('parameter bag: required (the bag directory to create)')
        if not self.topics:
            raise StartupError('parameter topics: give at least one topic')
        if types and len(types) != len(self.topics):
            raise StartupError(f'parameter types: {len(types)} types for {len(self.topics)} '
                               f'topics (one per topic, or none)')
        if Path(self.bag).exists():
            raise StartupError(f'parameter bag: {self.bag} exists already, not overwriting')
        for msgtype in types:
            if msgtype not in typestore().types:
                raise StartupError(f'parameter types: {msgtype} is not a ROS 2 Jazzy type')
        try:
            self._writer = Writer(self.bag, version=9, storage_plugin=StoragePlugin.MCAP)
            self._writer.open()
        except (WriterError, OSError) as err:
            raise StartupError(f'parameter bag: cannot create {self.bag} ({err})') from err
        self._connections = {}
        self._inputs = {}
        #: Messages written per topic.
        self.counts = dict.fromkeys(self.topics, 0)
        for topic, msgtype in zip(self.topics, types):
            self._subscribe(topic, msgtype)
        self._discovery = None
        if len(self._inputs) < len(self.topics):
            self._discovery = self.create_timer(0.1, self._discover)

    def _discover(self):
        found = dict(self.get_topic_names_and_types())
        for topic in self.topics:
            if topic in self._inputs or topic not in found:
                continue
            msgtype = found[topic][0]
            if msgtype not in typestore().types:
                self.get_logger().error(f'{topic}: type {msgtype} is unknown to rosbags; '
                                        f'not recorded', once=True)
                continue
            self._subscribe(topic, msgtype)
        if len(self._inputs) == len(self.topics):
            self._discovery.cancel()

    def _subscribe(self, topic: str, msgtype: str):
        qos = QoSProfile(depth=self.depth)
        offered = self.get_publishers_info_by_topic(topic)
        if offered and any(info.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT
                           for info in offered):
            # A reliable subscription would not match a best-effort publisher (sensor data).
            qos.reliability = ReliabilityPolicy.BEST_EFFORT
        self._connections[topic] = self._writer.add_connection(topic, msgtype,
                                                               typestore=typestore())
        self._inputs[topic] = self.create_subscription(
            message_class(msgtype), topic, lambda data, t=topic: self._write(t, data), qos,
            raw=True)
        self.get_logger().info(f'recording {topic} ({msgtype})')

    def _write(self, topic: str, data: bytes):
        if self._writer is None:
            return
        self._writer.write(self._connections[topic], self.get_clock().now().nanoseconds, data)
        self.counts[topic] += 1

    def close(self):
        """Close the bag (idempotent): everything received so far is in it."""
        if self._writer is not None:
            writer, self._writer = self._writer, None
            # No logging here: after SIGINT the context (and /rosout) is already shut down.
            writer.close()

    def destroy_node(self):
        """Close the bag, then destroy the node."""
        self.close()
        return super().destroy_node()


def main(args=None) -> int:
    """Record until SIGINT or SIGTERM; exit 0, or 1 when it cannot start."""
    return run_node(RecordNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
