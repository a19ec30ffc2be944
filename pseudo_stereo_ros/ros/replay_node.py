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
``replay``: publish a ROS 2 bag (mcap or sqlite3) with its original timing, without rosbag2.

The bag is read with rosbags; each message's CDR bytes are turned into the
rclpy message with ``rclpy.serialization.deserialize_message`` (so header
stamps are exactly those recorded) and published at
``first + (log_time - bag_start) / rate`` on the wall clock.  With
``publish_clock`` the bag's log time goes out on ``/clock`` before each
message, for nodes run with ``use_sim_time``.

Parameters: ``bag`` (path, required), ``rate`` (time factor, 2.0 = twice as
fast), ``start_offset_s`` (skip the bag's first seconds), ``topics`` (topics
to play; empty = all), ``remap`` (``from:=to`` entries), ``loop``,
``publish_clock``, ``qos_depth`` and ``wait_for_subscribers_s`` (wait up to
this long for each topic to have a subscriber before the first message).
The topics and their types come from the bag's index (no message is read
at start-up, so a long bag starts as fast as a short one).  When the bag
ends (without ``loop``), or on Ctrl-C / SIGTERM, the executable exits with
status 0; it exits 1 when it cannot start (bad parameter or parameter file,
no such bag, not a bag, no messages) or when the bag turns out to be
damaged during playback.
"""

import threading
import time
from typing import List, Optional

import rclpy
from rclpy.duration import Duration
from rclpy.executors import ExternalShutdownException
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rclpy.serialization import deserialize_message

from .messages import message_class, ns_to_stamp
from .node_tools import (check_params_files, close, declare, init_context, logger_name, spin,
                         split_executor_option, STARTUP_ERRORS, StartupError)
from ..formats.bagio import bag_message_counts, BagError, iter_raw
from ..stamps import seconds_to_ns

__all__ = ['ReplayNode', 'main']


def _parse_remap(entries: List[str]) -> dict:
    remap = {}
    for entry in entries:
        source, sep, target = entry.partition(':=')
        if not sep or not source.startswith('/') or not target.startswith('/'):
            raise StartupError(f'parameter remap: {entry!r} is not /from:=/to')
        remap[source] = target
    return remap


class ReplayNode(Node):
    """Publishes the messages of a bag with their original timing on a worker thread."""

    def __init__(self, **kwargs):
        super().__init__('replay', **kwargs)
        self.bag = declare(self, 'bag', '', 'the bag to play (rosbag2 directory, .mcap or .db3)',
                           read_only=True)
        self.rate = declare(self, 'rate', 1.0, 'time factor (2.0 = twice as fast)',
                            min_value=1e-3, read_only=True)
        self.start_offset_s = declare(self, 'start_offset_s', 0.0,
                                      'seconds of the bag to skip at the start [s]',
                                      min_value=0.0, read_only=True)
        topics = declare(self, 'topics', [''], 'topics to play (empty: all)', read_only=True)
        remap = declare(self, 'remap', [''], 'topic remappings, /from:=/to', read_only=True)
        self.loop = declare(self, 'loop', False, 'play the bag again when it ends',
                            read_only=True)
        self.publish_clock = declare(self, 'publish_clock', True,
                                     'publish the bag time on /clock (for use_sim_time)',
                                     read_only=True)
        depth = declare(self, 'qos_depth', 100, 'publisher queue depth', min_value=1,
                        read_only=True)
        self.wait_for_subscribers_s = declare(
            self, 'wait_for_subscribers_s', 1.0,
            'wait up to this long for every topic to have a subscriber before playing [s]',
            min_value=0.0, read_only=True)
        if not self.bag:
            raise StartupError('parameter bag: required (the bag to play)')
        self.topics = [topic for topic in topics if topic] or None
        self.remap = _parse_remap([entry for entry in remap if entry])

        # The index only: a missing bag or topic, or an empty bag, stops the node at start-up;
        # damage inside the message data shows during playback (self.error, exit status 1).
        counts = bag_message_counts(self.bag, self.topics)
        self._count = sum(count for _, count in counts.values())
        if not self._count:
            raise BagError(f'{self.bag}: no messages to play')
        self._classes = {topic: message_class(msgtype) for topic, (msgtype, _) in counts.items()}
        qos = QoSProfile(depth=depth)
        self._outputs = {topic: self.create_publisher(cls, self.remap.get(topic, topic), qos)
                         for topic, cls in self._classes.items()}
        self._clock_publisher = None
        if self.publish_clock:
            from rosgraph_msgs.msg import Clock
            self._clock_class = Clock
            self._clock_publisher = self.create_publisher(Clock, '/clock', qos)
        #: Messages published, and messages that did not decode (skipped).
        self.published = 0
        self.dropped = 0
        #: Why playback stopped before the end of the bag (a damaged bag), or None.
        self.error: Optional[str] = None
        self.finished = threading.Event()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._play, name='replay', daemon=True)
        self._thread.start()

    def destroy_node(self):
        """Stop playback, then destroy the node."""
        self._stop.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout=2.0)
        return super().destroy_node()

    def _play(self):
        # DDS discovery takes a moment; messages published before a subscriber matched are lost.
        deadline = time.monotonic() + self.wait_for_subscribers_s
        while (time.monotonic() < deadline and not self._stop.is_set()
               and any(p.get_subscription_count() == 0 for p in self._outputs.values())):
            self._stop.wait(0.02)
        self.get_logger().info(f'playing {self.bag}: {self._count} messages on '
                               f'{len(self._outputs)} topics at rate {self.rate:g}')
        try:
            while not self._stop.is_set() and self.context.ok():
                self._play_once()
                if not self.loop:
                    break
        except BagError as err:
            self.error = str(err)
            self.get_logger().error(f'playback stopped: {err}')
        except _rclpy.RCLError:
            # Ctrl-C / SIGTERM shut the context down between the check and the publish.
            pass
        finally:
            # Reliable subscribers get the tail of the bag before the executable exits (not
            # after a shutdown: the publishers are gone with the context then).
            try:
                for publisher in self._outputs.values():
                    if not self.context.ok():
                        break
                    publisher.wait_for_all_acked(Duration(seconds=1.0))
            except _rclpy.RCLError:
                pass
            # No summary here: a signal can shut /rosout down at any moment; main() logs it.
            self.finished.set()

    def summary(self) -> str:
        """Return the one-line playback summary: messages published and skipped."""
        return f'played {self.published} messages ({self.dropped} skipped)'

    def _play_once(self):
        start_bag: Optional[int] = None
        start_wall = None
        offset_ns = seconds_to_ns(self.start_offset_s)
        for topic, _, log_time, data in iter_raw(self.bag, self.topics):
            if self._stop.is_set() or not self.context.ok():
                return
            if start_bag is None:
                start_bag = log_time + offset_ns
            if log_time < start_bag:
                continue
            if start_wall is None:
                start_wall = time.monotonic()
            due = start_wall + (log_time - start_bag) / 1e9 / self.rate
            delay = due - time.monotonic()
            if (delay > 0 and self._stop.wait(delay)) or not self.context.ok():
                return
            try:
                message = deserialize_message(data, self._classes[topic])
            except Exception as err:  # noqa: B902 - rclpy raises plain exceptions on bad CDR
                self.dropped += 1
                self.get_logger().warning(f'{topic}: a message does not decode ({err})',
                                          throttle_duration_sec=5.0)
                continue
            if self._clock_publisher is not None:
                self._clock_publisher.publish(self._clock_class(clock=ns_to_stamp(log_time)))
            self._outputs[topic].publish(message)
            self.published += 1


def main(args=None) -> int:
    """Play a bag; exit 0 at its end or on a signal, 1 when it cannot start or the bag is bad."""
    name = logger_name('replay', args)
    logger = rclpy.logging.get_logger(name)
    try:
        executor, args = split_executor_option(args)
    except StartupError as err:
        logger.fatal(f'cannot start: {err}')
        return 1
    if not init_context(args, name=name):  # a bad --params-file or --ros-args: one line
        return 1
    node = None
    try:
        try:
            node = ReplayNode()
        except STARTUP_ERRORS as err:
            logger.fatal(f'cannot start: {err}')
            return 1
        check_params_files([node], args)
        spin([node], executor=executor, until=node.finished.is_set)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        close([node])
        if node is not None:
            # Not through the node: after a signal its /rosout publisher is invalid.
            logger.info(node.summary())
    return 1 if node is not None and node.error else 0


if __name__ == '__main__':
    raise SystemExit(main())
