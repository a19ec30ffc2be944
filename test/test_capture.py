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
The frame sources and the capture loop, without a ROS graph.

The device source runs on a fake camera (:mod:`fake_camera`; there is no
hardware here) that stamps its buffers on ``CLOCK_MONOTONIC`` as V4L2 does
and delivers them a driver latency later; file sources read MJPG videos the
tests write with ``cv2.VideoWriter``; the capture loop's reporting and
back-off run on a fake clock.
"""

import math
import threading
import time

import cv2
from fake_camera import FakeDevice
import numpy as np
from pseudo_stereo_ros.capture import (CaptureLoop, ClockMapping, DeviceSource, FileSource, Frame,
                                       parse_device, VirtualSource)
from pseudo_stereo_ros.detection import BallDetector
from pseudo_stereo_ros.errors import CaptureError
from pseudo_stereo_ros.sim.rendering import BallRenderer
from pseudo_stereo_ros.sim.scenarios import default_rig, make_scenario, truth_at
import pytest

BALL = (1.2, 0.8, 1.1)


def _image(camera_index=0):
    camera = default_rig()[camera_index]
    return BallRenderer(camera, radius_m=0.03, seed=camera_index).render(BALL)


def _read(source, count, stop=None):
    stop = stop or threading.Event()
    return [source.read(stop.wait) for _ in range(count)]


# -- clock mapping -------------------------------------------------------------------------------

def test_clock_mapping_matches_the_system_clock():
    clock = ClockMapping()
    offset = clock.measure()
    expected = time.time_ns() - time.monotonic_ns()
    # The bracket is a microsecond or so; a loaded machine may preempt between the two reads.
    assert abs(offset - expected) < 2_000_000
    assert clock.uncertainty_ns < 1_000_000
    now_mono = time.monotonic_ns()
    assert abs(clock.to_system_ns(now_mono) - time.time_ns()) < 2_000_000


@pytest.mark.parametrize('seed', range(20))
def test_clock_mapping_is_within_its_bracket(seed):
    # Fake clocks: each reading advances monotonic time by a random step; the system clock
    # reads monotonic + offset at its own instant. The estimate is within the tightest bracket.
    rng = np.random.default_rng(seed)
    offset = int(rng.integers(-10**18, 10**18))
    steps = iter(rng.integers(1, 5000, 100).tolist())
    state = {'t': 10**12}

    def tick():
        state['t'] += next(steps)
        return state['t']

    clock = ClockMapping(monotonic_ns=tick, system_ns=lambda: tick() + offset)
    estimate = clock.measure()
    assert abs(estimate - offset) <= clock.uncertainty_ns + 1


def test_clock_mapping_measures_again_after_refresh():
    state = {'t': 0, 'offset': 1000}
    clock = ClockMapping(refresh_s=1.0, monotonic_ns=lambda: state['t'],
                         system_ns=lambda: state['t'] + state['offset'])
    assert clock.offset_ns() == 1000
    state['offset'] = 5000  # NTP stepped the system clock
    state['t'] = 500_000_000
    assert clock.offset_ns() == 1000  # not yet measured again
    state['t'] = 1_500_000_001
    assert clock.offset_ns() == 5000


# -- device source (fake camera) -----------------------------------------------------------------

@pytest.mark.parametrize('stamp_clock, source_name', [('monotonic', 'driver'),
                                                      ('system', 'driver (system clock)')])
def test_device_stamps_are_the_driver_capture_times(stamp_clock, source_name):
    device = FakeDevice(_image(), latency_s=0.008, stamp_clock=stamp_clock)
    source = DeviceSource('0', capture_factory=device, stamp_offset_s=0.0)
    assert source.start() == []
    frames = _read(source, 6)
    source.release()
    for frame in frames:
        captured = device.captured[frame_index(device, frame)]
        assert frame.stamp_source == source_name
        # The capture time itself (the offset is measured to a microsecond, but the system
        # clock of a VM may step by 0.5 ms between two readings), not the read time ...
        assert abs(frame.stamp_ns - captured) < 1_000_000
        # ... which is a driver latency (8 ms) later.
        assert frame.available_ns - frame.stamp_ns > 7_000_000
    assert all(b.stamp_ns > a.stamp_ns for a, b in zip(frames, frames[1:]))


def frame_index(device, frame):
    """Return the fake device's index of a frame: the capture nearest to its stamp."""
    return min(device.captured, key=lambda i: abs(device.captured[i] - frame.stamp_ns))


