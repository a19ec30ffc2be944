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
edge, the full frame is searched.  When the two last frames both had the
ball, a tight window around its predicted position (the last one plus the
last image velocity; sized from the blob and the image speed, a sixth to a
tenth of the square's pixels) is searched first, and its detection is
accepted only when the blob keeps a guard band from the window's edges wide
enough that the square would give the same result to the last bit (the
opening, the blob and the centroid's margin all lie inside).  The one
difference: an acceptable blob elsewhere in the square but outside the
tight window is not seen, so a larger orange object near the ball no
longer captures the track (``largest``).  Coordinates are raw pixels with
pixel centres at integers.

Cost: the steps on the tight window and on the blob's patch are a few
microseconds of work each and as much again of call overhead, which is
why the single-blob case works with plain Python numbers and the fewest
numpy and OpenCV calls; a detection that runs after a frame period of
other work pays two to three times more (cold caches), see
:meth:`BallDetector.warm_up`.

:func:`image_array` turns the raw buffer of an image (the fields of a
``sensor_msgs/Image``, from rclpy or from a bag) into the array
:meth:`BallDetector.detect` takes; it knows no ROS type.
"""

from __future__ import annotations

import array
from collections import Counter
from collections.abc import Sequence
import math

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

    :param values: (N,) integers (any integer or float dtype), N >= 1
    :return: the median
    """
    ordered = np.sort(values).tolist()
    middle = len(ordered) // 2
    if len(ordered) % 2:
        return float(ordered[middle])
    return (ordered[middle - 1] + ordered[middle]) / 2.0


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
        # A tight window's result is the square's when the blob keeps this far from its inner
        # edges: the opening sees 2 * (size // 2) px beyond a pixel, a component one more, and
        # the centroid's margin must fit.
        self._guard_px = max(2 * (size // 2) + 1 if size > 1 else 1, _MARGIN_PX)
        # (du, dv, blob side) [px] of the last detection when the frame before had one too.
        self._motion: tuple[float, float, int] | None = None
        #: The last detection (u, v) [px], or None.
        self.last: tuple[float, float] | None = None
        #: Counts: ``frames``, ``detections``, ``no_ball``, ``window_hits``, ``window_misses``
        #: (found in a window or not), ``tight_hits``, ``tight_misses`` (the tight window).
        self.stats: Counter[str] = Counter()

    def reset(self) -> None:
        """Forget the last position (and the motion)."""
        self.last = self._motion = None

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
        last, motion, stats = self.last, self._motion, self.stats
        self.stats = Counter()
        if motion is not None:
            # The previous frame's ball was at the last detection: predict it there, so the
            # warm-up takes the tight window's path, as the next detection will (a miss would
            # search the square too: a quarter more CPU, measured).
            self.last = (last[0] - motion[0], last[1] - motion[1])
        try:
            self.detect(image, encoding)
        finally:
            self.last, self._motion, self.stats = last, motion, stats
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
        stats = self.stats
        stats['frames'] += 1
        height, width = image.shape[:2]
        found = None
        if self.last is not None and self.search_window_px > 0:
            half = self.search_window_px
            u, v = int(round(self.last[0])), int(round(self.last[1]))
            square = (max(u - half, 0), max(v - half, 0), min(u + half + 1, width),
                      min(v + half + 1, height))
            if square[0] < square[2] and square[1] < square[3]:
                tight = self._tight_window(square)
                if tight is not None:
                    found = self._search(image, encoding, tight, self._guard_px,
                                         origin=square[:2])
                    stats['tight_hits' if found is not None else 'tight_misses'] += 1
                if found is None:
                    found = self._search(image, encoding, square, 1)
            stats['window_hits' if found is not None else 'window_misses'] += 1
        if found is None:
            found = self._search(image, encoding, (0, 0, width, height), 1)
        if found is None:
            stats['no_ball'] += 1
            self.last = self._motion = None
            return None
        stats['detections'] += 1
        ball_u, ball_v, size = found
        # Image velocity from two detections in a row (frames without a ball break the chain).
        self._motion = (None if self.last is None else
                        (ball_u - self.last[0], ball_v - self.last[1], size))
        self.last = (ball_u, ball_v)
        return self.last

    # -- steps ----------------------------------------------------------------------------------

    def _tight_window(self, square: tuple[int, int, int, int]) -> tuple[int, int, int, int] | None:
        """
        Return the tight window around the predicted position, within ``square``; or None.

        The ball is predicted at the last detection plus its last image velocity;
        the window covers the last blob's size, 3 px plus a quarter of the image
        speed for the prediction's error (an image acceleration: ~2 px per frame
        at 30 fps for the simulated flights), and the guard band.  None without a
        velocity or when the window would be no smaller than ``square``.
        """
        if self._motion is None or self.last is None:
            return None
        du, dv, size = self._motion
        half = int(math.ceil(size / 2.0 + 4.0 + 0.25 * math.hypot(du, dv))) + self._guard_px
        if half >= self.search_window_px:
            return None
        u, v = int(round(self.last[0] + du)), int(round(self.last[1] + dv))
        x0, y0 = max(u - half, square[0]), max(v - half, square[1])
        x1, y1 = min(u + half + 1, square[2]), min(v + half + 1, square[3])
        if x1 - x0 <= 2 * self._guard_px or y1 - y0 <= 2 * self._guard_px:
            return None
        return x0, y0, x1, y1

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

    def _choose(self, stats: np.ndarray, centroids: np.ndarray,
                offset: tuple[int, int]) -> int | None:
        """Return the label of the chosen blob among several, or None if none is acceptable."""
        areas = stats[1:, cv2.CC_STAT_AREA].astype(float)
        candidates = np.flatnonzero((areas >= self.min_area_px) & (areas <= self.max_area_px))
        if candidates.size == 0:
            return None
        if self.choice == 'nearest' and self.last is not None:
            target = np.array(self.last) - offset
            distance = np.hypot(*(centroids[1 + candidates] - target).T)
            return int(candidates[np.argmin(distance)]) + 1
        return int(candidates[np.argmax(areas[candidates])]) + 1

    def _search(self, image: np.ndarray, encoding: str, bounds: tuple[int, int, int, int],
                guard_px: int, *, origin: tuple[int, int] | None = None
                ) -> tuple[float, float, int] | None:
        """
        Detect in ``image[y0:y1, x0:x1]`` (``bounds`` = x0, y0, x1, y1).

        :param guard_px: the chosen blob must keep this distance [px] to the window's edges
            inside the frame (1: not touch them), else None: a blob cut by such an edge would
            bias the centroid
        :param origin: the corner (x, y) [px] whose frame position is added last (default
            ``bounds``' own): a tight window adds its square's, so the float sums round as
            the square's search would and the detections are the same to the last bit
        :return: (u, v) in the frame and the blob's larger side [px]; None if no acceptable blob
        """
        x0, y0, x1, y1 = bounds
        height, width = image.shape[:2]
        window = image[y0:y1, x0:x1]
        mask = self._mask(window, encoding)
        if self._kernel is not None:
            mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, self._kernel)
        count, labels, stats, centroids = cv2.connectedComponentsWithStats(mask, connectivity=8)
        if count <= 1:
            return None
        if count == 2:
            # One blob, the usual case: plain Python numbers from here, a few us each step.
            left, top, w, h, area = stats[1].tolist()
            if not self.min_area_px <= area <= self.max_area_px:
                return None
            best = 1
        else:
            chosen = self._choose(stats, centroids, (x0, y0))
            if chosen is None:
                return None
            best = chosen
            left, top, w, h = stats[best, :4].tolist()
        ww, wh = x1 - x0, y1 - y0
        if (x0 > 0 and left < guard_px) or (y0 > 0 and top < guard_px) or \
                (x1 < width and left + w > ww - guard_px) or \
                (y1 < height and top + h > wh - guard_px):
            return None
        px0, py0 = max(left - _MARGIN_PX, 0), max(top - _MARGIN_PX, 0)
        px1, py1 = min(left + w + _MARGIN_PX, ww), min(top + h + _MARGIN_PX, wh)
        if count == 2:
            blob = mask[py0:py1, px0:px1]
        else:
            blob = (labels[py0:py1, px0:px1] == best).astype(np.uint8) * np.uint8(255)
        centroid = self._centroid(window[py0:py1, px0:px1], blob)
        if centroid is None:
            u, v = centroids[best]
            u, v = u - px0, v - py0
        else:
            u, v = centroid
        ox, oy = (x0, y0) if origin is None else origin
        return float(u + (px0 + x0 - ox) + ox), float(v + (py0 + y0 - oy) + oy), max(w, h)

    def _centroid(self, patch: np.ndarray, blob: np.ndarray) -> tuple[float, float] | None:
        """
        Return the soft-weighted centroid within ``patch`` (relative to it); None if no weight.

        :param patch: the image around the blob, (h, w) or (h, w, C) uint8
        :param blob: (h, w) uint8, 255 on the blob's pixels, 0 elsewhere
        """
        if patch.ndim == 2:
            signal = patch
        else:
            # max >= min: the uint8 difference does not wrap.
            signal = np.ptp(patch[:, :, :3], axis=2)
        near = cv2.dilate(blob, self._dilate)
        ring = near > cv2.dilate(blob, self._ring_kernel)
        # Background level: the outer ring of the margin, beyond the blob's anti-aliased edge.
        values = signal[ring]
        level = _median_of_integers(values) if values.size else 0.0
        # Zero outside the margin, then (signal - level) clipped at 0, in float32: the values
        # are integers or halves, exact, so the moments are those of the plain formula.
        weight = cv2.bitwise_and(signal, near).astype(np.float32)
        weight -= level
        np.maximum(weight, 0.0, out=weight)
        moments = cv2.moments(weight)
        if moments['m00'] <= 0:
            return None
        return moments['m10'] / moments['m00'], moments['m01'] / moments['m00']
