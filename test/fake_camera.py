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
A fake V4L2 camera for the tests: there is no hardware here.

:class:`FakeDevice` is a ``capture_factory``: called with a device it returns
a :class:`FakeCapture` with the ``cv2.VideoCapture`` methods the device source
uses.  Frames are captured at ``t0 + k / fps`` on the monotonic clock and
delivered ``latency_s`` later (a driver's latency), with
``CAP_PROP_POS_MSEC`` = the capture time in ms on ``CLOCK_MONOTONIC`` as
OpenCV's V4L2 backend reports the buffer stamp (or on the system clock, or
none).  During ``outage`` (seconds after creation) the camera is unplugged:
``read()`` fails and opening fails.  After an outage the first frame read can
be a stale one from before it (a driver queue), if ``stale_after_outage``.
"""

import threading
import time

import cv2


class FakeDevice:
    """
    A fake camera and the factory of its captures.

    :param image: the frame every read returns (bgr8)
    :param fps: frame rate [Hz]
    :param phase_s: first capture after creation [s]
    :param latency_s: capture -> read() returns [s]
    :param outage: ``(start, end)`` seconds after creation when the camera is unplugged
    :param stamp_clock: ``'monotonic'``, ``'system'`` or ``'none'`` (POS_MSEC is 0)
    :param refuse: property -> the value the camera gives instead of the requested one
    :param stale_after_outage: deliver one frame captured before the outage first
    """

    def __init__(self, image, *, fps=30.0, phase_s=0.0, latency_s=0.008, outage=None,
                 stamp_clock='monotonic', refuse=None, stale_after_outage=False):
        self.image = image
        self.period_ns = int(round(1e9 / fps))
        self.t0_ns = time.monotonic_ns() + int(round(phase_s * 1e9))
        self.latency_ns = int(round(latency_s * 1e9))
        self.outage = outage
        self.stamp_clock = stamp_clock
        self.refuse = dict(refuse or {})
        self.stale_after_outage = stale_after_outage
        self.lock = threading.Lock()
        #: Frame index -> capture time on the system clock [ns], of every frame delivered.
        self.captured = {}
        self.opens = 0
        self.next_index = 0
        self.pending_stale = None

    def unplugged(self, monotonic_ns=None) -> bool:
        """Return whether the camera is unplugged at a monotonic time (default: now)."""
        if self.outage is None:
            return False
        now = time.monotonic_ns() if monotonic_ns is None else monotonic_ns
        seconds = (now - self.t0_ns) / 1e9
        return self.outage[0] <= seconds < self.outage[1]

    def capture_mono_ns(self, index) -> int:
        """Return the monotonic capture time [ns] of frame ``index``."""
        return self.t0_ns + index * self.period_ns

    def __call__(self, device):
        """Open the device: a new capture (not opened while unplugged)."""
        self.opens += 1
        return FakeCapture(self, opened=not self.unplugged())


class FakeCapture:
    """The ``cv2.VideoCapture`` methods the device source uses, on a :class:`FakeDevice`."""

    def __init__(self, device, *, opened):
        self.device = device
        self.opened = opened
        self.props = {cv2.CAP_PROP_FRAME_WIDTH: float(device.image.shape[1]),
                      cv2.CAP_PROP_FRAME_HEIGHT: float(device.image.shape[0]),
                      cv2.CAP_PROP_FPS: 1e9 / device.period_ns,
                      cv2.CAP_PROP_FOURCC: float(cv2.VideoWriter_fourcc(*'YUYV')),
                      cv2.CAP_PROP_EXPOSURE: 100.0, cv2.CAP_PROP_POS_MSEC: 0.0}

    def isOpened(self):  # noqa: N802 - OpenCV's name
        return self.opened

    def set(self, prop, value):  # noqa: A003 - OpenCV's name
        if prop in self.device.refuse:
            self.props[prop] = float(self.device.refuse[prop])
            return False
        self.props[prop] = float(value)
        return True

    def get(self, prop):
        return self.props.get(prop, -1.0)

    def release(self):
        self.opened = False

    def _fail(self):
        """Fail a read: unplugged. The driver keeps the last frame queued (a stale one)."""
        device = self.device
        if device.stale_after_outage and device.pending_stale is None and device.captured:
            device.pending_stale = max(device.captured)
        return False, None

    def read(self):
        device = self.device
        if not self.opened:
            return False, None
        if device.unplugged():
            time.sleep(0.002)
            return self._fail()
        with device.lock:
            if device.pending_stale is not None and device.captured:
                index, device.pending_stale = device.pending_stale, None
                device.stale_after_outage = False
            else:
                earliest = -(-(time.monotonic_ns() - device.latency_ns - device.t0_ns)
                             // device.period_ns)
                index = max(device.next_index, earliest, 0)
                device.next_index = index + 1
        capture_ns = device.capture_mono_ns(index)
        delay = (capture_ns + device.latency_ns - time.monotonic_ns()) / 1e9
        if delay > 0:
            time.sleep(delay)
        if device.unplugged():
            return self._fail()
        system_capture_ns = time.time_ns() - (time.monotonic_ns() - capture_ns)
        device.captured.setdefault(index, system_capture_ns)
        if device.stamp_clock == 'monotonic':
            self.props[cv2.CAP_PROP_POS_MSEC] = capture_ns / 1e6
        elif device.stamp_clock == 'system':
            self.props[cv2.CAP_PROP_POS_MSEC] = system_capture_ns / 1e6
        else:
            self.props[cv2.CAP_PROP_POS_MSEC] = 0.0
        return True, device.image.copy()
