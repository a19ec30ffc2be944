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
The ``camera_detector`` node: capture and ball detection in one process, one per camera.

Run in the camera's namespace (``/camera1``).  A capture thread reads frames
from the source (``device``, ``file`` or ``virtual``; see
:mod:`pseudo_stereo_ros.capture`), runs the ball detector on each and
publishes ``ball/image_point`` (x = u, y = v raw px, header stamp = the
frame's capture time, frame_id = the camera name) at once; no image crosses
DDS.  Then ``camera_info`` (when a calibration is known), the true ball
position on ``/ball/ground_truth`` (virtual source) and, every
``publish_image_every_n`` frames, ``image_raw`` (sensor-data QoS).  A failing
source is reported at most once per ``report_period_s``, retried with
back-off and resumes without a restart.  ``/diagnostics`` carries the frame
and point counts and where the time goes: shutter -> frame available and
frame available -> image point published.

Latency: the image point is published before any other work on the frame,
serialized by :func:`~pseudo_stereo_ros.ros.messages.point_encoder` (a tenth
of the cost of building a message and having rclpy convert it).
With ``warm_up_s`` the detector runs once on the previous frame that long
before the next is due and its result is dropped: after a frame period of
sleep the caches are cold and a detection costs two to three times more.
File and virtual sources wait for each frame's time; for a device the next
frame's arrival is predicted from the driver's stamps (see
:class:`~pseudo_stereo_ros.capture.CaptureLoop`).  OpenCV runs in the capture
thread alone (``opencv_threads: 1``).
"""

from collections import Counter, deque
import math
import threading
import time
from typing import Optional

import cv2
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped
import numpy as np
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import CameraInfo, Image

from .messages import (array_to_image, calibration_to_camera_info, diagnostic_array,
                       diagnostic_status, estimate_to_point, ns_to_stamp, point_encoder)
from .node_tools import declare, declare_detector, run_node, StartupError
from ..calibration import load_calibration, load_camera_info
from ..camera import Camera
from ..capture import CaptureLoop, DeviceSource, FileSource, Frame, VirtualSource
from ..errors import CalibrationError, CaptureError, EncodingError
from ..records import GroundTruth
from ..rig import config_dir
from ..sim.scenarios import SCENARIOS

__all__ = ['CameraDetectorNode', 'SOURCES', 'main']

#: The ``source`` parameter's values.
SOURCES = ('virtual', 'file', 'device')
#: Latency samples kept for the diagnostics' percentiles.
_TIMING_SAMPLES = 2000


def _percentiles_ms(samples_ns) -> tuple:
    values = np.array(samples_ns, dtype=float) / 1e6
    if not values.size:
        return (math.nan,) * 3
    return tuple(float(x) for x in np.percentile(values, (50, 90, 99)))


class CameraDetectorNode(Node):
    """
    Capture frames, detect the ball in each and publish its stamped image point.

    :param capture_factory: ``factory(device or path) -> VideoCapture`` for the device and
        file sources (tests inject a fake camera); None for OpenCV's
    :param start: start capturing at once; False to call :meth:`start` later (``bringup``
        starts its cameras together once every node exists)
    :param kwargs: passed to :class:`rclpy.node.Node` (``namespace``, ``parameter_overrides``,
        ``context``, ...)
    """

    def __init__(self, *, capture_factory=None, start: bool = True, **kwargs):
        kwargs.setdefault('node_name', 'camera_detector')
        super().__init__(**kwargs)
        source = declare(self, 'source', 'virtual', 'where frames come from',
                         choices=SOURCES, read_only=True)
        name = declare(self, 'camera_name', '',
                       "camera name (frame_id of the points); '': the namespace's last part",
                       read_only=True)
        calibration_file = declare(
            self, 'calibration_file', '',
            'calibration or camera_info YAML (for camera_info; virtual: also the pose); "": '
            'virtual: config/rig/<camera_name>.yaml, else no camera_info', read_only=True)
        # Device.
        device = declare(self, 'device', '/dev/video0', 'source device: /dev/videoN or an index',
                         read_only=True)
        width_px = declare(self, 'width_px', 0, 'device: requested width [px]; 0: driver '
                           'default', min_value=0, read_only=True)
        height_px = declare(self, 'height_px', 0, 'device: requested height [px]; 0: driver '
                            'default', min_value=0, read_only=True)
        fps = declare(self, 'fps', 30.0, 'frame rate [Hz] (device: requested; 0: driver '
                      'default)', min_value=0.0, max_value=1000.0, read_only=True)
        fourcc = declare(self, 'fourcc', '', 'device: pixel format (MJPG, YUYV, ...); "": '
                         'driver default', read_only=True)
        exposure_s = declare(self, 'exposure_s', 0.0, 'device: manual exposure time [s]; 0: '
                             'auto exposure', min_value=0.0, max_value=10.0, read_only=True)
        stamp_offset_s = declare(self, 'stamp_offset_s', 0.0,
                                 "device: subtracted from the driver's capture stamp (middle "
                                 'of exposure to driver stamp) [s]', min_value=-1.0,
                                 max_value=1.0, read_only=True)
        max_frame_age_s = declare(self, 'max_frame_age_s', 0.5,
                                  'device: frames older than this when read are dropped [s]',
                                  min_value=0.001, read_only=True)
        # File.
        video_file = declare(self, 'video_file', '', 'file: the video file', read_only=True)
        as_fast = declare(self, 'as_fast_as_possible', False,
                          'file: read frames without waiting for their time', read_only=True)
        # File and virtual.
        epoch_ns = declare(self, 'epoch_ns', 0, "file: stamp of the file's time 0; virtual: "
                           'of scenario time 0 [ns]; 0: now', min_value=0, read_only=True)
        loop = declare(self, 'loop', True, 'file and virtual: start again at the end',
                       read_only=True)
        # Virtual.
        scenario = declare(self, 'scenario', 'spiral', 'virtual: ball trajectory',
                           choices=tuple(SCENARIOS), read_only=True)
        phase_s = declare(self, 'phase_s', 0.0, 'virtual: shutter delay after the epoch [s]',
                          min_value=0.0, read_only=True)
        pause_s = declare(self, 'pause_s', 0.5, 'virtual: time without a ball between '
                          'repetitions [s]', min_value=0.0, read_only=True)
        radius_m = declare(self, 'ball_radius_m', 0.02, 'virtual: ball radius [m]',
                           min_value=0.001, read_only=True)
        rgb = declare(self, 'ball_rgb', [255, 120, 0], 'virtual: ball colour (R, G, B)',
                      read_only=True)
        noise = declare(self, 'noise_std', 2.0, 'virtual: pixel noise [grey levels]',
                        min_value=0.0, read_only=True)
        seed = declare(self, 'seed', 0, 'virtual: random seed of background and noise',
                       read_only=True)
        truth_topic = declare(self, 'ground_truth_topic', '/ball/ground_truth',
                              'virtual: topic of the true ball position', read_only=True)
        # Output and supervision.
        self.detector = declare_detector(self)
        self.image_every_n = declare(self, 'publish_image_every_n', 0,
                                     'publish image_raw every n-th frame (debugging); 0: never',
                                     min_value=0, read_only=True)
        self.wait_for_subscribers_s = declare(
            self, 'wait_for_subscribers_s', 0.0,
            'before the first frame, wait up to this long for min_subscribers ball/image_point '
            'subscribers (matched by DDS, not only in the graph) [s]',
            min_value=0.0, read_only=True)
        self.min_subscribers = declare(self, 'min_subscribers', 1,
                                       'subscribers wait_for_subscribers_s waits for',
                                       min_value=1, read_only=True)
        report_period_s = declare(self, 'report_period_s', 1.0,
                                  'least time between reports of a failing source [s]',
                                  min_value=0.01, read_only=True)
        retry_initial_s = declare(self, 'retry_initial_s', 0.1,
                                  'first retry after a failure [s]; doubles per failure',
                                  min_value=0.001, read_only=True)
        retry_max_s = declare(self, 'retry_max_s', 2.0, 'longest wait between retries [s]',
                              min_value=0.001, read_only=True)
        warm_up_s = declare(self, 'warm_up_s', 0.002,
                            'run the detector on the previous frame this long before the next '
                            "is due (device: predicted from the driver's stamps), to warm the "
                            'caches [s]; 0: never', min_value=0.0, max_value=0.1,
                            read_only=True)
        opencv_threads = declare(self, 'opencv_threads', 1,
                                 "OpenCV's worker threads in this process (cv2.setNumThreads); "
                                 '1: detection runs in the capture thread alone; 0: leave '
                                 "OpenCV's default", min_value=0, max_value=64, read_only=True)
        diagnostics_period_s = declare(self, 'diagnostics_period_s', 1.0,
                                       'period of /diagnostics [s]; 0 disables', min_value=0.0,
                                       read_only=True)

        self.camera_name = name or self.get_namespace().rstrip('/').split('/')[-1] or 'camera'
        if opencv_threads > 0:
            # Process-wide. A search window is too small to share: handing half of it to a
            # worker thread costs more than it saves, and on a busy machine the worker may not
            # be scheduled for a while (the same detections either way).
            cv2.setNumThreads(opencv_threads)
        self.calibration = self._calibration(calibration_file, source)
        try:
            if source == 'virtual':
                if len(rgb) != 3 or any(not 0 <= c <= 255 for c in rgb):
                    raise StartupError(f'parameter ball_rgb: expected three values 0..255, '
                                       f'got {list(rgb)}')
                self.source = VirtualSource(
                    Camera(self.calibration), scenario=scenario, fps=fps, phase_s=phase_s,
                    epoch_ns=epoch_ns, loop=loop, pause_s=pause_s, radius_m=radius_m,
                    ball_rgb=rgb, noise_std=noise, seed=seed)
            elif source == 'file':
                if not video_file:
                    raise StartupError('parameter video_file: needed with source file')
                self.source = FileSource(video_file, epoch_ns=epoch_ns, realtime=not as_fast,
                                         loop=loop, capture_factory=capture_factory)
                try:
                    self.source.start()
                except CaptureError as err:
                    raise StartupError(f'parameter video_file: {err}') from err
            else:
                self.source = DeviceSource(
                    device, width_px=width_px, height_px=height_px, fps=fps, fourcc=fourcc,
                    exposure_s=exposure_s, stamp_offset_s=stamp_offset_s,
                    capture_factory=capture_factory)
        except CaptureError as err:
            raise StartupError(f'source {source}: {err}') from err
        self.capture_loop = CaptureLoop(
            self.source, self._on_frame, report=self._report, report_period_s=report_period_s,
            retry_initial_s=min(retry_initial_s, retry_max_s), retry_max_s=retry_max_s,
            max_frame_age_s=max_frame_age_s,
            warm_up=self._warm_up if warm_up_s > 0 else None, warm_up_s=warm_up_s)
        #: Counts: ``frames`` handled, ``published`` points, ``no_ball``, ``bad_image``,
        #: ``size_mismatch`` (frames of another size than the calibration's).
        self.stats = Counter()
        #: Recent shutter -> frame available times of all frames [ns].
        self.wake_ns = deque(maxlen=_TIMING_SAMPLES)
        #: Recent frame available -> image point published times [ns] (frames with a ball).
        self.point_ns = deque(maxlen=_TIMING_SAMPLES)
        self._stamp_source = None
        self._size_warned = False
        # The last frame's image and encoding, for the warm-up before the next frame.
        self._last_image = None
        self._encode_point = point_encoder(self.camera_name)
        # Built once (ten times the cost of a point message); each frame sets its stamp.
        self._info = (None if self.calibration is None else
                      calibration_to_camera_info(self.calibration, 0, self.camera_name))

        # Reliable with a deep history: a subscriber slowed by a loaded machine gets every
        # point late rather than losing the ones the writer overwrote (points are tiny).
        self._point_pub = self.create_publisher(PointStamped, 'ball/image_point', 100)
        self._info_pub = self.create_publisher(CameraInfo, 'camera_info',
                                               qos_profile_sensor_data)
        self._image_pub = (self.create_publisher(Image, 'image_raw', qos_profile_sensor_data)
                           if self.image_every_n > 0 else None)
        self._truth_pub = (self.create_publisher(PointStamped, truth_topic, 10)
                           if source == 'virtual' else None)
        self._diagnostics_pub = None
        if diagnostics_period_s > 0:
            self._diagnostics_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
            self.create_timer(diagnostics_period_s, self._publish_diagnostics)
        self._stop = threading.Event()
        #: Set when the source is over (a file or a scenario without ``loop``).
        self.ended = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f'capture {self.camera_name}',
                                        daemon=True)
        self.get_logger().info(
            f'{self.camera_name}: {source} source {self.source.description}, publishing '
            f'{self._point_pub.topic_name}')
        if start:
            self.start()

    def start(self, epoch_ns: Optional[int] = None) -> None:
        """
        Start the capture thread.

        :param epoch_ns: for the file and virtual sources, the stamp of time 0 [ns] instead of
            the ``epoch_ns`` parameter (cameras started together share one epoch)
        """
        if epoch_ns is not None and isinstance(self.source, (FileSource, VirtualSource)):
            self.source.epoch_ns = int(epoch_ns)
        self._thread.start()

    # -- start-up -------------------------------------------------------------------------------

    def _calibration(self, path: str, source: str):
        if not path and source != 'virtual':
            # The default rig is the simulated one: its intrinsics would be a wrong camera_info
            # for a real camera.
            self.get_logger().info('no calibration_file: camera_info is not published')
            return None
        if not path:
            default = config_dir() / 'rig' / f'{self.camera_name}.yaml'
            if not default.is_file():
                raise StartupError(f'parameter calibration_file: none given and no {default} '
                                   '(a virtual camera needs its pose)')
            path = str(default)
        try:
            # A virtual camera renders with the pose; a real one needs the intrinsics only,
            # so a camera_info file (ROS camera_calibration's ost.yaml) is enough.
            return load_calibration(path) if source == 'virtual' else load_camera_info(path)
        except CalibrationError as err:
            raise StartupError(f'parameter calibration_file: {err}') from err

    # -- capture thread -------------------------------------------------------------------------

    def _report(self, level: str, text: str) -> None:
        # One call site per severity: rclpy refuses two severities from one line.
        if level == 'error':
            self.get_logger().error(text)
        elif level == 'warn':
            self.get_logger().warning(text)
        else:
            self.get_logger().info(text)

    def _run(self) -> None:
        try:
            deadline = time.monotonic() + self.wait_for_subscribers_s
            while (self._point_pub.get_subscription_count() < self.min_subscribers
                   and time.monotonic() < deadline and not self._stop.is_set()):
                self._stop.wait(0.01)
            if self.capture_loop.run(self._stop) == 'ended':
                self.ended.set()
        except Exception as err:  # noqa: B902 - the outermost handler of the capture thread
            if self._stop.is_set() or not self.context.ok():
                return  # shutting down: a publisher may already be gone
            self.get_logger().fatal(f'capture thread stopped: {type(err).__name__}: {err}')
            raise

    def _warm_up(self) -> None:
        # In the capture thread (the source's wait), just before the next frame is due.
        if self._last_image is not None:
            self.detector.warm_up(*self._last_image)

    def _on_frame(self, frame: Frame) -> None:
        # The point goes out first; the bookkeeping waits until it is published.
        error = None
        try:
            found = self.detector.detect(frame.image, frame.encoding)
        except (EncodingError, ValueError, cv2.error) as err:
            found, error = None, err
        else:
            if found is not None:
                self._point_pub.publish(self._encode_point(frame.stamp_ns, found[0], found[1],
                                                           0.0))
                self.point_ns.append(time.time_ns() - frame.available_ns)
        self.stats['frames'] += 1
        self.wake_ns.append(frame.available_ns - frame.stamp_ns)
        if frame.stamp_source != self._stamp_source:
            if frame.stamp_source == 'read time':
                self.get_logger().warning(
                    f'{self.source.description}: the driver gives no usable capture stamp; '
                    'stamping with the time read() returned (later than the shutter by the '
                    'driver latency: set stamp_offset_s)')
            elif isinstance(self.source, FileSource) and self.source.late_start_s:
                self.get_logger().warning(
                    f'{self.source.description}: parameter epoch_ns was '
                    f'{self.source.late_start_s:.3f} s in the past at the first frame: playing '
                    "at the file's pace from now, each frame published that long after its "
                    'stamp (stamps stay on the epoch); files given one epoch that started late '
                    "by amounts differing by more than the fuser's reorder window reach it out "
                    'of order (late points, or a new session): give an epoch further ahead')
            self._stamp_source = frame.stamp_source
        if error is not None:
            self._last_image = None
            self.stats['bad_image'] += 1
            self.get_logger().error(f'frame dropped: {str(error).strip()}',
                                    throttle_duration_sec=5.0)
            return
        self._last_image = (frame.image, frame.encoding)
        self.stats['published' if found is not None else 'no_ball'] += 1
        if self._info is not None:
            self._check_size(frame)
            self._info.header.stamp = ns_to_stamp(frame.stamp_ns)
            self._info_pub.publish(self._info)
        if self._truth_pub is not None and frame.truth is not None:
            self._truth_pub.publish(estimate_to_point(GroundTruth(frame.stamp_ns, *frame.truth),
                                                      'world'))
        if self._image_pub is not None and frame.index % self.image_every_n == 0:
            self._image_pub.publish(array_to_image(frame.image, frame.encoding, frame.stamp_ns,
                                                   self.camera_name))

    def _check_size(self, frame: Frame) -> None:
        height, width = frame.image.shape[:2]
        size = (self.calibration.image_width, self.calibration.image_height)
        if (width, height) != size:
            self.stats['size_mismatch'] += 1
            if not self._size_warned:
                self._size_warned = True
                self.get_logger().error(
                    f'frames are {width}x{height} px but the calibration is for '
                    f'{size[0]}x{size[1]}: set width_px/height_px or calibrate at this size')

    # -- diagnostics ----------------------------------------------------------------------------

    def diagnostics(self) -> dict:
        """
        Return the values of this node's diagnostic status.

        :return: counts, the capture loop's failures and warm-ups, and the percentiles (p50,
            p90, p99) [ms] of shutter -> frame available (all recent frames) and frame
            available -> image point published (recent frames with a ball; ``timing samples``
            of them)
        """
        wake = _percentiles_ms(list(self.wake_ns))
        point_ns = list(self.point_ns)
        point = _percentiles_ms(point_ns)
        values = {
            'source': self.source.description,
            'stamp source': self._stamp_source or 'none yet',
            'frames': self.stats['frames'],
            'image points': self.stats['published'],
            'no ball': self.stats['no_ball'],
            'bad image': self.stats['bad_image'],
            'dropped stale': self.capture_loop.stats['stale'],
            'dropped not newer': self.capture_loop.stats['not_newer'],
            'failures': self.capture_loop.stats['failures'],
            'recoveries': self.capture_loop.stats['recoveries'],
            'warm-ups': self.capture_loop.stats['warm_ups'],
            'timing samples': len(point_ns),
        }
        for label, (p50, p90, p99) in (('shutter -> frame available', wake),
                                       ('frame available -> image point', point)):
            values[f'{label} p50 [ms]'] = p50
            values[f'{label} p90 [ms]'] = p90
            values[f'{label} p99 [ms]'] = p99
        return values

    def _publish_diagnostics(self) -> None:
        values = self.diagnostics()
        if self.capture_loop.failing:
            level, message = 'error', 'source failing, retrying'
        elif self.ended.is_set():
            level, message = 'warn', 'source ended'
        else:
            level, message = 'ok', f'{values["frames"]} frames, {values["image points"]} points'
        self._diagnostics_pub.publish(diagnostic_array(time.time_ns(), [diagnostic_status(
            f'camera_detector: {self.camera_name}', level, message, values,
            hardware_id=self.source.description)]))

    def destroy_node(self):
        """Stop the capture thread, release the source, then destroy the node."""
        self._stop.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout=5.0)
        self.source.release()
        return super().destroy_node()


def main(args=None) -> int:
    """Run the camera_detector node (``ros2 run pseudo_stereo_ros camera_detector``)."""
    return run_node(CameraDetectorNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
