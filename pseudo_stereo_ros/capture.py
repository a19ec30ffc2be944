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
Frame sources with capture stamps: a camera device, a video file, the built-in renderer.

Every :class:`Frame` carries ``stamp_ns``, the time its image was captured on
the system clock (the clock of ROS time when ``use_sim_time`` is off), and
``available_ns``, the system time at which the program got it.  The stamp is
never the time a callback ran: at 3 m/s a stamp 1 ms late is 3 mm of error,
and a driver latency of 10 ms is as large as the naive method's whole error.

- :class:`DeviceSource`: a camera through OpenCV (V4L2 on Linux).  V4L2 stamps
  each buffer when the driver captures it, on ``CLOCK_MONOTONIC``; OpenCV
  returns that time as ``CAP_PROP_POS_MSEC``.  It is mapped to the system
  clock by the offset :class:`ClockMapping` measures right after each frame
  is read (the system clock is slewed and stepped against the monotonic one:
  by NTP, and by 5 ms/s on the virtual machine this was developed on), minus
  ``stamp_offset_s`` (exposure and readout before the driver's stamp).  A
  driver stamping on the system clock is recognised; without a usable buffer
  stamp the time ``read()`` returned is used, and the frame says so
  (``stamp_source``).
- :class:`FileSource`: a video file; a frame's stamp is ``epoch_ns`` plus
  its time in the file (the container's presentation time), so stamps are
  those of the recording whatever the playback speed.  Played at the file's
  rate or as fast as possible; looping adds the file's length each pass.
- :class:`VirtualSource`: a calibrated camera rendering a scenario of
  :mod:`pseudo_stereo_ros.sim.scenarios` at ``epoch + phase + k / fps``;
  each frame is rendered before its shutter time and released at it.

:class:`CaptureLoop` runs a source: it starts it, reads frames and hands them
on; a source that fails (a camera unplugged, ``read()`` failing) is reported
once per ``report_period_s`` while it fails, retried with a doubling back-off,
and resumes by itself.  Frames of a live source older than ``max_frame_age_s``
when read (a driver's queue after an outage) and frames not newer than the
last one handed on are dropped and counted, so nothing stale goes out.  With
``warm_up`` it calls that ``warm_up_s`` before a frame is due: the file and
virtual sources wait for each frame's time; for a device, whose ``read()``
blocks in the driver, the next frame's arrival is predicted from the last
driver stamps (their period) and the shortest recent driver latency, and
the loop waits for the warm-up before it calls ``read()`` (only while the
stamps are regular to within ``warm_up_s``; not with read-time stamps):
a detector that last ran a frame period ago runs two to three times
slower, its caches cold, than one run just before.
A source has ``description``, ``live`` (frames come from the physical world
now), ``is_open``, ``start() -> warnings`` (open it; :class:`CaptureError`
when it cannot), ``read(wait) -> Frame or None`` (None: the end, or asked to
stop; :class:`CaptureError` on failure) and ``release()``.
ROS-free: the ``camera_detector`` node is the glue.
"""

from __future__ import annotations

from collections import Counter, deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
import math
import os
import sys
import time
from typing import Protocol, TypedDict

import cv2
import numpy as np

from .camera import Camera
from .errors import CaptureError
from .records import Point3
from .sim.rendering import BallRenderer, DEFAULT_BALL_RADIUS_M, DEFAULT_BALL_RGB
from .sim.scenarios import make_scenario

__all__ = [
    'CaptureLoop',
    'ClockMapping',
    'DeviceSource',
    'FileSource',
    'Frame',
    'VirtualSource',
    'parse_device',
]

#: ``wait(seconds) -> True when asked to stop``, as :meth:`threading.Event.wait`.
Wait = Callable[[float], bool]

#: A capture stamp later than the time the frame was read by more than this is not plausible.
_FUTURE_TOLERANCE_NS = 5_000_000
#: A driver stamp further than this from the read time is taken as being on another clock.
_CLOCK_WINDOW_NS = 60_000_000_000
#: A virtual frame more than this many periods late is skipped, not delivered in a burst.
_MAX_CATCH_UP = 3
#: Driver-stamped frames in a row a device's warm-up predicts the next frame from.
_WARM_UP_HISTORY = 9


class _Capture(Protocol):
    """What this module uses of ``cv2.VideoCapture`` (tests inject fakes)."""

    def isOpened(self) -> bool: ...

    def read(self) -> tuple[bool, np.ndarray | None]: ...

    def get(self, prop: int, /) -> float: ...

    def set(self, prop: int, value: float, /) -> bool: ...  # noqa: A003 (OpenCV's name)

    def release(self) -> None: ...


#: ``factory(device) -> VideoCapture`` of a :class:`DeviceSource`.
DeviceFactory = Callable[[str | int], _Capture | None]
#: ``factory(path) -> VideoCapture`` of a :class:`FileSource`.
FileFactory = Callable[[str], _Capture | None]


class _Source(Protocol):
    """A frame source, as the module docstring describes it."""

    description: str
    live: bool

    @property
    def is_open(self) -> bool: ...

    def start(self) -> list[str]: ...

    def read(self, wait: Wait) -> Frame | None: ...

    def release(self) -> None: ...


class _Stop(Protocol):
    """A :class:`threading.Event` as :meth:`CaptureLoop.run` uses it."""

    def is_set(self) -> bool: ...

    def wait(self, timeout: float | None = None) -> bool: ...


class _Requested(TypedDict):
    fourcc: str
    width_px: int
    height_px: int
    fps: float
    exposure_s: float


@dataclass(frozen=True, eq=False)
class Frame:
    """
    One captured image.

    ``image`` is (H, W, 3) uint8 for ``bgr8`` (OpenCV's order), (H, W) for
    ``mono8``; ``stamp_ns`` the capture time and ``available_ns`` the time the
    program got the frame, both system clock [ns]; ``index`` counts the frames
    the source delivered; ``stamp_source`` says where the stamp came from
    (``driver``, ``driver (system clock)``, ``read time``, ``file``,
    ``virtual``); ``truth`` is the true ball centre [m] of a virtual frame
    (None without a ball or for real sources).
    """

    image: np.ndarray
    encoding: str
    stamp_ns: int
    available_ns: int
    index: int
    stamp_source: str
    truth: Point3 | None = None


def _encoding(image: np.ndarray) -> str:
    if image.ndim == 2:
        return 'mono8'
    return 'bgra8' if image.shape[2] == 4 else 'bgr8'


def parse_device(device: str | int) -> str | int:
    """
    Return a device as OpenCV opens it: an index (``'0'`` -> 0) or a path (``/dev/video0``).

    :raises CaptureError: an empty name
    """
    text = str(device).strip()
    if not text:
        raise CaptureError('device: empty (give /dev/videoN or an index)')
    return int(text) if text.isdigit() else text


class ClockMapping:
    """
    Map ``CLOCK_MONOTONIC`` times (V4L2 buffer stamps) to the system clock.

    The offset system - monotonic is measured by reading the system clock
    between two monotonic readings and keeping the tightest of a few tries
    (its error is half that bracket, a microsecond or less); it is measured
    again when older than ``refresh_s``, since NTP slews and steps the system
    clock (0: at every call; a measurement costs about a microsecond).

    :param refresh_s: re-measure the offset when it is older than this [s]
    :param monotonic_ns: the monotonic clock [ns] (injectable for tests)
    :param system_ns: the system clock [ns]
    """

    def __init__(self, *, refresh_s: float = 1.0,
                 monotonic_ns: Callable[[], int] = time.monotonic_ns,
                 system_ns: Callable[[], int] = time.time_ns):
        self.refresh_ns = int(refresh_s * 1e9)
        self._monotonic_ns = monotonic_ns
        self._system_ns = system_ns
        self._offset_ns: int | None = None
        self._measured_at: int | None = None
        #: Half-width of the tightest bracket of the last measurement [ns].
        self.uncertainty_ns: int | None = None

    def measure(self, tries: int = 5) -> int:
        """Measure the offset now; return it [ns] (system = monotonic + offset)."""
        best: tuple[int, int] | None = None  # (bracket width, offset) [ns]
        for _ in range(tries):
            before = self._monotonic_ns()
            system = self._system_ns()
            after = self._monotonic_ns()
            if best is None or after - before < best[0]:
                best = (after - before, system - (before + after) // 2)
        assert best is not None, 'tries must be at least 1'
        self._offset_ns = best[1]
        self.uncertainty_ns = (best[0] + 1) // 2
        self._measured_at = self._monotonic_ns()
        return self._offset_ns

    def offset_ns(self) -> int:
        """Return the current offset [ns], re-measured when older than ``refresh_s``."""
        if self._offset_ns is None or self._measured_at is None or \
                self._monotonic_ns() - self._measured_at >= self.refresh_ns:
            return self.measure()
        return self._offset_ns

    def to_system_ns(self, monotonic_ns: int) -> int:
        """Return a monotonic time [ns] on the system clock [ns]."""
        return int(monotonic_ns) + self.offset_ns()


# -- sources --------------------------------------------------------------------------------------

def _default_device_capture(device: str | int) -> cv2.VideoCapture:
    if sys.platform.startswith('linux'):
        return cv2.VideoCapture(device, cv2.CAP_V4L2)
    return cv2.VideoCapture(device)


def _fourcc_text(value: float) -> str:
    code = int(value) if math.isfinite(value) and value > 0 else 0
    return ''.join(chr((code >> (8 * i)) & 0xFF) for i in range(4)).strip('\0 ')


class _OpenCvSource:
    """What the ``VideoCapture`` sources share: the open capture and the frame counter."""

    _capture: _Capture | None
    _index: int

    def _frame(self, image: np.ndarray, stamp_ns: int, returned_ns: int, source: str) -> Frame:
        """Return the next frame (numbered in delivery order)."""
        frame = Frame(image, _encoding(image), stamp_ns, returned_ns, self._index, source)
        self._index += 1
        return frame

    def release(self) -> None:
        """Close the capture (it may be opened again)."""
        if self._capture is not None:
            self._capture.release()
            self._capture = None


class DeviceSource(_OpenCvSource):
    """
    A camera device through OpenCV ``VideoCapture`` (V4L2 on Linux).

    :param device: ``/dev/videoN`` or an index
    :param width_px: requested image width [px]; 0 keeps the driver's
    :param height_px: requested image height [px]; 0 keeps the driver's
    :param fps: requested frame rate [Hz]; 0 keeps the driver's
    :param fourcc: requested pixel format (``MJPG``, ``YUYV``, ...); '' keeps the driver's
    :param exposure_s: manual exposure time [s]; 0 leaves auto exposure on
    :param stamp_offset_s: subtracted from the driver's stamp: the time from the middle of
        the exposure to the moment the driver stamps the buffer [s]
    :param capture_factory: ``factory(device) -> VideoCapture`` (tests inject a fake)
    :param clock: the monotonic -> system mapping (by default one measured at every frame)
    :param system_ns: the system clock [ns]
    """

    live = True

    def __init__(self, device: str | int, *, width_px: int = 0, height_px: int = 0,
                 fps: float = 0.0, fourcc: str = '', exposure_s: float = 0.0,
                 stamp_offset_s: float = 0.0, capture_factory: DeviceFactory | None = None,
                 clock: ClockMapping | None = None,
                 system_ns: Callable[[], int] = time.time_ns):
        self.device = parse_device(device)
        self.description = str(device)
        if fourcc and len(fourcc) != 4:
            raise CaptureError(f'fourcc {fourcc!r}: expected four characters such as MJPG')
        for name, value in (('width_px', width_px), ('height_px', height_px), ('fps', fps),
                            ('exposure_s', exposure_s)):
            if not (math.isfinite(value) and value >= 0):
                raise CaptureError(f'{name}: expected a number >= 0, got {value!r}')
        self.requested: _Requested = {'fourcc': fourcc.upper(), 'width_px': int(width_px),
                                      'height_px': int(height_px), 'fps': float(fps),
                                      'exposure_s': float(exposure_s)}
        self.stamp_offset_ns = int(round(stamp_offset_s * 1e9))
        self._factory: DeviceFactory = capture_factory or _default_device_capture
        self.clock = clock or ClockMapping(refresh_s=0.0)
        self._system_ns = system_ns
        self._capture: _Capture | None = None
        self._index = 0
        #: What the camera delivers after :meth:`start` (read back from the driver).
        self.settings: dict[str, int | float | str] = {}

    @property
    def is_open(self) -> bool:
        """Return True while the device is open."""
        return self._capture is not None

    def start(self) -> list[str]:
        """
        Open the device and apply the requested settings, reading each back.

        :return: one warning per setting the camera refused or changed
        :raises CaptureError: the device cannot be opened
        """
        if self._factory is _default_device_capture and isinstance(self.device, str) and \
                not os.path.exists(self.device):
            # Checked here: OpenCV would print a warning of its own at every retry.
            raise CaptureError(f'{self.description}: no such device (unplugged?)')
        capture = self._factory(self.device)
        if capture is None or not capture.isOpened():
            if capture is not None:
                capture.release()
            raise CaptureError(f'{self.description}: cannot open the camera (not a capture '
                               'device, in use by another program, or no permission: is the '
                               'user in the video group?)')
        warnings = []
        wanted = self.requested
        if wanted['fourcc']:
            capture.set(cv2.CAP_PROP_FOURCC, cv2.VideoWriter.fourcc(*wanted['fourcc']))
            got_fourcc = _fourcc_text(capture.get(cv2.CAP_PROP_FOURCC))
            if got_fourcc.upper() != wanted['fourcc']:
                warnings.append(f'{self.description}: asked for fourcc {wanted["fourcc"]}, the '
                                f'camera gives {got_fourcc or "unknown"}')
        sizes = (('width_px', wanted['width_px'], cv2.CAP_PROP_FRAME_WIDTH),
                 ('height_px', wanted['height_px'], cv2.CAP_PROP_FRAME_HEIGHT))
        for _, size, prop in sizes:
            if size:
                capture.set(prop, size)
        for name, size, prop in sizes:
            got_size = int(capture.get(prop))
            if size and got_size != size:
                warnings.append(f'{self.description}: asked for {name} {size}, the '
                                f'camera gives {got_size}')
        if wanted['fps']:
            capture.set(cv2.CAP_PROP_FPS, wanted['fps'])
            got = capture.get(cv2.CAP_PROP_FPS)
            if not abs(got - wanted['fps']) <= 0.01 * wanted['fps']:
                warnings.append(f'{self.description}: asked for fps {wanted["fps"]:g}, the '
                                f'camera gives {got:g}')
        if wanted['exposure_s']:
            # V4L2: exposure_auto 1 is manual; exposure_absolute is in units of 100 us.
            capture.set(cv2.CAP_PROP_AUTO_EXPOSURE, 1)
            capture.set(cv2.CAP_PROP_EXPOSURE, wanted['exposure_s'] * 1e4)
            got = capture.get(cv2.CAP_PROP_EXPOSURE) / 1e4
            if not abs(got - wanted['exposure_s']) <= 1e-4:
                warnings.append(f'{self.description}: asked for exposure_s '
                                f'{wanted["exposure_s"]:g}, the camera gives {got:g} (auto '
                                'exposure may still be on)')
        self.settings = {
            'width_px': int(capture.get(cv2.CAP_PROP_FRAME_WIDTH)),
            'height_px': int(capture.get(cv2.CAP_PROP_FRAME_HEIGHT)),
            'fps': float(capture.get(cv2.CAP_PROP_FPS)),
            'fourcc': _fourcc_text(capture.get(cv2.CAP_PROP_FOURCC)),
        }
        self._capture = capture
        self.clock.measure()
        return warnings

    def stamp(self, pos_msec: float, returned_ns: int) -> tuple[int, str]:
        """
        Return the capture stamp [ns] of a frame and where it came from.

        :param pos_msec: ``CAP_PROP_POS_MSEC`` after the read (V4L2: the buffer's monotonic
            capture time [ms]; 0 or less when the driver gives none)
        :param returned_ns: system time when ``read()`` returned [ns]
        :return: ``(stamp_ns, source)``: the driver's stamp on the system clock minus
            ``stamp_offset_s``, or the read time when the driver's stamp is not usable
        """
        if math.isfinite(pos_msec) and pos_msec > 0:
            driver_ns = int(round(pos_msec * 1e6))
            for stamp, source in ((self.clock.to_system_ns(driver_ns), 'driver'),
                                  (driver_ns, 'driver (system clock)')):
                age = returned_ns - stamp
                if -_FUTURE_TOLERANCE_NS <= age <= _CLOCK_WINDOW_NS:
                    return stamp - self.stamp_offset_ns, source
        return returned_ns - self.stamp_offset_ns, 'read time'

    def read(self, wait: Wait) -> Frame:
        """
        Read the next frame (blocks until the camera delivers one).

        :param wait: unused (the driver paces the frames)
        :return: the frame
        :raises CaptureError: the device is not open or delivered no frame
        """
        if self._capture is None:
            raise CaptureError(f'{self.description}: not open')
        ok, image = self._capture.read()
        returned_ns = self._system_ns()
        if not ok or image is None or image.size == 0:
            raise CaptureError(f'{self.description}: no frame (read failed: camera unplugged '
                               'or stopped?)')
        stamp_ns, source = self.stamp(self._capture.get(cv2.CAP_PROP_POS_MSEC), returned_ns)
        return self._frame(image, stamp_ns, returned_ns, source)


class FileSource(_OpenCvSource):
    """
    A video file played with the stamps of its frames.

    :param path: the file (anything OpenCV's FFmpeg reads: avi, mp4, mkv, ...)
    :param epoch_ns: stamp of the file's time 0 [ns]; 0: the system time of the first read
    :param realtime: play at the file's rate (True) or as fast as frames can be read; when
        the first frame's stamp is in the future each frame is released at its stamp (files
        given one epoch play in step), else at the file's pace from the first read
    :param loop: start again at the end; each pass adds the file's length to the stamps
    :param capture_factory: ``factory(path) -> VideoCapture`` (tests may inject a fake)
    :param system_ns: the system clock [ns]
    """

    live = False

    def __init__(self, path: str, *, epoch_ns: int = 0, realtime: bool = True,
                 loop: bool = False, capture_factory: FileFactory | None = None,
                 system_ns: Callable[[], int] = time.time_ns):
        if not str(path):
            raise CaptureError('video file: empty path')
        self.path = str(path)
        self.description = self.path
        self.epoch_ns = int(epoch_ns)
        self.realtime = bool(realtime)
        self.loop = bool(loop)
        self._factory: FileFactory = capture_factory or cv2.VideoCapture
        self._system_ns = system_ns
        self._capture: _Capture | None = None
        self._index = 0            # frames delivered, all passes
        self._pass_frames = 0      # frames read in this pass
        self._pass_offset_ns = 0.0  # added to the file times of this pass
        self._last_time_ns: float | None = None  # file time of the previous frame of this pass
        self._start: tuple[int, int] | None = None  # (system ns, stamp ns) of the first frame
        #: How late [s] the first frame was for its stamp when a given epoch had already passed
        #: (it then plays at the file's pace from its first read); None otherwise.
        self.late_start_s: float | None = None
        self.period_ns: float | None = None
        self.settings: dict[str, int | float] = {}

    @property
    def is_open(self) -> bool:
        """Return True while the file is open."""
        return self._capture is not None

    def start(self) -> list[str]:
        """
        Open the file.

        :return: no warnings (kept for the source interface)
        :raises CaptureError: the file is missing or not a video OpenCV can decode
        """
        capture = self._factory(self.path)
        if capture is None or not capture.isOpened():
            if capture is not None:
                capture.release()
            raise CaptureError(f'{self.path}: cannot open the video file (missing, not a '
                               'video, or a codec OpenCV lacks)')
        fps = capture.get(cv2.CAP_PROP_FPS)
        self.period_ns = 1e9 / fps if math.isfinite(fps) and fps > 0 else None
        self.settings = {'fps': float(fps), 'frames': int(capture.get(cv2.CAP_PROP_FRAME_COUNT)),
                         'width_px': int(capture.get(cv2.CAP_PROP_FRAME_WIDTH)),
                         'height_px': int(capture.get(cv2.CAP_PROP_FRAME_HEIGHT))}
        self._capture = capture
        return []

    def _file_time_ns(self) -> float:
        """Return the file time [ns] of the frame just read: its presentation time."""
        assert self._capture is not None, 'called by read() on an open file'
        pos_msec = self._capture.get(cv2.CAP_PROP_POS_MSEC)
        if math.isfinite(pos_msec) and pos_msec >= 0:
            time_ns = pos_msec * 1e6
            if self._last_time_ns is None or time_ns > self._last_time_ns:
                return time_ns
        if self.period_ns is None:
            raise CaptureError(f'{self.path}: frames have no times and the file no frame rate')
        # No usable presentation time: the frame's place times the nominal period.
        return self._pass_frames * self.period_ns

    def _rewind(self) -> bool:
        """Start the next pass; return False when the file gave no frame in this one."""
        if self._pass_frames == 0 or self._last_time_ns is None:
            return False
        self._pass_offset_ns += self._last_time_ns + (self.period_ns or 0.0)
        self._pass_frames = 0
        self._last_time_ns = None
        assert self._capture is not None, 'called by read() on an open file'
        if not self._capture.set(cv2.CAP_PROP_POS_FRAMES, 0):
            self.release()
            self.start()
        return True

    def read(self, wait: Wait) -> Frame | None:
        """
        Read the next frame; with ``realtime`` wait until its time comes.

        :param wait: ``wait(seconds) -> True when asked to stop``
        :return: the frame; None at the end of the file (without ``loop``) or when stopped
        :raises CaptureError: the file is not open or holds no frame
        """
        if self._capture is None:
            raise CaptureError(f'{self.path}: not open')
        ok, image = self._capture.read()
        if not ok or image is None:
            if not self.loop or not self._rewind():
                if self._index == 0:
                    raise CaptureError(f'{self.path}: no frame could be decoded')
                return None
            ok, image = self._capture.read()
            if not ok or image is None:
                return None
        time_ns = self._file_time_ns()
        self._last_time_ns = time_ns
        self._pass_frames += 1
        if self._start is None:
            now = self._system_ns()
            if self.epoch_ns == 0:
                self.epoch_ns = now - int(round(time_ns))
            first = self.epoch_ns + int(round(time_ns))
            # Stamps in the future: release each frame at its stamp, so files given one epoch
            # play in step; else at the file's pace from now.
            self._start = (first, first) if first >= now else (now, first)
            if self.realtime and first < now:
                self.late_start_s = (now - first) / 1e9
        # Float ns within the file (exact to well under 1 ns for hours), integer stamps.
        stamp_ns = self.epoch_ns + int(round(self._pass_offset_ns + time_ns))
        if self.realtime:
            due_ns = self._start[0] + (stamp_ns - self._start[1])
            remaining = due_ns - self._system_ns()
            if remaining > 0 and wait(remaining / 1e9):
                return None
        return self._frame(image, stamp_ns, self._system_ns(), 'file')


class VirtualSource:
    """
    The built-in camera: renders a scenario at exact shutter times.

    Frame ``k`` has the stamp ``epoch + phase + round(k / fps)`` [ns] and shows
    the ball where the scenario puts it then (:class:`BallRenderer`: exact,
    anti-aliased, with the calibration's distortion).  With ``loop`` the
    scenario repeats after ``pause_s`` without a ball (a new flight).

    :param camera: the calibrated camera
    :param scenario: a name of :data:`pseudo_stereo_ros.sim.scenarios.SCENARIOS`
    :param fps: frame rate [Hz]
    :param phase_s: delay of the first shutter after the epoch [s]
    :param epoch_ns: system time of scenario time 0 [ns]; 0: 0.2 s after construction
    :param loop: repeat the scenario
    :param pause_s: time without a ball between repetitions [s]
    :param radius_m: ball radius [m]
    :param ball_rgb: ball colour (R, G, B)
    :param noise_std: pixel noise [grey levels]
    :param seed: random seed of background and noise
    :param system_ns: the system clock [ns]
    """

    live = False

    def __init__(self, camera: Camera, *, scenario: str = 'spiral', fps: float = 30.0,
                 phase_s: float = 0.0, epoch_ns: int = 0, loop: bool = True,
                 pause_s: float = 0.5, radius_m: float = DEFAULT_BALL_RADIUS_M,
                 ball_rgb: Sequence[int] = DEFAULT_BALL_RGB, noise_std: float = 2.0,
                 seed: int = 0, system_ns: Callable[[], int] = time.time_ns):
        if not (math.isfinite(fps) and fps > 0):
            raise CaptureError(f'fps: expected a positive frame rate, got {fps!r}')
        if not phase_s >= 0 or not pause_s >= 0:
            raise CaptureError('phase_s and pause_s must be >= 0')
        self.camera = camera
        self.description = f'virtual {camera.name} ({scenario}, {fps:g} fps)'
        self.scenario = make_scenario(scenario)
        self.renderer = BallRenderer(camera, radius_m=radius_m, ball_rgb=ball_rgb,
                                     noise_std=noise_std, seed=seed)
        self.period_ns = 1e9 / fps
        self.phase_ns = int(round(phase_s * 1e9))
        self.loop = bool(loop)
        self.pause_s = float(pause_s)
        self._system_ns = system_ns
        self.epoch_ns = int(epoch_ns) if epoch_ns else system_ns() + 200_000_000
        self._next_index = 0
        self._prepared: tuple[int, np.ndarray | None, Point3 | None] | None = None
        #: Counts: ``skipped`` frames (late by more than a few periods).
        self.stats: Counter[str] = Counter()

    is_open = True

    def start(self) -> list[str]:
        """Nothing to open; return no warnings."""
        return []

    def release(self) -> None:
        """Nothing to release."""

    def stamp_of(self, index: int) -> int:
        """Return the shutter stamp [ns] of frame ``index``."""
        return self.epoch_ns + self.phase_ns + int(round(index * self.period_ns))

    def render(self, index: int) -> tuple[np.ndarray | None, Point3 | None]:
        """
        Render frame ``index``.

        :return: ``(image, truth)``: the bgr8 image (None once a scenario without ``loop`` is
            over) and the true ball centre [m] (None between repetitions, when there is no
            ball)
        """
        seconds = (self.stamp_of(index) - self.epoch_ns) / 1e9
        if self.loop:
            seconds %= self.scenario.duration_s + self.pause_s
        if seconds > self.scenario.duration_s:
            if not self.loop:
                return None, None
            return self.renderer.render(None), None
        position = self.scenario.position(np.array([seconds]))[0]
        x, y, z = (float(c) for c in position)
        return self.renderer.render(position), (x, y, z)

    def read(self, wait: Wait) -> Frame | None:
        """
        Render the next frame ahead of its shutter and return it at its shutter time.

        :param wait: ``wait(seconds) -> True when asked to stop``
        :return: the frame; None when stopped or when a scenario without ``loop`` is over
        """
        while True:
            index = self._next_index
            stamp_ns = self.stamp_of(index)
            if stamp_ns < self._system_ns() - _MAX_CATCH_UP * self.period_ns:
                self._next_index += 1
                self.stats['skipped'] += 1
                continue
            if self._prepared is None or self._prepared[0] != index:
                self._prepared = (index, *self.render(index))
            _, image, truth = self._prepared
            if image is None:
                return None
            remaining = stamp_ns - self._system_ns()
            if remaining > 0 and wait(remaining / 1e9):
                return None
            available_ns = self._system_ns()
            self._next_index += 1
            self._prepared = None
            return Frame(image, 'bgr8', stamp_ns, available_ns, index, 'virtual', truth)


# -- the loop -------------------------------------------------------------------------------------

class CaptureLoop:
    """
    Read a source until stopped: hand frames on, report failures, retry, resume.

    :param source: a :class:`DeviceSource`, :class:`FileSource` or :class:`VirtualSource`
    :param on_frame: called with every frame that is handed on
    :param report: ``report(level, text)`` with level ``'info'``, ``'warn'`` or ``'error'``
    :param report_period_s: least time between two reports of a continuing failure [s]
    :param retry_initial_s: wait after the first failure before retrying [s]; it doubles with
        every further failure, up to ``retry_max_s``
    :param retry_max_s: longest wait between retries [s]
    :param max_frame_age_s: frames of a live source older than this when read are dropped
        (``stale``) [s]
    :param warm_up: called ``warm_up_s`` before a frame is due, when the source waits for the
        frame's time or, for a live source, before its predicted arrival (``warm_ups`` counts
        the calls); None for none
    :param warm_up_s: how long before the frame is due [s]
    :param clock: monotonic clock [s] for the reports and the warm-up (injectable for tests)
    :param system_ns: the system clock [ns] (of the frames' stamps; injectable for tests)
    """

    def __init__(self, source: _Source, on_frame: Callable[[Frame], None], *,
                 report: Callable[[str, str], None] | None = None,
                 report_period_s: float = 1.0, retry_initial_s: float = 0.1,
                 retry_max_s: float = 2.0, max_frame_age_s: float = 0.5,
                 warm_up: Callable[[], None] | None = None, warm_up_s: float = 0.002,
                 clock: Callable[[], float] = time.monotonic,
                 system_ns: Callable[[], int] = time.time_ns):
        if not (0 < retry_initial_s <= retry_max_s):
            raise CaptureError(f'need 0 < retry_initial_s <= retry_max_s, got '
                               f'{retry_initial_s}, {retry_max_s}')
        if not (math.isfinite(warm_up_s) and warm_up_s >= 0):
            raise CaptureError(f'warm_up_s: expected a time >= 0 s, got {warm_up_s!r}')
        self.source = source
        self.on_frame = on_frame
        self.report = report or (lambda level, text: None)
        self.report_period_s = float(report_period_s)
        self.retry_initial_s = float(retry_initial_s)
        self.retry_max_s = float(retry_max_s)
        self.max_frame_age_ns = int(max_frame_age_s * 1e9)
        self.warm_up = warm_up
        self.warm_up_s = float(warm_up_s)
        self.clock = clock
        self.system_ns = system_ns
        # (stamp, available) [ns] of the last driver-stamped frames of a live source.
        self._arrivals: deque[tuple[int, int]] = deque(maxlen=_WARM_UP_HISTORY)
        # Set once the source waits for its frames' times itself (the warm-up runs in the wait).
        self._source_waits = False
        #: Counts: ``frames`` read, ``delivered``, ``stale``, ``not_newer``, ``failures``,
        #: ``reports``, ``recoveries``, ``warm_ups``.
        self.stats: Counter[str] = Counter()
        self._failing_since: float | None = None
        self._outage_failures = 0
        self._last_report: float | None = None
        self._last_error: CaptureError | None = None
        self._last_stamp_ns: int | None = None

    @property
    def failing(self) -> bool:
        """Return whether the source is failing now (from a failure to the next frame)."""
        return self._failing_since is not None

    def retry_delay_s(self) -> float:
        """Return the wait before the next retry [s]: doubling per failure, capped."""
        exponent = max(self._outage_failures - 1, 0)
        return min(self.retry_initial_s * 2.0 ** min(exponent, 30), self.retry_max_s)

    def _failed(self, error: CaptureError) -> None:
        self._arrivals.clear()
        now = self.clock()
        self.stats['failures'] += 1
        self._outage_failures += 1
        self._last_error = error
        if self._failing_since is None:
            self._failing_since = now
        if self._last_report is None or now - self._last_report >= self.report_period_s:
            self._report_failure(now, self.retry_delay_s())

    def _report_failure(self, now: float, retry_in_s: float) -> None:
        assert self._failing_since is not None, 'called while failing'
        self._last_report = now
        self.stats['reports'] += 1
        self.report('error', f'{self._last_error} (failing for '
                             f'{now - self._failing_since:.1f} s, {self._outage_failures} '
                             f'attempts; retrying in {retry_in_s:.2g} s)')

    def _wait_to_retry(self, stop: _Stop) -> None:
        """Wait out the back-off; report the continuing failure once per report period."""
        retry_at = self.clock() + self.retry_delay_s()
        while True:
            now = self.clock()
            assert self._last_report is not None, '_failed() reported the failure'
            next_report = self._last_report + self.report_period_s
            if stop.wait(max(min(retry_at, next_report) - now, 0.0)):
                return
            now = self.clock()
            if now >= retry_at:
                return
            if now >= next_report:
                self._report_failure(now, retry_at - now)

    def _recovered(self) -> None:
        if self._failing_since is None:
            return
        self.stats['recoveries'] += 1
        self.report('info', f'{self.source.description}: delivering again after '
                            f'{self.clock() - self._failing_since:.1f} s '
                            f'({self._outage_failures} failed attempts)')
        self._failing_since = None
        self._outage_failures = 0
        self._last_report = None

    def _waiter(self, stop: _Stop) -> Wait:
        """Return the ``wait`` the source gets: ``stop.wait``, warming up before the end."""
        if self.warm_up is None:
            return stop.wait
        warm_up = self.warm_up

        def wait(seconds: float) -> bool:
            self._source_waits = True
            if seconds <= self.warm_up_s:
                return stop.wait(seconds)
            end = self.clock() + seconds
            if stop.wait(seconds - self.warm_up_s):
                return True
            warm_up()
            self.stats['warm_ups'] += 1
            return stop.wait(max(end - self.clock(), 0.0))

        return wait

    def _warm_up_live(self, stop: _Stop) -> bool:
        """
        Before a live source's ``read()``: wait for, and run, the warm-up of its next frame.

        The frame is predicted at the last stamp plus the stamps' period (their
        median step) plus the shortest recent latency (stamp -> available), which
        a frame does not beat, so waiting here delays none; nothing happens while
        the steps vary by more than ``warm_up_s`` (dropped frames, a variable rate)
        or when the prediction leaves less than ``warm_up_s``.

        :return: True when asked to stop
        """
        arrivals = self._arrivals
        if self.warm_up is None or self._source_waits or len(arrivals) < _WARM_UP_HISTORY:
            return False
        stamps = [stamp for stamp, _ in arrivals]
        steps = sorted(b - a for a, b in zip(stamps, stamps[1:]))
        if steps[-1] - steps[0] > self.warm_up_s * 1e9:
            return False
        latency = min(available - stamp for stamp, available in arrivals)
        step = steps[len(steps) // 2]
        due_ns = stamps[-1] + step + latency
        lead_s = (due_ns - self.system_ns()) / 1e9
        # Beyond the prediction's own horizon (one period and the latency) the system clock
        # was stepped back (NTP): no warm-up rather than a wait for the size of the step.
        if not self.warm_up_s < lead_s <= (step + max(latency, 0)) / 1e9 + self.warm_up_s:
            return False
        if stop.wait(lead_s - self.warm_up_s):
            return True
        self.warm_up()
        self.stats['warm_ups'] += 1
        return False

    def run(self, stop: _Stop) -> str:
        """
        Run until ``stop`` is set or the source ends.

        :param stop: a :class:`threading.Event` (or anything with ``is_set()`` and
            ``wait(seconds) -> bool``)
        :return: ``'stopped'`` or ``'ended'`` (a file or a non-looping scenario is over)
        """
        wait = self._waiter(stop)
        while not stop.is_set():
            if not self.source.is_open:
                try:
                    for warning in self.source.start():
                        self.report('warn', warning)
                except CaptureError as err:
                    self._failed(err)
                    self._wait_to_retry(stop)
                    continue
            if self.source.live and self._warm_up_live(stop):
                break
            try:
                frame = self.source.read(wait)
            except CaptureError as err:
                self.source.release()
                self._failed(err)
                self._wait_to_retry(stop)
                continue
            if frame is None:
                if stop.is_set():
                    break
                self.report('info', f'{self.source.description}: end of stream after '
                                    f'{self.stats["frames"]} frames')
                return 'ended'
            self._recovered()
            self.stats['frames'] += 1
            if self.source.live and frame.available_ns - frame.stamp_ns > self.max_frame_age_ns:
                self.stats['stale'] += 1
                continue
            if self._last_stamp_ns is not None and frame.stamp_ns <= self._last_stamp_ns:
                self.stats['not_newer'] += 1
                continue
            self._last_stamp_ns = frame.stamp_ns
            if self.source.live:
                if frame.stamp_source.startswith('driver'):
                    self._arrivals.append((frame.stamp_ns, frame.available_ns))
                else:
                    self._arrivals.clear()
            self.stats['delivered'] += 1
            self.on_frame(frame)
        return 'stopped'