def test_device_stamp_offset_is_subtracted():
    device = FakeDevice(_image(), latency_s=0.004)
    source = DeviceSource('/dev/null', capture_factory=device, stamp_offset_s=0.0025)
    source.start()
    frame = _read(source, 1)[0]
    source.release()
    captured = device.captured[max(device.captured)]
    assert abs(frame.stamp_ns - (captured - 2_500_000)) < 1_000_000


def test_device_without_buffer_stamps_uses_the_read_time():
    device = FakeDevice(_image(), latency_s=0.002, stamp_clock='none')
    source = DeviceSource(0, capture_factory=device)
    source.start()
    frame = _read(source, 1)[0]
    assert frame.stamp_source == 'read time' and frame.stamp_ns == frame.available_ns
    # A buffer stamp on neither clock (decades off) is not used either.
    stamp, kind = source.stamp(123.0, time.time_ns())
    assert kind == 'read time'


def test_device_settings_are_read_back_and_refusals_named():
    device = FakeDevice(_image(), refuse={cv2.CAP_PROP_FRAME_WIDTH: 640,
                                          cv2.CAP_PROP_FOURCC: cv2.VideoWriter_fourcc(*'YUYV')})
    source = DeviceSource(0, width_px=1280, height_px=480, fps=30.0, fourcc='MJPG',
                          exposure_s=0.01, capture_factory=device)
    warnings = source.start()
    assert any('width_px 1280' in w and 'gives 640' in w for w in warnings)
    assert any('fourcc MJPG' in w and 'gives YUYV' in w for w in warnings)
    assert not any('height_px' in w or 'fps' in w or 'exposure' in w for w in warnings)
    assert source.settings['fourcc'] == 'YUYV' and source.settings['width_px'] == 640


@pytest.mark.parametrize('kwargs, match', [
    ({'fourcc': 'MJPEG'}, 'fourcc'),
    ({'fps': -1.0}, 'fps'),
    ({'width_px': math.nan}, 'width_px'),
])
def test_device_bad_options_are_named(kwargs, match):
    with pytest.raises(CaptureError, match=match):
        DeviceSource(0, **kwargs)


def test_device_that_cannot_open_says_so():
    with pytest.raises(CaptureError, match='/dev/video_none: no such device'):
        DeviceSource('/dev/video_none').start()
    device = FakeDevice(_image(), outage=(0.0, 60.0))
    with pytest.raises(CaptureError, match='cannot open the camera'):
        DeviceSource(0, capture_factory=device).start()
    assert parse_device(' 2 ') == 2 and parse_device('/dev/video2') == '/dev/video2'
    with pytest.raises(CaptureError, match='empty'):
        parse_device('')


# -- the capture loop on a fake clock ------------------------------------------------------------

class FakeStop:
    """A stop event whose waits advance a fake clock."""

    def __init__(self, clock, until_s):
        self.clock = clock
        self.until_s = until_s
        self.waits = []

    def is_set(self):
        return self.clock[0] >= self.until_s

    def wait(self, seconds):
        self.waits.append(seconds)
        self.clock[0] += seconds
        return self.is_set()


class ScriptedSource:
    """A live source on the fake clock: a frame every 1/30 s; fails while ``down(t)``."""

    live = True
    description = 'scripted'

    def __init__(self, clock, down, *, stale_at=None):
        self.clock = clock
        self.down = down
        self.is_open = False
        self.stale_at = stale_at  # fake time after which one stale frame is delivered
        self.index = 0

    def start(self):
        if self.down(self.clock[0]):
            raise CaptureError('scripted: cannot open')
        self.is_open = True
        return []

    def read(self, wait):
        wait(1 / 30)
        now = self.clock[0]
        if self.down(now):
            raise CaptureError('scripted: no frame')
        stamp = int(now * 1e9)
        if self.stale_at is not None and now >= self.stale_at:
            self.stale_at = None
            stamp -= 2_000_000_000  # from the driver's queue, before the outage
        self.index += 1
        return Frame(np.zeros((4, 4, 3), np.uint8), 'bgr8', stamp, int(now * 1e9) + 1000,
                     self.index, 'driver')

    def release(self):
        self.is_open = False


