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

Messages are taken serialized (``raw=True``) and written as they arrive,
log time = receive time on the node's clock.  Types come from the ``types``
parameter (same order as ``topics``) or, when it is empty, from the ROS
graph.

A topic is subscribed when its first publisher shows in the graph (checked
every 0.1 s), with the QoS reliability its publishers offer: reliable when
every publisher is reliable, else best effort (a best-effort subscription
matches both kinds; a reliable one never receives from a best-effort
publisher such as a camera with sensor-data QoS, and a best-effort one
would lose a reliable publisher's retransmissions).  When a best-effort
publisher appears on a topic already subscribed reliably, the topic is
subscribed again best effort; messages sent during the switch can be
missing and a warning says so.

**No silent loss.**  With the default ``qos_depth`` 0 the subscriptions
keep all (``KEEP_ALL``): a message the recorder has not taken yet is never
overwritten in its queue, and a reliable publisher is slowed down instead.
What is still lost (a publisher's own queue overwriting messages the
recorder had not acknowledged, a best-effort transport dropping them) is
reported by DDS as the ``message_lost`` event: counted per topic, a warning
at most every 5 s per topic while it happens, and the total in the summary
at the end.  A positive ``qos_depth`` keeps only that many (``KEEP_LAST``),
as before; messages overwritten in that queue are not reported by DDS.
Measured here (a publisher in another process, 15,000 PointStamped): with
``EventsExecutor``, the default of every executable, all recorded at 2,000,
5,000 and 12,000 messages/s; with ``--executor single`` at 5,000/s 8,718
recorded and 3,547 reported lost (the rest still queued when it was
stopped); the old recorder (depth 1000, ``SingleThreadedExecutor``)
recorded 1,880 of a 6,000-message burst without a word.

**Crash-safe bag.**  The bag is written with
:class:`~pseudo_stereo_ros.formats.checkpoint_bag.CheckpointBagWriter`:
every ``checkpoint_period_s`` (1 s) the mcap and ``metadata.yaml`` on disk
become a complete bag of everything received so far, so a recorder killed
with ``kill -9`` leaves a bag that ``replay`` and ``pseudo_stereo track
--bag`` read up to its last checkpoint.  On SIGINT or SIGTERM the node
closes the bag, so every message taken from a subscription is in it, and
logs how many that was per topic (and how many were lost).
"""

import time

from rclpy.event_handler import SubscriptionEventCallbacks
import rclpy.logging
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

from .messages import message_class
from .node_tools import declare, run_node, StartupError
from ..errors import BagError
from ..formats.bagio import typestore
from ..formats.checkpoint_bag import CheckpointBagWriter

__all__ = ['RecordNode', 'main']

#: Shortest interval between two loss warnings of one topic [s].
LOSS_WARNING_PERIOD_S = 5.0


class RecordNode(Node):
    """Subscribes topics serialized and appends every message to a crash-safe mcap bag."""

    def __init__(self, **kwargs):
        super().__init__('record', **kwargs)
        self.bag = declare(self, 'bag', '', 'the bag directory to create (must not exist)',
                           read_only=True)
        topics = declare(self, 'topics', [''], 'topics to record', read_only=True)
        types = declare(self, 'types', [''],
                        'their message types, same order (empty: discovered from the graph)',
                        read_only=True)
        self.depth = declare(self, 'qos_depth', 0,
                             'subscription queue depth; 0: keep all (nothing overwritten)',
                             min_value=0, read_only=True)
        checkpoint_s = declare(self, 'checkpoint_period_s', 1.0,
                               'the bag on disk is complete up to this long ago [s]',
                               min_value=0.01, read_only=True)
        self.topics = [topic for topic in topics if topic]
        types = [t for t in types if t]
        if not self.bag:
            raise StartupError('parameter bag: required (the bag directory to create)')
        if not self.topics:
            raise StartupError('parameter topics: give at least one topic')
        if types and len(types) != len(self.topics):
            raise StartupError(f'parameter types: {len(types)} types for {len(self.topics)} '
                               f'topics (one per topic, or none)')
        for msgtype in types:
            if msgtype not in typestore().types:
                raise StartupError(f'parameter types: {msgtype} is not a ROS 2 Jazzy type')
        try:
            self._writer = CheckpointBagWriter(self.bag)
            self._writer.create()
        except BagError as err:
            raise StartupError(f'parameter bag: {err}') from err
        self._types = dict(zip(self.topics, types))
        self._summary = None
        self._connections = {}
        self._inputs = {}
        #: The reliability each topic is subscribed with (topics not subscribed yet: absent).
        self.reliability = {}
        #: Messages written per topic.
        self.counts = dict.fromkeys(self.topics, 0)
        #: Messages DDS reported lost per topic (the ``message_lost`` event).
        self.lost = dict.fromkeys(self.topics, 0)
        #: Messages taken but not written (the disk refused them).
        self.unwritten = 0
        self._lost_warned = dict.fromkeys(self.topics, (0, -LOSS_WARNING_PERIOD_S))
        self._watch = self.create_timer(0.1, self._watch_graph)
        self.create_timer(checkpoint_s, self._checkpoint)
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
                self._connections[topic] = (self._writer.add_connection(topic, msgtype),
                                            msgtype)
                self._subscribe(topic, msgtype, wanted)
                self.get_logger().info(f'recording {topic} ({msgtype}, '
                                       f'{wanted.name.lower().replace("_", " ")})')
            elif current == ReliabilityPolicy.RELIABLE and not reliable:
                # A reliable subscription never matches a best-effort publisher (sensor data).
                self.destroy_subscription(self._inputs.pop(topic))
                self._subscribe(topic, self._connections[topic][1], wanted)
                self.get_logger().warning(f'{topic}: a best-effort publisher appeared; '
                                          f'subscribed again best effort (messages sent '
                                          f'during the switch may be missing)')
        if all(self.reliability.get(topic) == ReliabilityPolicy.BEST_EFFORT
               for topic in self.topics):
            self._watch.cancel()  # best effort matches every publisher: nothing left to follow

    def _subscribe(self, topic: str, msgtype: str, reliability: ReliabilityPolicy):
        if self.depth > 0:
            qos = QoSProfile(depth=self.depth, reliability=reliability)
        else:
            qos = QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=reliability)
        events = SubscriptionEventCallbacks(
            message_lost=lambda info, t=topic: self._on_lost(t, info.total_count_change))
        connection = self._connections[topic][0]
        self._inputs[topic] = self.create_subscription(
            message_class(msgtype), topic,
            lambda data, t=topic, c=connection: self._write(t, c, data), qos, raw=True,
            event_callbacks=events)
        self.reliability[topic] = reliability

    def _write(self, topic: str, connection: int, data: bytes):
        if self._writer is None:
            return
        try:
            self._writer.write(connection, self.get_clock().now().nanoseconds, data)
        except BagError as err:
            self.unwritten += 1
            self.get_logger().error(f'cannot write: {err}', throttle_duration_sec=5.0)
            return
        self.counts[topic] += 1
        if self.counts[topic] == 1:
            self.get_logger().info(f'{topic}: first message')

    def _on_lost(self, topic: str, count: int):
        """DDS reports messages of ``topic`` that never reached the recorder."""
        if count <= 0:
            return
        self.lost[topic] += count
        warned, warned_at = self._lost_warned[topic]
        now = time.monotonic()
        if now - warned_at >= LOSS_WARNING_PERIOD_S:
            self.get_logger().warning(
                f'{topic}: {self.lost[topic] - warned} messages lost ({self.lost[topic]} in '
                f'total): the publisher outran the recorder or the link dropped them')
            self._lost_warned[topic] = (self.lost[topic], now)

    def _checkpoint(self):
        if self._writer is None:
            return
        try:
            self._writer.checkpoint()
        except BagError as err:
            self.get_logger().error(f'cannot write: {err}', throttle_duration_sec=5.0)

    def close(self):
        """Close the bag (idempotent): everything received so far is in it."""
        if self._writer is not None:
            writer, self._writer = self._writer, None
            try:
                writer.close()
            except BagError as err:
                self.get_logger().error(f'cannot close the bag: {err}')
            lost = sum(self.lost.values())
            self._summary = (f'closed {self.bag}: recorded {sum(self.counts.values())} '
                             f'messages (' + ', '.join(f'{topic}: {count}' for topic, count
                                                       in self.counts.items()) + ')')
            if lost:
                self._summary += ('; LOST ' + str(lost) + ' (' + ', '.join(
                    f'{topic}: {count}' for topic, count in self.lost.items() if count) + ')')
            if self.unwritten:
                self._summary += f'; {self.unwritten} not written (disk)'
            if self.context.ok():
                self._log_summary(self.get_logger())

    def _log_summary(self, logger):
        if self._summary:
            if 'LOST' in self._summary or self.unwritten:
                logger.warning(self._summary)
            else:
                logger.info(self._summary)
            self._summary = None

    def destroy_node(self):
        """Close the bag, then destroy the node."""
        self.close()
        name = self.get_logger().name
        result = super().destroy_node()
        # After SIGINT the context, and /rosout, are shut down: log once the node is gone.
        self._log_summary(rclpy.logging.get_logger(name))
        return result


def main(args=None) -> int:
    """Record until SIGINT or SIGTERM; exit 0, or 1 when it cannot start."""
    return run_node(RecordNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
