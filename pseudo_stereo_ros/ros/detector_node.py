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
The ``detector`` node: ``image_raw`` in, ``ball/image_point`` (raw pixels) out.

Thin glue around :class:`pseudo_stereo_ros.detection.BallDetector`.  The
output carries the image's header unchanged (the shutter stamp and the
camera's frame); no ball, nothing is published.  Run one per camera in its
namespace: ``/camera1/image_raw`` -> ``/camera1/ball/image_point``.
"""

from collections import Counter, deque
import time

import cv2
from geometry_msgs.msg import PointStamped
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import Image

from .messages import EncodingError, image_point, image_to_array
from .node_tools import declare, declare_detector, run_node

__all__ = ['DetectorNode', 'main']


class DetectorNode(Node):
    """
    Find the ball in every image and publish its centroid.

    :param kwargs: passed to :class:`rclpy.node.Node` (``namespace``, ``parameter_overrides``,
        ``context``, ...)
    """

    def __init__(self, **kwargs):
        kwargs.setdefault('node_name', 'detector')
        super().__init__(**kwargs)
        self.detector = declare_detector(self)
        self._throttle_s = declare(self, 'error_throttle_s', 5.0,
                                   'least time between repeated error messages [s]',
                                   min_value=0.0)
        #: Counts: ``images``, ``published``, ``no_ball``, ``bad_image``.
        self.stats = Counter()
        #: Seconds spent in the detector per image, the most recent ones (for benchmarks).
        self.detect_times_s = deque(maxlen=10_000)
        self._last_error = {}
        # 100 like camera_detector: points a stalled fuser process has not acknowledged yet.
        self._publisher = self.create_publisher(PointStamped, 'ball/image_point', 100)
        self._subscription = self.create_subscription(
            Image, 'image_raw', self._on_image, qos_profile_sensor_data)

    def _throttled_error(self, key: str, text: str) -> None:
        now = time.monotonic()
        if now - self._last_error.get(key, -1e9) >= self._throttle_s:
            self._last_error[key] = now
            self.get_logger().error(f'{text} ({self.stats[key]} so far)')

    def _on_image(self, msg: Image) -> None:
        self.stats['images'] += 1
        try:
            pixels = image_to_array(msg)
            start = time.perf_counter()
            found = self.detector.detect(pixels, msg.encoding)
        except (EncodingError, ValueError, cv2.error) as err:
            # cv2.error: a last guard for images OpenCV refuses that the checks above let by.
            self.stats['bad_image'] += 1
            self._throttled_error('bad_image', f'image dropped: {str(err).strip()}')
            return
        self.detect_times_s.append(time.perf_counter() - start)
        if found is None:
            self.stats['no_ball'] += 1
            return
        self.stats['published'] += 1
        self._publisher.publish(image_point(msg.header, found[0], found[1]))


def main(args=None) -> int:
    """Run the detector node (``ros2 run pseudo_stereo_ros detector``)."""
    return run_node(DetectorNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