def test_failing_source_is_reported_once_per_period_retried_with_backoff_and_resumes():
    clock = [0.0]
    outage = (1.0, 6.0)
    source = ScriptedSource(clock, lambda t: outage[0] <= t < outage[1], stale_at=outage[1])
    reports, frames = [], []
    loop = CaptureLoop(source, frames.append, report=lambda level, text: reports.append(
        (clock[0], level, text)), report_period_s=1.0, retry_initial_s=0.1, retry_max_s=0.8,
        max_frame_age_s=0.5, clock=lambda: clock[0])
    stop = FakeStop(clock, until_s=8.0)
    assert loop.run(stop) == 'stopped'
    errors = [r for r in reports if r[1] == 'error']
    recovered = [r for r in reports if r[1] == 'info']
    assert len(recovered) == 1 and 'delivering again after 5.' in recovered[0][2]
    # Back in service at most one back-off (0.8 s) after the camera returned.
    assert outage[1] <= recovered[0][0] < outage[1] + 0.8 + 0.1
    # Reported once per second while it failed (from the first failure to the recovery).
    assert len(errors) == math.floor(recovered[0][0] - errors[0][0]) + 1
    np.testing.assert_allclose(np.diff([r[0] for r in errors]), 1.0, atol=1e-9)
    assert 'scripted: no frame' in errors[0][2] and 'retrying in 0.1 s' in errors[0][2]
    assert 'scripted: cannot open' in errors[-1][2]
    # Retries 0.1, 0.2, 0.4 s after the failures before them, then every 0.8 s (the cap)
    # until one lands after the outage: that many failed attempts.
    attempt, gap, expected = errors[0][0], 0.1, 0
    while attempt < outage[1]:
        expected += 1
        attempt += gap
        gap = min(2 * gap, 0.8)
    assert loop.stats['failures'] == expected
    assert max(stop.waits) <= 0.8 + 1e-9
    assert loop.stats['recoveries'] == 1 and not loop.failing
    # Nothing stale goes out: the queued frame is dropped, stamps only grow.
    assert loop.stats['stale'] == 1
    stamps = [f.stamp_ns for f in frames]
    assert all(b > a for a, b in zip(stamps, stamps[1:]))
    assert not any(outage[0] * 1e9 <= s < outage[1] * 1e9 for s in stamps)
    # Resumed: every frame from the recovery to the end (8 s) is delivered.
    assert sum(s >= outage[1] * 1e9 for s in stamps) >= math.floor(
        (8.0 - recovered[0][0]) * 30) - 1


def test_capture_loop_drops_frames_not_newer_than_the_last():
    frames = [Frame(np.zeros((2, 2, 3), np.uint8), 'bgr8', stamp, stamp, i, 'file')
              for i, stamp in enumerate([10, 20, 20, 15, 30])]

    class Listed:
        live, is_open, description = False, True, 'listed'

        def start(self):
            return []

        def read(self, wait):
            return frames.pop(0) if frames else None

        def release(self):
            pass

    delivered, reports = [], []
    loop = CaptureLoop(Listed(), delivered.append,
                       report=lambda level, text: reports.append(text))
    assert loop.run(threading.Event()) == 'ended'
    assert [f.stamp_ns for f in delivered] == [10, 20, 30]
    assert loop.stats['not_newer'] == 2
    assert reports == ['listed: end of stream after 5 frames']


def test_capture_loop_rejects_bad_retry_options():
    with pytest.raises(CaptureError, match='retry'):
        CaptureLoop(None, print, retry_initial_s=3.0, retry_max_s=1.0)
    with pytest.raises(CaptureError, match='warm_up_s'):
        CaptureLoop(None, print, warm_up_s=-0.001)


def test_capture_loop_warms_up_just_before_each_frame_is_due():
    # ScriptedSource waits 1/30 s for every frame: the warm-up must come 2 ms before its end,
    # inside the wait the source asked for, and the frame must not come any later for it.
    clock = [0.0]
    source = ScriptedSource(clock, lambda t: False)
    frames, warm_ups = [], []
    loop = CaptureLoop(source, frames.append, warm_up=lambda: warm_ups.append(clock[0]),
                       warm_up_s=0.002, clock=lambda: clock[0])
    stop = FakeStop(clock, until_s=0.5)
    assert loop.run(stop) == 'stopped'
    # Every frame but the last, whose wait the stop ended before its warm-up.
    assert len(frames) >= 14 and loop.stats['warm_ups'] == len(warm_ups) == len(frames) - 1
    for warm_up_s, frame in zip(warm_ups, frames):
        assert abs(frame.stamp_ns / 1e9 - 0.002 - warm_up_s) < 1e-6
    # The waits add up to the source's: 1/30 s per frame, split at the warm-up.
    np.testing.assert_allclose(sum(stop.waits), clock[0])
    np.testing.assert_allclose(stop.waits[:2], [1 / 30 - 0.002, 0.002])


