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
Find the ball in one image: colour (or brightness) segmentation and a sub-pixel centroid.

Steps: threshold (HSV range for colour images, brightness for mono8) ->
morphological opening (removes specks) -> connected blobs within
``[min_area_px, max_area_px]`` -> one blob (the largest, or the one nearest
to the last detection) -> centroid by image moments of a soft weight over
the blob and a two-pixel margin.  The weight is the pixel's chroma
(``max - min`` of its channels; brightness for mono8) above the local
background level, which is linear in the ball's coverage of an
anti-aliased edge pixel, so the centroid is sub-pixel accurate.

With ``search_window_px > 0`` only a square around the last detection is
searched; when the ball is not found there, or its blob touches the window's
edge, the full frame is searched.  Coordinates are raw pixels with pixel
centres at integers.

:func:`image_array` turns the raw buffer of an image (the fields of a
``sensor_msgs/Image``, from rclpy or from a bag) into the array
:meth:`BallDetector.detect` takes; it knows no ROS type.
"""

from __future__ import annotations

import array
from collections import Counter
from collections.abc import Sequence

import cv2
import numpy as np

from .errors import DetectorConfigError, EncodingError

__all__ = ['BallDetector', 'CHOICES', 'COLOR_ENCODINGS', 'ENCODING_CHANNELS', 'ENCODINGS',
           'EncodingError', 'image_array']

#: Blob choice policies.
CHOICES = ('largest', 'nearest')
#: Colour encodings -> OpenCV conversion to HSV (takes 3 or 4 channels; alpha is ignored).
COLOR_ENCODINGS = {
    'rgb8': cv2.COLOR_RGB2HSV,
    'bgr8': cv2.COLOR_BGR2HSV,
    'rgba8': cv2.COLOR_RGB2HSV,
    'bgra8': cv2.COLOR_BGR2HSV,
}
#: Every encoding :meth:`BallDetector.detect` accepts.
ENCODINGS = tuple(COLOR_ENCODINGS) + ('mono8',)
#: Supported image encodings -> channels per pixel (all 8 bits per channel).
ENCODING_CHANNELS = {'mono8': 1, 'rgb8': 3, 'bgr8': 3, 'rgba8': 4, 'bgra8': 4}

_MARGIN_PX = 2


def image_array(data: bytes | bytearray | memoryview | array.array[int] | np.ndarray,
                height: int, width: int, step: int, encoding: str) -> np.ndarray:
    """
    Return the pixels of a raw 8-bit image buffer as an array (a view where possible).

    Rows may be padded (``step > width * channels``); the padding is dropped.

    :param data: the pixel bytes (bytes, a uint8 array, ``array.array('B')``, ...), row-major
    :param height: rows [px]
    :param width: columns [px]
    :param step: bytes per row, padding included
    :param encoding: one of :data:`ENCODING_CHANNELS`
    :return: (H, W) uint8 for mono8, (H, W, C) uint8 in the encoding's channel order
    :raises EncodingError: unsupported encoding, an empty image (no rows or no columns), or
        ``step``/``data`` inconsistent with the size
    """
    channels = ENCODING_CHANNELS.get(encoding)
    if channels is None:
        raise EncodingError(f'unsupported image encoding {encoding!r} '
                            f'(supported: {", ".join(ENCODING_CHANNELS)})')
    height, width, step = int(height), int(width), int(step)
    if height < 0 or width < 0:
        raise EncodingError(f'negative image size {width} x {height}')
    if height == 0 or width == 0:
        # OpenCV asserts on empty images (cv2.error, not a ValueError): refuse them here.
        raise EncodingError(f'empty image ({width} x {height} px)')
    row_bytes = width * channels
    if step < row_bytes:
        raise EncodingError(f'step {step} is less than width x channels = {row_bytes}')
    buffer = np.frombuffer(data, dtype=np.uint8)
    if buffer.size < step * height:
        raise EncodingError(f'data has {buffer.size} bytes, expected step x height = '
                            f'{step * height}')
    rows = buffer[:step * height].reshape(height, step)[:, :row_bytes]
    if channels == 1:
        return rows
    return rows.reshape(height, width, channels)


def _median_of_integers(values: np.ndarray) -> float:
    """
    Return the median of integer-valued floats, exactly as ``float(np.median(values))``.

    A tenth of ``np.median``'s time on the few dozen values of a ring: the mean of the two
    middle values is exact for integers, in float32 as in Python floats.

    :param values: (N,) integer-valued float32, N >= 1
    :return: the median
    """
    ordered = np.sort(values)
    middle = ordered.size // 2
    if ordered.size % 2:
        return float(ordered[middle])
    return (float(ordered[middle - 1]) + float(ordered[middle])) / 2.0


class BallDetector:
    """
    Ball detector with state (the last position, for the search window and the blob choice).

    :param hsv_lower: lowest (H, S, V), OpenCV ranges (H 0..179, S and V 0..255); a lower hue
        above the upper hue wraps around red
    :param hsv_upper: highest (H, S, V)
    :param mono_threshold: mono8 images: a ball pixel is at least this bright (0..255)
    :param min_area_px: smallest blob area [px]
    :param max_area_px: largest blob area [px]
    :param open_kernel_px: size of the elliptical opening kernel [px]; 0 or 1 disables
    :param choice: ``'largest'`` or ``'nearest'`` (to the last detection)
    :param search_window_px: half side of the search window around the last detection [px];
        0 always searches the full frame
    """

    def __init__(self, *, hsv_lower: Sequence[int] = (5, 120, 100),
                 hsv_upper: Sequence[int] = (25, 255, 255), mono_threshold: int = 200,
                 min_area_px: float = 4.0, max_area_px: float = 20000.0,
                 open_kernel_px: int = 3, choice: str = 'largest',
                 search_window_px: int = 48) -> None:
        lower = [int(x) for x in hsv_lower]
        upper = [int(x) for x in hsv_upper]
        if len(lower) != 3 or len(upper) != 3:
            raise DetectorConfigError('hsv_lower and hsv_upper take three values (H, S, V)')
        for name, values in (('hsv_lower', lower), ('hsv_upper', upper)):
            if not (0 <= values[0] <= 179 and all(0 <= x <= 255 for x in values[1:])):
                raise DetectorConfigError(
                    f'{name} out of range (H 0..179, S and V 0..255): {values}')
        if lower[1] > upper[1] or lower[2] > upper[2]:
            raise DetectorConfigError(f'hsv_lower {lower} exceeds hsv_upper {upper} in S or V')
        if not 0 <= int(mono_threshold) <= 255:
            raise DetectorConfigError(f'mono_threshold must be in 0..255, got {mono_threshold}')
        if not 0 < min_area_px <= max_area_px:
            raise DetectorConfigError(f'need 0 < min_area_px <= max_area_px, got {min_area_px}, '
                                      f'{max_area_px}')
        if choice not in CHOICES:
            raise DetectorConfigError(f'unknown choice {choice!r} (known: {", ".join(CHOICES)})')
        if int(search_window_px) < 0 or int(open_kernel_px) < 0:
            raise DetectorConfigError('search_window_px and open_kernel_px must be >= 0')
        # (lower, upper) HSV bounds; two when the hue range wraps around red
        self._ranges: list[tuple[np.ndarray, np.ndarray]] = []
        if lower[0] <= upper[0]:
            self._ranges.append((np.array(lower, np.uint8), np.array(upper, np.uint8)))
        else:  # hue wraps around 180
            self._ranges.append((np.array(lower, np.uint8), np.array((179,) + tuple(upper[1:]),
                                                                     np.uint8)))
            self._ranges.append((np.array((0,) + tuple(lower[1:]), np.uint8),
                                 np.array(upper, np.uint8)))
        self.mono_threshold = int(mono_threshold)
        self.min_area_px = float(min_area_px)
        self.max_area_px = float(max_area_px)
        self.choice = choice
        self.search_window_px = int(search_window_px)
        size = int(open_kernel_px)
        self._kernel = (cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size))
                        if size > 1 else None)
        self._dilate = cv2.getStructuringElement(cv2.MORPH_RECT,
                                                 (2 * _MARGIN_PX + 1, 2 * _MARGIN_PX + 1))
        self._ring_kernel = np.ones((3, 3), np.uint8)
        #: The last detection (u, v) [px], or None.
        self.last: tuple[float, float] | None = None
        #: Counts: ``frames``, ``detections``, ``no_ball``, ``window_hits``, ``window_misses``.
        self.stats: Counter[str] = Counter()

    def reset(self) -> None:
        """Forget the last position."""
        self.last = None

    def warm_up(self, image: np.ndarray, encoding: str = 'bgr8') -> bool:
        """
        Run a windowed detection on ``image`` and forget it, to have the caches warm.

        A detection that runs after a frame period of sleep costs two to three
        times one that follows another (the code and data it touches were evicted
        by other work on the core); a capture loop calls this on the previous frame
        just before the next is due.  The last position and the counts are left as
        they were.  Nothing runs without a last position: a full-frame search costs
        more than it would save.

        :param image: an image as :meth:`detect` takes it (the previous frame)
        :param encoding: one of :data:`ENCODINGS`
        :return: whether a detection ran
        """
        if self.last is None or self.search_window_px <= 0:
            return False
        last, stats = self.last, self.stats
        self.stats = Counter()
        try:
            self.detect(image, encoding)
        finally:
            self.last, self.stats = last, stats
        return True

    def detect(self, image: np.ndarray, encoding: str = 'bgr8') -> tuple[float, float] | None:
        """
        Find the ball.

        :param image: (H, W) uint8 for mono8, (H, W, 3 or 4) uint8 in the encoding's order
        :param encoding: one of :data:`ENCODINGS`
        :return: the centroid (u, v) in raw pixels, or None when there is no ball
        :raises EncodingError: an unknown encoding, an empty image, or an image whose shape does
            not fit the encoding
        """
        if encoding not in ENCODINGS:
            raise EncodingError(f'unsupported encoding {encoding!r} (supported: '
                                f'{", ".join(ENCODINGS)})')
        channels = 1 if encoding == 'mono8' else (4 if encoding.endswith('a8') else 3)
        if image.dtype != np.uint8 or image.ndim != (2 if channels == 1 else 3) or \
                (channels > 1 and image.shape[2] != channels):
            raise EncodingError(f'image of shape {image.shape} and type {image.dtype} does not '
                                f'fit encoding {encoding!r}')
        if image.size == 0:
            raise EncodingError(f'empty image of shape {image.shape}')
        self.stats['frames'] += 1
        height, width = image.shape[:2]
        result = None
        if self.last is not None and self.search_window_px > 0:
            half = self.search_window_px
            u, v = int(round(self.last[0])), int(round(self.last[1]))
            x0, y0 = max(u - half, 0), max(v - half, 0)
            x1, y1 = min(u + half + 1, width), min(v + half + 1, height)
            if x0 < x1 and y0 < y1:
                result = self._search(image[y0:y1, x0:x1], encoding, (x0, y0),
                                      (x0 > 0, y0 > 0, x1 < width, y1 < height))
            self.stats['window_hits' if result is not None else 'window_misses'] += 1
        if result is None:
            result = self._search(image, encoding, (0, 0), (False, False, False, False))
        if result is None:
            self.stats['no_ball'] += 1
            self.last = None
            return None
        self.stats['detections'] += 1
        self.last = result
        return result

    # -- steps ----------------------------------------------------------------------------------

    def _mask(self, image: np.ndarray, encoding: str) -> np.ndarray:
        if encoding == 'mono8':
            return cv2.threshold(image, self.mono_threshold - 1, 255, cv2.THRESH_BINARY)[1]
        # The conversion reads 3 or 4 channels and strided views (a search window) as they
        # are: no copy of the frame.
        hsv = cv2.cvtColor(image, COLOR_ENCODINGS[encoding])
        (lower, upper), *more = self._ranges
        mask = cv2.inRange(hsv, lower, upper)
        for lower, upper in more:
            mask = cv2.bitwise_or(mask, cv2.inRange(hsv, lower, upper))
        return mask

    def _search(self, image: np.ndarray, encoding: str, offset: tuple[int, int],
                inner_edges: tuple[bool, bool, bool, bool]) -> tuple[float, float] | None:
        """Detect in ``image`` (a view of the frame at ``offset``); None if no acceptable blob."""
        mask = self._mask(image, encoding)
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
        # A blob cut by an inner window edge would bias the centroid: search the full frame.
        if (inner_edges[0] and left <= 0) or (inner_edges[1] and top <= 0) or \
                (inner_edges[2] and left + w >= width) or \
                (inner_edges[3] and top + h >= height):
            return None
        x0, y0 = max(left - _MARGIN_PX, 0), max(top - _MARGIN_PX, 0)
        x1, y1 = min(left + w + _MARGIN_PX, width), min(top + h + _MARGIN_PX, height)
        centroid = self._centroid(image[y0:y1, x0:x1], labels[y0:y1, x0:x1] == best)
        if centroid is None:
            u, v = centroids[best]
            u, v = u - x0, v - y0
        else:
            u, v = centroid
        return float(u + x0 + offset[0]), float(v + y0 + offset[1])

    def _centroid(self, patch: np.ndarray, blob: np.ndarray) -> tuple[float, float] | None:
        """Soft-weighted centroid within ``patch`` (relative to the patch); None if no weight."""
        if patch.ndim == 2:
            signal = patch.astype(np.float32)
        else:
            colour = patch[:, :, :3]
            # max >= min: the uint8 difference does not wrap.
            signal = (colour.max(axis=2) - colour.min(axis=2)).astype(np.float32)
        blob = blob.astype(np.uint8)
        near = cv2.dilate(blob, self._dilate).astype(bool)
        ring = near & ~cv2.dilate(blob, self._ring_kernel).astype(bool)
        # Background level: the outer ring of the margin, beyond the blob's anti-aliased edge.
        level = _median_of_integers(signal[ring]) if ring.any() else 0.0
        weight = np.where(near, np.clip(signal - level, 0.0, None), 0.0).astype(np.float32)
        moments = cv2.moments(weight)
        if moments['m00'] <= 0:
            return None
        return moments['m10'] / moments['m00'], moments['m01'] / moments['m00']
