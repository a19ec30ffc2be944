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
The ``monitor`` node: rates, error against ground truth and latency, live.

Subscribes each camera's ``camera_info`` (its frame rate without the cost of
images), each ``ball/image_point``, ``/ball/position`` and
``/ball/ground_truth``.  A second core :class:`~pseudo_stereo_ros.fusion.Fuser`
with ``method='naive'`` runs on the same image points, so the error of the
paper's method and of the naive pairing are compared on the same
detections.  Latency is the wall-clock time of receiving ``/ball/position``
minus its stamp (meaningful when the cameras stamp with the wall clock, as
the virtual cameras do).

Every store (estimates, ground truth, latencies) keeps only its newest
``max_history`` entries, so a monitor left running uses bounded memory; the
default holds more than 25 minutes of two 30 fps cameras, and the summary
is then over that most recent stretch.
"""

from collections import Counter, deque
import functools
import math
import time
from typing import Dict

from geometry_msgs.msg import PointStamped
import numpy as np
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import CameraInfo

from .messages import point_to_observation, point_to_xyz
from .node_tools import check_camera_names, declare, load_cameras, run_node
from ..fusion import Fuser
from ..reorder import ReorderBuffer

__all__ = ['DEFAULT_MAX_HISTORY', 'MonitorNode', 'main']

#: Default of the ``max_history`` parameter: entries kept per store.
DEFAULT_MAX_HISTORY = 100_000


def _percentiles(latency_ns) -> tuple:
    """Return (p50, p90, p99) [ms] of latencies [ns] (NaN when there are none)."""
    latency = np.array(latency_ns, dtype=float) / 1e6
    if not latency.size:
        return (math.nan,) * 3
    return tuple(float(x) for x in np.percentile(latency, (50, 90, 99)))


def _remember(store: dict, stamp_ns: int, value, limit: int) -> None:
    """Store ``value`` at ``stamp_ns``; drop the first-inserted entries beyond ``limit``."""
    store[stamp_ns] = value
    while len(store) > limit:
        del store[next(iter(store))]


class MonitorNode(Node):
    """
    Measure the pipeline while it runs; :meth:`summary` returns the numbers.

    :param kwargs: passed to :class:`rclpy.node.Node` (``namespace``, ``parameter_overrides``,
        ``context``, ...)
    """

    def __init__(self, **kwargs):
        kwargs.setdefault('node_name', 'monitor')
        super().__init__(**kwargs)
        names = declare(self, 'camera_names', ['camera1', 'camera2'], 'camera names',
                        read_only=True)
        files = declare(self, 'calibration_files', [''],
                        'calibration YAML per camera, for the naive comparison; '
                        '[""]: config/rig/<name>.yaml', read_only=True)
        self.report_period_s = declare(self, 'report_period_s', 2.0,
                                       'period of the live log line [s]; 0 disables',
                                       min_value=0.0)
        compare = declare(self, 'compare_naive', True,
                          'also fuse the image points with the naive method', read_only=True)
        self.max_history = declare(self, 'max_history', DEFAULT_MAX_HISTORY,
                                   'entries kept per store (estimates of each method, ground '
                                   'truth, each latency series); the oldest go first',
                                   min_value=1, read_only=True)
        self.names = check_camera_names(names, minimum=0)
        files = [] if files in ([''], None) else files
        self.naive = None
        if compare:
            self.naive = Fuser(load_cameras(self.names, files), method='naive')
            self._buffer = ReorderBuffer(0, sources=self.names)
        self.counts = Counter()
        self.first_ns: Dict[str, int] = {}
        self.last_ns: Dict[str, int] = {}
        self.truth: Dict[int, tuple] = {}
        self.paper: Dict[int, tuple] = {}
        self.naive_estimates: Dict[int, tuple] = {}
        self.latency_ns = deque(maxlen=self.max_history)
        self.point_latency_ns = deque(maxlen=self.max_history)
        self._recent_error = deque(maxlen=300)
        self._started = time.monotonic()
        self._subs = []
        for name in self.names:
            self._subs.append(self.create_subscription(
                CameraInfo, f'{name}/camera_info', functools.partial(self._on_info, name),
                qos_profile_sensor_data))
            self._subs.append(self.create_subscription(
                PointStamped, f'{name}/ball/image_point',
                functools.partial(self._on_image_point, name), 100))
        self._subs.append(self.create_subscription(PointStamped, 'ball/position',
                                                   self._on_position, 100))
        self._subs.append(self.create_subscription(PointStamped, '/ball/ground_truth',
                                                   self._on_truth, 100))
        if self.report_period_s > 0:
            self.create_timer(self.report_period_s, self._report)

    def _count(self, key: str) -> None:
        now = time.monotonic_ns()
        self.counts[key] += 1
        self.first_ns.setdefault(key, now)
        self.last_ns[key] = now

    def _on_info(self, name: str, msg: CameraInfo) -> None:
        self._count(f'{name}/camera_info')

    def _on_image_point(self, name: str, msg: PointStamped) -> None:
        received = time.time_ns()
        self._count(f'{name}/ball/image_point')
        observation = point_to_observation(msg, name)
        self.point_latency_ns.append(received - observation.stamp_ns)
        if self.naive is None:
            return
        for item in self._buffer.push(observation.stamp_ns, name, observation, 0):
            estimate = self.naive.update(item)
            if estimate is not None:
                _remember(self.naive_estimates, estimate.stamp_ns,
                          (estimate.x, estimate.y, estimate.z), self.max_history)

    def _on_position(self, msg: PointStamped) -> None:
        received = time.time_ns()
        self._count('ball/position')
        stamp, x, y, z = point_to_xyz(msg)
        self.latency_ns.append(received - stamp)
        _remember(self.paper, stamp, (x, y, z), self.max_history)
        truth = self.truth.get(stamp)
        if truth is not None:
            self._recent_error.append(math.dist(truth, (x, y, z)))

    def _on_truth(self, msg: PointStamped) -> None:
        stamp, x, y, z = point_to_xyz(msg)
        _remember(self.truth, stamp, (x, y, z), self.max_history)

    def rate_hz(self, key: str) -> float:
        """Return the mean rate [Hz] of a counted topic (0 when fewer than two messages)."""
        count = self.counts[key]
        if count < 2:
            return 0.0
        return (count - 1) / ((self.last_ns[key] - self.first_ns[key]) / 1e9)

    def errors(self, estimates: Dict[int, tuple]) -> np.ndarray:
        """Return (N, 3) rows (stamp [ns], 3D error [m], 0) of estimates with ground truth."""
        rows = [(stamp, math.dist(point, self.truth[stamp]))
                for stamp, point in sorted(estimates.items()) if stamp in self.truth]
        return np.array(rows, dtype=float).reshape(-1, 2)

    def summary(self) -> dict:
        """
        Return the measurements so far.

        :return: ``rates`` (topic -> Hz), ``error_mm`` (method -> mean 3D error [mm]),
            ``matched`` (method -> estimates with truth), ``latency_ms`` (p50, p90, p99 of
            image stamp -> /ball/position), ``point_latency_ms`` (the same for image points);
            errors and latencies are over the kept (newest ``max_history``) entries, rates
            over the whole run
        """
        rates = {f'{name} camera': self.rate_hz(f'{name}/camera_info') for name in self.names}
        rates.update({f'{name} image points': self.rate_hz(f'{name}/ball/image_point')
                      for name in self.names})
        rates['/ball/position'] = self.rate_hz('ball/position')
        error_mm, matched = {}, {}
        for method, estimates in (('paper', self.paper), ('naive', self.naive_estimates)):
            errors = self.errors(estimates)
            matched[method] = len(errors)
            error_mm[method] = float(errors[:, 1].mean() * 1e3) if len(errors) else math.nan
        return {'rates': rates, 'error_mm': error_mm, 'matched': matched,
                'latency_ms': _percentiles(self.latency_ns),
                'point_latency_ms': _percentiles(self.point_latency_ns),
                'positions': self.counts['ball/position']}

    def _report(self) -> None:
        summary = self.summary()
        rates = ', '.join(f'{key} {value:.1f} Hz' for key, value in summary['rates'].items()
                          if not key.endswith('image points'))
        recent = (f'{np.mean(self._recent_error) * 1e3:.2f} mm' if self._recent_error
                  else 'n/a')
        p50, p90, _ = summary['latency_ms']
        self.get_logger().info(f'{rates}; error (recent) {recent}; latency p50 {p50:.2f} ms, '
                               f'p90 {p90:.2f} ms')


def main(args=None) -> int:
    """Run the monitor node (``ros2 run pseudo_stereo_ros monitor``)."""
    return run_node(MonitorNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