def test_capture_loop_without_warm_up_passes_the_waits_through():
    clock = [0.0]
    loop = CaptureLoop(ScriptedSource(clock, lambda t: False), lambda frame: None,
                       clock=lambda: clock[0])
    stop = FakeStop(clock, until_s=0.2)
    loop.run(stop)
    np.testing.assert_allclose(stop.waits, 1 / 30)
    assert loop.stats['warm_ups'] == 0


def test_device_loop_through_a_fake_outage_resumes_with_fresh_stamps():
    # Real threads and clocks: the fake camera is unplugged from 0.3 s to 0.9 s.
    device = FakeDevice(_image(), outage=(0.3, 0.9), stale_after_outage=True)
    source = DeviceSource(0, capture_factory=device)
    frames, reports = [], []
    loop = CaptureLoop(source, frames.append, report=lambda level, text: reports.append(level),
                       report_period_s=1.0, retry_initial_s=0.05, retry_max_s=0.2,
                       max_frame_age_s=0.2)
    stop = threading.Event()
    thread = threading.Thread(target=loop.run, args=(stop,))
    thread.start()
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline and not (
            loop.stats['recoveries'] and sum(f.stamp_ns > device_time(device, 0.9)
                                             for f in frames) >= 5):
        time.sleep(0.02)
    stop.set()
    thread.join(5.0)
    source.release()
    assert loop.stats['recoveries'] == 1 and device.opens >= 2
    assert loop.stats['stale'] == 1  # the queued pre-outage frame
    assert reports.count('error') == 1  # 0.6 s outage, one report per second
    stamps = [f.stamp_ns for f in frames]
    assert all(b > a for a, b in zip(stamps, stamps[1:]))
    assert not any(device_time(device, 0.3 + 0.034) < s < device_time(device, 0.9)
                   for s in stamps)


def device_time(device, seconds):
    """Return the system time [ns] of ``seconds`` after the fake device's creation."""
    return time.time_ns() - (time.monotonic_ns() - device.t0_ns) + int(seconds * 1e9)


# -- file source ---------------------------------------------------------------------------------

def _write_video(path, images, fps=30.0):
    height, width = images[0].shape[:2]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*'MJPG'), fps, (width, height))
    assert writer.isOpened()
    for image in images:
        writer.write(image)
    writer.release()


@pytest.fixture(scope='module')
def video(tmp_path_factory):
    path = tmp_path_factory.mktemp('video') / 'ten.avi'
    base = _image()
    _write_video(path, [np.roll(base, 3 * i, axis=1) for i in range(10)])
    return path


def test_file_frames_are_stamped_with_epoch_plus_their_file_time(video):
    epoch = 1_700_000_000_000_000_000
    source = FileSource(str(video), epoch_ns=epoch, realtime=False, loop=False)
    source.start()
    frames = _read(source, 11)
    assert frames[-1] is None  # the end of the file
    stamps = [f.stamp_ns for f in frames[:-1]]
    assert stamps == [epoch + round(k * 1e9 / 30) for k in range(10)]
    assert all(f.stamp_source == 'file' and f.encoding == 'bgr8' for f in frames[:-1])
    # The ball moves 3 px per frame in the file: the detector follows the file's frames.
    detector = BallDetector()
    u = [detector.detect(f.image)[0] for f in frames[:-1]]
    np.testing.assert_allclose(np.diff(u), 3.0, atol=0.3)


def test_file_loops_with_growing_stamps(video):
    source = FileSource(str(video), epoch_ns=5_000_000_000, realtime=False, loop=True)
    source.start()
    stamps = [f.stamp_ns for f in _read(source, 25)]
    assert stamps == [5_000_000_000 + round(k * 1e9 / 30) for k in range(25)]


def test_file_played_at_its_rate_is_never_early(video):
    # A lower bound only (a loaded machine may be late, never early): frame k is not read
    # before k / fps after the first.
    source = FileSource(str(video), epoch_ns=0, realtime=True, loop=False)
    source.start()
    frames = _read(source, 10)
    first = frames[0]
    assert abs(first.stamp_ns - first.available_ns) < 50_000_000  # epoch 0: stamps are now
    for frame in frames:
        assert frame.available_ns - first.available_ns >= frame.stamp_ns - first.stamp_ns


