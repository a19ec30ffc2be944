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
empty, from the ROS graph.

A topic is subscribed when its first publisher shows in the graph (checked
every 0.1 s), with the QoS reliability its publishers offer: reliable when
every publisher is reliable, else best effort (a best-effort subscription
matches both kinds; a reliable one never receives from a best-effort
publisher such as a camera with sensor-data QoS, and a best-effort one
would lose a reliable publisher's retransmissions).  When a best-effort
publisher appears on a topic already subscribed reliably, the topic is
subscribed again best effort; messages sent during the switch can be
missing and a warning says so.

rclpy turns SIGINT and SIGTERM into a shutdown; the node then closes the
bag, so every message taken from a subscription is in it, and logs how many
that was per topic.  (Messages DDS had delivered but the node had not taken
yet are not.)
"""

from pathlib import Path

import rclpy.logging
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosbags.rosbag2 import StoragePlugin, Writer, WriterError

from .node_tools import declare, run_node, StartupError
from .replay_node import message_class
from ..formats.bagio import typestore

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
        self._types = dict(zip(self.topics, types))
        self._summary = None
        self._connections = {}
        self._inputs = {}
        #: The reliability each topic is subscribed with (topics not subscribed yet: absent).
        self.reliability = {}
        #: Messages written per topic.
        self.counts = dict.fromkeys(self.topics, 0)
        self._watch = self.create_timer(0.1, self._watch_graph)
        self._watch_graph()

    def _watch_graph(self):
        """Subscribe topics whose publishers appeared; follow their reliability."""
        for topic in self.topics:
            offered = self.get_publishers_info_by_topic(topic)
            if not offered:
                continue
            reliable = all(info.qos_profile.reliability == ReliabilityPolicy.RELIABLE
                           for info in offered)
            wanted = ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT
            current = self.reliability.get(topic)
            if current is None:
                msgtype = self._types.get(topic) or offered[0].topic_type
                if msgtype not in typestore().types:
                    self.get_logger().error(f'{topic}: type {msgtype} is unknown to rosbags; '
                                            f'not recorded', once=True)
                    continue
                self._connections[topic] = self._writer.add_connection(
                    topic, msgtype, typestore=typestore())
                self._subscribe(topic, msgtype, wanted)
                self.get_logger().info(f'recording {topic} ({msgtype}, '
                                       f'{wanted.name.lower().replace("_", " ")})')
            elif current == ReliabilityPolicy.RELIABLE and not reliable:
                # A reliable subscription never matches a best-effort publisher (sensor data).
                self.destroy_subscription(self._inputs.pop(topic))
                self._subscribe(topic, self._connections[topic].msgtype, wanted)
                self.get_logger().warning(f'{topic}: a best-effort publisher appeared; '
                                          f'subscribed again best effort (messages sent '
                                          f'during the switch may be missing)')
        if all(self.reliability.get(topic) == ReliabilityPolicy.BEST_EFFORT
               for topic in self.topics):
            self._watch.cancel()  # best effort matches every publisher: nothing left to follow

    def _subscribe(self, topic: str, msgtype: str, reliability: ReliabilityPolicy):
        qos = QoSProfile(depth=self.depth, reliability=reliability)
        self._inputs[topic] = self.create_subscription(
            message_class(msgtype), topic, lambda data, t=topic: self._write(t, data), qos,
            raw=True)
        self.reliability[topic] = reliability

    def _write(self, topic: str, data: bytes):
        if self._writer is None:
            return
        self._writer.write(self._connections[topic], self.get_clock().now().nanoseconds, data)
        self.counts[topic] += 1
        if self.counts[topic] == 1:
            self.get_logger().info(f'{topic}: first message')

    def close(self):
        """Close the bag (idempotent): everything received so far is in it."""
        if self._writer is not None:
            writer, self._writer = self._writer, None
            writer.close()
            self._summary = (f'closed {self.bag}: recorded {sum(self.counts.values())} '
                             f'messages (' + ', '.join(f'{topic}: {count}' for topic, count
                                                       in self.counts.items()) + ')')
            if self.context.ok():
                self.get_logger().info(self._summary)
                self._summary = None

    def destroy_node(self):
        """Close the bag, then destroy the node."""
        self.close()
        name = self.get_logger().name
        result = super().destroy_node()
        if self._summary:
            # After SIGINT the context, and /rosout, are shut down: log once the node is gone.
            rclpy.logging.get_logger(name).info(self._summary)
            self._summary = None
        return result


def main(args=None) -> int:
    """Record until SIGINT or SIGTERM; exit 0, or 1 when it cannot start."""
    return run_node(RecordNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
