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
The ball detector as it was before its latency work (commit 45f1651), the reference of the tests.

:class:`ReferenceDetector` searches the fixed square of ``search_window_px``
around the last detection, then the full frame, and computes the centroid
with one plain numpy step after another.  It takes the configuration (and
its checks) of :class:`~pseudo_stereo_ros.detection.BallDetector`; only the
search is the old one.  The optimised detector must give the same
detections, bit for bit, wherever its shortcuts apply.
"""

import cv2
import numpy as np
from pseudo_stereo_ros.detection import BallDetector

_MARGIN_PX = 2


class ReferenceDetector(BallDetector):
    """The detector's search and centroid before the latency work."""

    def detect(self, image, encoding='bgr8'):
        """Find the ball: the window around the last detection, else the full frame."""
        height, width = image.shape[:2]
        result = None
        if self.last is not None and self.search_window_px > 0:
            half = self.search_window_px
            u, v = int(round(self.last[0])), int(round(self.last[1]))
            x0, y0 = max(u - half, 0), max(v - half, 0)
            x1, y1 = min(u + half + 1, width), min(v + half + 1, height)
            if x0 < x1 and y0 < y1:
                result = self._old_search(image[y0:y1, x0:x1], encoding, (x0, y0),
                                          (x0 > 0, y0 > 0, x1 < width, y1 < height))
        if result is None:
            result = self._old_search(image, encoding, (0, 0), (False,) * 4)
        self.last = result
        return result

    def _old_search(self, image, encoding, offset, inner_edges):
        if encoding == 'mono8':
            mask = cv2.threshold(image, self.mono_threshold - 1, 255, cv2.THRESH_BINARY)[1]
        else:
            code = cv2.COLOR_RGB2HSV if encoding.startswith('rgb') else cv2.COLOR_BGR2HSV
            hsv = cv2.cvtColor(image, code)
            mask = np.zeros(hsv.shape[:2], np.uint8)
            for lower, upper in self._ranges:
                mask = cv2.bitwise_or(mask, cv2.inRange(hsv, lower, upper))
        if self._kernel is not None:
            mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, self._kernel)
        count, labels, stats, centroids = cv2.connectedComponentsWithStats(mask, connectivity=8)
        if count <= 1:
            return None
        areas = stats[1:, cv2.CC_STAT_AREA].astype(float)
        candidates = np.flatnonzero((areas >= self.min_area_px) & (areas <= self.max_area_px))
        if candidates.size == 0:
            return None
        if self.choice == 'nearest' and self.last is not None:
            target = np.array(self.last) - offset
            distance = np.hypot(*(centroids[1 + candidates] - target).T)
            best = int(candidates[np.argmin(distance)]) + 1
        else:
            best = int(candidates[np.argmax(areas[candidates])]) + 1
        left, top, w, h = stats[best, :4]
        height, width = mask.shape
        if (inner_edges[0] and left <= 0) or (inner_edges[1] and top <= 0) or \
                (inner_edges[2] and left + w >= width) or \
                (inner_edges[3] and top + h >= height):
            return None
        x0, y0 = max(left - _MARGIN_PX, 0), max(top - _MARGIN_PX, 0)
        x1, y1 = min(left + w + _MARGIN_PX, width), min(top + h + _MARGIN_PX, height)
        patch = image[y0:y1, x0:x1]
        blob = (labels[y0:y1, x0:x1] == best).astype(np.uint8)
        if patch.ndim == 2:
            signal = patch.astype(np.float32)
        else:
            colour = patch[:, :, :3]
            signal = (colour.max(axis=2) - colour.min(axis=2)).astype(np.float32)
        near = cv2.dilate(blob, np.ones((2 * _MARGIN_PX + 1,) * 2, np.uint8)).astype(bool)
        ring = near & ~cv2.dilate(blob, np.ones((3, 3), np.uint8)).astype(bool)
        level = float(np.median(signal[ring])) if ring.any() else 0.0
        weight = np.where(near, np.clip(signal - level, 0.0, None), 0.0).astype(np.float32)
        moments = cv2.moments(weight)
        if moments['m00'] <= 0:
            u, v = centroids[best]
            u, v = u - x0, v - y0
        else:
            u, v = moments['m10'] / moments['m00'], moments['m01'] / moments['m00']
        return float(u + x0 + offset[0]), float(v + y0 + offset[1])