def test_files_with_a_future_epoch_play_at_their_stamps(video):
    epoch = time.time_ns() + 100_000_000
    source = FileSource(str(video), epoch_ns=epoch, realtime=True, loop=False)
    source.start()
    for frame in _read(source, 4):
        assert frame.available_ns >= frame.stamp_ns
    assert source.late_start_s is None


def test_a_file_started_after_its_epoch_says_how_late_and_plays_from_its_start(video):
    # Its frames are published this much after their stamps (another file given the same
    # epoch and started on time is not): the camera_detector warns with it.
    clock = [10_000_000_000]
    source = FileSource(str(video), epoch_ns=8_500_000_000, realtime=True, loop=False,
                        system_ns=lambda: clock[0])
    source.start()
    waits = []

    def wait(seconds):
        waits.append(seconds)
        clock[0] += round(seconds * 1e9)
        return False

    frames = [source.read(wait) for _ in range(3)]
    assert source.late_start_s == pytest.approx(1.5)
    assert [f.stamp_ns for f in frames] == [8_500_000_000 + round(k * 1e9 / 30) for k in range(3)]
    # At the file's pace from the first read, not all at once to catch up.
    assert waits == pytest.approx([1 / 30, 1 / 30], abs=1e-6)


def test_file_errors_name_the_file(tmp_path):
    with pytest.raises(CaptureError, match='none.avi: cannot open'):
        FileSource(str(tmp_path / 'none.avi')).start()
    garbage = tmp_path / 'garbage.avi'
    garbage.write_bytes(b'not a video')
    with pytest.raises(CaptureError, match='garbage.avi: cannot open'):
        FileSource(str(garbage)).start()
    with pytest.raises(CaptureError, match='empty path'):
        FileSource('')


# -- virtual source ------------------------------------------------------------------------------

def test_virtual_frames_at_exact_shutters_show_the_ball_where_it_was():
    camera = default_rig()[1]
    now = [10**18]  # a fake system clock, advanced by the waits
    epoch = now[0] + 50_000_000
    source = VirtualSource(camera, scenario='turntable', fps=60.0, phase_s=0.004,
                           epoch_ns=epoch, noise_std=2.0, seed=3, system_ns=lambda: now[0])

    def wait(seconds):
        now[0] += int(math.ceil(seconds * 1e9))
        return False

    frames = [source.read(wait) for _ in range(5)]
    stamps = [f.stamp_ns for f in frames]
    assert stamps == [epoch + 4_000_000 + round(k * 1e9 / 60) for k in range(5)]
    truth = truth_at(make_scenario('turntable'), stamps, epoch_ns=epoch)
    detector = BallDetector()
    for frame, position in zip(frames, truth):
        assert frame.available_ns == frame.stamp_ns  # released at its shutter
        np.testing.assert_allclose(frame.truth, position, atol=1e-12)
        found = detector.detect(frame.image)
        expected = camera.project(position.reshape(1, 3))[0]
        assert np.hypot(*(np.array(found) - expected)) < 0.3


def test_virtual_source_skips_frames_it_is_late_for_and_pauses_between_flights():
    now = [10**18]
    camera = default_rig()[0]
    source = VirtualSource(camera, scenario='spiral', fps=30.0, epoch_ns=now[0],
                           system_ns=lambda: now[0])

    def wait(seconds):
        now[0] += int(seconds * 1e9)
        return False

    assert source.read(wait).index == 0
    now[0] += 1_000_000_000  # the reader stalled for a second
    frame = source.read(wait)
    assert frame.index >= 30 - 3 and source.stats['skipped'] >= 26
    # In the pause after the flight (1.46 s), frames come without a ball.
    scenario = make_scenario('spiral')
    index = math.ceil((scenario.duration_s + 0.2) * 30)
    image, truth = source.render(index)
    assert truth is None and BallDetector().detect(image) is None
    ended = VirtualSource(camera, scenario='spiral', epoch_ns=now[0], loop=False)
    assert ended.render(index) == (None, None)


