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
The ``virtual_camera`` node: the built-in camera of the simulated rig.

From a calibration file and a scenario of :mod:`pseudo_stereo_ros.sim.scenarios`
it renders frames (:mod:`pseudo_stereo_ros.sim.rendering`) at ``fps`` with a
``phase_s`` offset and publishes ``image_raw`` (bgr8), ``camera_info`` and
the true ball position on ``/ball/ground_truth``, all stamped with the
shutter time ``epoch + phase + k / fps`` exactly (integer ns).  The timer
runs on the wall clock and the epoch is a wall-clock time, so stamps are
near ``now`` and the latency of the pipeline can be measured against them.
Each frame is rendered before its shutter time and published at it.
"""

import time

from geometry_msgs.msg import PointStamped
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import CameraInfo, Image

from .messages import array_to_image, calibration_to_camera_info, estimate_to_point
from .node_tools import declare, run_node, StartupError
from ..calibration import load_calibration
from ..camera import Camera
from ..capture import VirtualSource
from ..records import GroundTruth
from ..rig import config_dir
from ..sim.scenarios import SCENARIOS

__all__ = ['VirtualCameraNode', 'main']

# Frames more than this many periods late are skipped (counted), not published in a burst.
_MAX_CATCH_UP = 3


class VirtualCameraNode(Node):
    """
    Publish rendered frames of a simulated ball at exact shutter stamps.

    :param kwargs: passed to :class:`rclpy.node.Node` (``namespace``, ``parameter_overrides``,
        ``context``, ...)
    """

    def __init__(self, **kwargs):
        kwargs.setdefault('node_name', 'virtual_camera')
        super().__init__(**kwargs)
        path = declare(self, 'calibration_file', '',
                       'camera calibration YAML; "": config/rig/camera1.yaml', read_only=True)
        scenario = declare(self, 'scenario', 'spiral', 'ball trajectory',
                           choices=tuple(SCENARIOS), read_only=True)
        fps = declare(self, 'fps', 30.0, 'frame rate [Hz]', min_value=0.1, max_value=1000.0,
                      read_only=True)
        phase_s = declare(self, 'phase_s', 0.0, 'shutter delay after the epoch [s]',
                          min_value=0.0, read_only=True)
        epoch_ns = declare(self, 'epoch_ns', 0,
                           'wall-clock stamp of scenario time 0 [ns]; 0: 0.2 s after start',
                           min_value=0, read_only=True)
        self.loop = declare(self, 'loop', True, 'repeat the scenario')
        # Between repetitions the ball is out of view, as between two real flights; without a
        # pause the ball would jump from the end of the path to its start within one frame.
        self.pause_s = declare(self, 'pause_s', 0.5,
                               'time without a ball between repetitions of the scenario [s]',
                               min_value=0.0, read_only=True)
        radius_m = declare(self, 'ball_radius_m', 0.02, 'ball radius [m]', min_value=0.001,
                           read_only=True)
        rgb = declare(self, 'ball_rgb', [255, 120, 0], 'ball colour (R, G, B) 0..255',
                      read_only=True)
        noise = declare(self, 'noise_std', 2.0, 'pixel noise [grey levels]', min_value=0.0,
                        read_only=True)
        seed = declare(self, 'seed', 0, 'random seed of background and noise', read_only=True)
        self.frame_id = declare(self, 'frame_id', '',
                                'frame_id of the images; "": <camera_name>_optical_frame')
        truth_topic = declare(self, 'ground_truth_topic', '/ball/ground_truth',
                              'topic of the true ball position at each shutter')
        if len(rgb) != 3 or any(not 0 <= c <= 255 for c in rgb):
            raise StartupError(f'parameter ball_rgb: expected three values 0..255, got {rgb}')
        if not path:
            path = str(config_dir() / 'rig' / 'camera1.yaml')
        self.calibration = load_calibration(path)
        self.camera = Camera(self.calibration)
        if not self.frame_id:
            self.frame_id = f'{self.camera.name}_optical_frame'
        if epoch_ns == 0:
            epoch_ns = self.get_clock().now().nanoseconds + 200_000_000
        # The renderer and shutter times of the camera_detector's virtual source: one
        # implementation of the built-in camera.
        self.source = VirtualSource(self.camera, scenario=scenario, fps=fps, phase_s=phase_s,
                                    epoch_ns=epoch_ns, loop=self.loop, pause_s=self.pause_s,
                                    radius_m=radius_m, ball_rgb=rgb, noise_std=noise,
                                    seed=seed)
        self.scenario = self.source.scenario
        self.period_ns = self.source.period_ns
        self.epoch_ns = self.source.epoch_ns
        #: Counts: ``frames`` published, ``skipped`` (late), ``ended`` (scenario over, no loop).
        self.stats = {'frames': 0, 'skipped': 0}
        self._next_index = 0
        self._prepared = None  # (index, image message, info message, truth message)

        self._image_pub = self.create_publisher(Image, 'image_raw', qos_profile_sensor_data)
        self._info_pub = self.create_publisher(CameraInfo, 'camera_info',
                                               qos_profile_sensor_data)
        self._truth_pub = self.create_publisher(PointStamped, truth_topic, 10)
        self._prepare(0)
        # Wait until the first shutter, then tick once per period: ticks follow the shutters.
        first = self.stamp_of(0)
        delay_s = max((first - self.get_clock().now().nanoseconds) / 1e9, 0.0)
        self._tick_timer = self.create_timer(max(delay_s, 1e-4), self._on_tick)
        self.get_logger().info(
            f'{self.camera.name}: {fps:g} fps, phase {phase_s * 1e3:.3f} ms, scenario '
            f'{scenario!r}, publishing {self._image_pub.topic_name}')

    def stamp_of(self, index: int) -> int:
        """Return the shutter stamp [ns] of frame ``index``."""
        return self.source.stamp_of(index)

    def _prepare(self, index: int) -> None:
        stamp = self.stamp_of(index)
        image, position = self.source.render(index)
        if image is None:  # the scenario is over: no more frames
            self._prepared = (index, None, None, None)
            return
        # No position: the pause between repetitions, a frame without a ball.
        truth = (None if position is None
                 else estimate_to_point(GroundTruth(stamp, *position), 'world'))
        self._prepared = (
            index,
            array_to_image(image, 'bgr8', stamp, self.frame_id),
            calibration_to_camera_info(self.calibration, stamp, self.frame_id),
            truth,
        )

    def _on_tick(self) -> None:
        # One-shot timers re-armed for the next shutter: a periodic timer drifts against the
        # stamps and would publish each frame up to a period after its shutter.
        self._tick_timer.cancel()
        self.destroy_timer(self._tick_timer)
        now = self.get_clock().now().nanoseconds
        while self.stamp_of(self._next_index) <= now:
            index = self._next_index
            self._next_index += 1
            if self.stamp_of(index) < now - _MAX_CATCH_UP * self.period_ns:
                self.stats['skipped'] += 1
                continue
            if self._prepared is None or self._prepared[0] != index:
                self._prepare(index)
            _, image, info, truth = self._prepared
            if image is not None:
                if truth is not None:
                    self._truth_pub.publish(truth)
                self._image_pub.publish(image)
                self._info_pub.publish(info)
                self.stats['frames'] += 1
            self._prepared = None
        if self._prepared is None:
            start = time.perf_counter()
            self._prepare(self._next_index)
            self.render_time_s = time.perf_counter() - start
        delay_ns = self.stamp_of(self._next_index) - self.get_clock().now().nanoseconds
        self._tick_timer = self.create_timer(max(delay_ns / 1e9, 1e-4), self._on_tick)


def main(args=None) -> int:
    """Run the virtual camera node (``ros2 run pseudo_stereo_ros virtual_camera``)."""
    return run_node(VirtualCameraNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
