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
from .node_tools import declare, run_node, StartupError
from ..detection import BallDetector, CHOICES

__all__ = ['DetectorNode', 'declare_detector', 'main']


def declare_detector(node: Node) -> BallDetector:
    """
    Declare the ball detector's parameters on a node and return the detector they configure.

    Shared by the ``detector`` and ``camera_detector`` nodes, so both take the same
    parameters (``hsv_lower``, ``hsv_upper``, ``mono_threshold``, ``min_area_px``,
    ``max_area_px``, ``open_kernel_px``, ``choice``, ``search_window_px``).

    :param node: the node
    :return: the detector
    :raises StartupError: a value the detector refuses, naming the parameters
    """
    hsv_lower = declare(node, 'hsv_lower', [5, 120, 100],
                        'lowest ball colour (H 0..179, S, V 0..255), OpenCV HSV')
    hsv_upper = declare(node, 'hsv_upper', [25, 255, 255],
                        'highest ball colour (H, S, V); lower H > upper H wraps around red')
    mono_threshold = declare(node, 'mono_threshold', 200,
                             'mono8 images: a ball pixel is at least this bright',
                             min_value=0, max_value=255)
    min_area = declare(node, 'min_area_px', 4.0, 'smallest ball blob area [px]', min_value=0.0)
    max_area = declare(node, 'max_area_px', 20000.0, 'largest ball blob area [px]',
                       min_value=0.0)
    open_kernel = declare(node, 'open_kernel_px', 3,
                          'morphological opening kernel size [px]; 0 disables',
                          min_value=0, max_value=31)
    choice = declare(node, 'choice', 'largest', 'which blob when there are several',
                     choices=CHOICES)
    window = declare(node, 'search_window_px', 48,
                     'half side of the search window around the last detection [px]; '
                     '0: always the full frame', min_value=0)
    try:
        return BallDetector(
            hsv_lower=hsv_lower, hsv_upper=hsv_upper, mono_threshold=mono_threshold,
            min_area_px=min_area, max_area_px=max_area, open_kernel_px=open_kernel,
            choice=choice, search_window_px=window)
    except (ValueError, TypeError) as err:
        raise StartupError(f'detector parameters (hsv_lower, hsv_upper, min_area_px, '
                           f'max_area_px, ...): {err}') from err


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
        self._publisher = self.create_publisher(PointStamped, 'ball/image_point', 10)
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