class DriverPacedSource:
    """
    A live source on the fake clock like a V4L2 device: ``read()`` blocks until the next frame.

    Frame k is captured at ``k * period + jitter_k`` and arrives ``latency + extra_k`` later;
    ``read()`` returns the oldest frame not yet read (the driver's queue) and never calls
    ``wait``.  ``read_at`` notes when each frame was read, against its arrival.
    """

    live = True
    description = 'driver-paced'
    is_open = True

    def __init__(self, clock, *, period_s=1 / 30, latency_s=0.008, jitter_s=0.0002,
                 extra_s=0.0005, stamp_source='driver', seed=0):
        rng = np.random.default_rng(seed)
        self.clock = clock
        self.period_s, self.latency_s = period_s, latency_s
        self.jitter = rng.uniform(-jitter_s, jitter_s, 10000)
        self.extra = rng.uniform(0.0, extra_s, 10000)
        self.stamp_source = stamp_source
        self.index = 0
        self.read_at = []  # (arrival, read) [s] per frame

    def start(self):
        return []

    def release(self):
        pass

    def read(self, wait):
        k = self.index
        self.index += 1
        stamp = 0.1 + k * self.period_s + self.jitter[k]
        arrival = stamp + self.latency_s + self.extra[k]
        self.clock[0] = max(self.clock[0], arrival)  # blocks in the driver
        self.read_at.append((arrival, self.clock[0]))
        stamp_ns = int(stamp * 1e9) if self.stamp_source == 'driver' else int(self.clock[0] * 1e9)
        return Frame(np.zeros((4, 4, 3), np.uint8), 'bgr8', stamp_ns, int(self.clock[0] * 1e9),
                     k, self.stamp_source)


def test_device_warm_up_never_waits_for_a_clock_step():
    # The prediction is in system time (driver stamps mapped to it): when the system clock is
    # stepped back (NTP at boot), the next frame seems seconds away. No warm-up then, and no
    # wait: frames keep coming at the camera's rate.
    clock = [0.0]
    source = DriverPacedSource(clock)
    step = {'ns': 0}
    frames = []

    def on_frame(frame):
        frames.append(frame)
        if len(frames) == 30:
            step['ns'] = -5_000_000_000

    loop = CaptureLoop(source, on_frame, warm_up=lambda: None, warm_up_s=0.002,
                       clock=lambda: clock[0], system_ns=lambda: int(clock[0] * 1e9) + step['ns'])
    stop = FakeStop(clock, until_s=3.0)
    loop.run(stop)
    assert max(stop.waits) < 0.05
    assert len(frames) >= 80  # 30 fps for 3 s, none lost to a wait


@pytest.mark.parametrize('stamp_source', ['driver', 'read time'])
def test_device_warm_up_comes_before_the_predicted_frame_and_delays_none(stamp_source):
    # A device blocks in read(): the loop predicts the next arrival from the driver's stamps
    # (period) and the shortest latency seen, and warms up 2 ms before it. Waiting for the
    # warm-up must not make a frame wait in the driver's queue: arrivals come no earlier than
    # the shortest latency seen.
    clock = [0.0]
    # The latency varies by 3 ms, more than warm_up_s: only the shortest one is safe to use.
    source = DriverPacedSource(clock, stamp_source=stamp_source, extra_s=0.003)
    frames, warm_ups = [], []

    def warm_up():  # takes the time a windowed detection takes
        warm_ups.append(clock[0])
        clock[0] += 0.0005

    loop = CaptureLoop(source, frames.append, warm_up=warm_up,
                       warm_up_s=0.002, clock=lambda: clock[0],
                       system_ns=lambda: int(clock[0] * 1e9))
    stop = FakeStop(clock, until_s=2.0)
    loop.run(stop)
    assert len(frames) >= 55
    if stamp_source != 'driver':
        assert not warm_ups  # read-time stamps say nothing about the next frame
        return
    # From the tenth frame on (nine stamps predict the next), one warm-up before each frame.
    assert len(warm_ups) >= len(frames) - 10 and loop.stats['warm_ups'] == len(warm_ups)
    arrivals = [arrival for arrival, _ in source.read_at]
    for time_s in warm_ups:
        following = min(a for a in arrivals if a > time_s)
        # warm_up_s before the frame, give or take the spread of the latency (3 ms) and of
        # the capture times (2 x 0.2 ms jitter, once in the frame, once in the median step).
        assert 0.002 - 0.0008 <= following - time_s <= 0.002 + 0.003 + 0.0008
    for arrival, read in source.read_at:
        assert read == arrival  # no frame waited for the warm-up
