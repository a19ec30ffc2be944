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
The ``fuser`` node: image points of several cameras in, ``/ball/position`` out at every event.

Thin glue around the core :class:`pseudo_stereo_ros.fusion.Fuser` (the same
code path as ``pseudo_stereo track``): each ``/<name>/ball/image_point``
becomes an :class:`~pseudo_stereo_ros.fusion.Observation`, a
:class:`~pseudo_stereo_ros.reorder.ReorderBuffer` puts the topics back into
stamp order (holding a point at most ``reorder_window_s``), and every
estimate is published stamped with the shutter stamp of its event.

Sessions are the core's decision (:meth:`~pseudo_stereo_ros.fusion.Fuser.off_timeline`):
a point whose stamp jumps away from the session's timeline (a replayed bag
looping, a restarted clock, one camera's bad stamp) bypasses the reorder
buffer and goes to the core, which holds it until the cameras agree on the
jump or drops it as that camera's ``stamp_outlier``; when the core starts a
new session, the reorder buffer and the timing statistics start afresh.

Points are taken as serialized bytes (``raw=True``) and read by
:func:`~pseudo_stereo_ros.ros.messages.decode_point`; bytes that are no
``PointStamped`` are dropped and counted (``malformed``), and a point a method
fails on is dropped, logged and counted (``internal_error``): the node never
dies on a message.

Time offsets (:mod:`pseudo_stereo_ros.timesync`): each point's stamp is
shifted by its camera's offset (``time_offset_s`` of its calibration file, or
``time_offsets_s``) on arrival, before anything else sees it, so estimates are
stamped on the common clock.  The reorder window grows by the spread of the
offsets, so that shifted points are still fused in stamp order.  An
:class:`~pseudo_stereo_ros.timesync.OnlineOffsetEstimator` estimates the
offsets from the raw points of the last ``time_offset_window_s`` and reports
them in ``/diagnostics``; with ``estimate_time_offsets`` a usable estimate is
applied, changed by at most ``time_offset_max_slew`` seconds per second of
stamps, so a camera's shifted stamps never go back and never jump.
"""

from collections import Counter, deque
from concurrent.futures.process import BrokenProcessPool
import functools
import math
import time

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped
import numpy as np
from rclpy.node import Node
from visualization_msgs.msg import Marker

from .messages import (decode_point, diagnostic_array, diagnostic_status, point_encoder,
                       trail_marker)
from .node_tools import declare, load_cameras, PublisherWatch, run_node, StartupError
from .processes import offset_worker
from ..errors import EncodingError, PseudoStereoError
from ..fusion import (DEFAULT_IMAGE_MARGIN, DEFAULT_MAX_SPEED_MPS, make_fuser,
                      METHOD_NAMES, resolve_method)
from ..offsets import camera_time_offsets, shift_observation
from ..records import Observation
from ..reorder import ReorderBuffer
from ..stamps import seconds_to_ns
from ..timesync import OnlineOffsetEstimator, run_offset_job
from ..trajectory import DEFAULT_MAX_WINDOW_S

__all__ = ['FuserNode', 'INPUT_QUEUE_DEPTH', 'main']

#: Default depth of each image point subscription: one second of a 1,000 Hz camera (100 was
#: 100 ms). It holds points while the node's Python thread waits for the core; when the whole
#: process is stalled, the publisher's own keep-last depth bounds what DDS can still deliver.
INPUT_QUEUE_DEPTH = 1000


def _seconds_to_ns(name: str, value: float) -> int:
    if not value >= 0:
        raise StartupError(f'parameter {name!r}: must be >= 0 s, got {value}')
    return seconds_to_ns(value)


class FuserNode(Node):
    """
    Fuse stamped image points of unsynchronized cameras into 3D positions.

    :param kwargs: passed to :class:`rclpy.node.Node` (``namespace``, ``parameter_overrides``,
        ``context``, ...)
    """

    def __init__(self, **kwargs):
        kwargs.setdefault('node_name', 'fuser')
        super().__init__(**kwargs)
        names = declare(self, 'camera_names', ['camera1', 'camera2'],
                        'camera names; subscribes /<name>/ball/image_point', read_only=True)
        files = declare(self, 'calibration_files', [''],
                        'calibration YAML per camera, same order; [""]: config/rig/<name>.yaml',
                        read_only=True)
        method = resolve_method(declare(
            self, 'method', 'paper', 'fusion method (best: the most accurate, now trajectory)',
            choices=METHOD_NAMES, read_only=True))
        self.world_frame = declare(self, 'world_frame', 'world',
                                   'frame_id of /ball/position and the marker')
        sync_s = declare(self, 'sync_tolerance_s', 0.001,
                         'observations of two cameras closer than this are simultaneous [s]',
                         min_value=0.0, read_only=True)
        gap_s = declare(self, 'max_gap_s', 0.1,
                        'upper bound of the longest interval bridged; older data is not used '
                        '(stale camera); each camera uses at most 4.5 measured frame periods [s]',
                        min_value=0.0, read_only=True)
        image_margin = declare(self, 'image_margin', DEFAULT_IMAGE_MARGIN,
                               'points farther outside the image than this fraction of its '
                               'width or height are dropped (outside_image)', min_value=0.0,
                               read_only=True)
        max_speed_mps = declare(self, 'max_speed_mps', DEFAULT_MAX_SPEED_MPS,
                                'estimates implying a faster motion are dropped (implausible) '
                                '[m/s]; 0 disables', min_value=0.0, read_only=True)
        workspace_min_m = declare(self, 'workspace_min_m', [-math.inf] * 3,
                                  'lower corner x, y, z of the workspace; estimates outside are '
                                  'dropped (implausible) [m]; -.inf: unbounded', read_only=True)
        workspace_max_m = declare(self, 'workspace_max_m', [math.inf] * 3,
                                  'upper corner x, y, z of the workspace [m]; .inf: unbounded',
                                  read_only=True)
        # 0 by default: every point is fused the moment it arrives (lowest latency); a point
        # older than one already fused is dropped and counted. Raise it when the detectors'
        # latencies differ by more than the cameras' phase.
        window_s = declare(self, 'reorder_window_s', 0.0,
                           'longest hold of a point to restore stamp order across topics [s]',
                           min_value=0.0, max_value=1.0, read_only=True)
        trail_length = declare(self, 'trail_length', 120,
                               'points in the /ball/marker trail', min_value=2)
        marker_period_s = declare(self, 'marker_period_s', 0.1,
                                  'period of /ball/marker [s]; 0 disables', min_value=0.0)
        diagnostics_period_s = declare(self, 'diagnostics_period_s', 1.0,
                                       'period of /diagnostics [s]; 0 disables',
                                       min_value=0.0)
        offsets_s = declare(self, 'time_offsets_s', [0.0],
                            "seconds added to each camera's stamps, same order as "
                            "camera_names; [0.0]: the calibration files' time_offset_s",
                            read_only=True)
        self.apply_estimates = declare(self, 'estimate_time_offsets', False,
                                       'apply the online time-offset estimates (else report '
                                       'them in /diagnostics only)', read_only=True)
        offset_window_s = declare(self, 'time_offset_window_s', 10.0,
                                  'sliding window of the online time-offset estimate [s]',
                                  min_value=0.5, read_only=True)
        offset_period_s = declare(self, 'time_offset_update_period_s', 1.0,
                                  'period of the online time-offset estimate [s]; 0 disables',
                                  min_value=0.0, read_only=True)
        depth = declare(self, 'qos_depth', INPUT_QUEUE_DEPTH,
                        'queue of each image point subscription (keep last): points that '
                        'arrive while the node is starved of CPU wait here', min_value=1,
                        read_only=True)
        self.max_slew = declare(self, 'time_offset_max_slew', 0.005,
                                'fastest change of an applied offset [s per s of stamps]',
                                min_value=0.0, max_value=0.5, read_only=True)
        if not self.world_frame:
            raise StartupError('parameter world_frame: must not be empty (the frame_id of '
                               '/ball/position, e.g. world)')
        if files == [''] or files == []:
            files = []
        #: True when the calibrations are the simulated rig's (calibration_files not given).
        self.default_calibration = not files
        self.cameras = load_cameras(names, files)
        path_window_s = declare(self, 'trajectory_max_window_s', DEFAULT_MAX_WINDOW_S,
                                'method trajectory: longest window of the path fit [s]',
                                min_value=0.01, max_value=5.0, read_only=True)
        order = declare(self, 'trajectory_order', 2,
                        'method trajectory: 2 constant acceleration, 1 constant velocity',
                        min_value=1, max_value=2, read_only=True)
        options = {}
        if method == 'trajectory':
            options = {'max_window_s': path_window_s, 'order': order}
        self.offsets_s = self._configured_offsets(names, offsets_s)
        #: Offsets in force [ns] (move towards :attr:`_target_ns` at most max_slew).
        self._applied_ns = {name: seconds_to_ns(value) for name, value in self.offsets_s.items()}
        self._target_ns = dict(self._applied_ns)
        self._last_raw_ns = {}
        self.offset_estimator = None
        self._estimates = None  # the process running the online estimate
        self._pending = None  # the estimate running there
        self._closing = False
        if offset_period_s > 0:
            self.offset_estimator = OnlineOffsetEstimator(self.cameras, self.offsets_s,
                                                          window_s=offset_window_s)
        try:
            self.fuser = make_fuser(self.cameras, method=method,
                                    sync_tolerance_ns=_seconds_to_ns('sync_tolerance_s', sync_s),
                                    max_gap_ns=_seconds_to_ns('max_gap_s', gap_s),
                                    image_margin=image_margin, max_speed_mps=max_speed_mps,
                                    workspace_min_m=list(workspace_min_m),
                                    workspace_max_m=list(workspace_max_m), **options)
        except ValueError as err:
            if isinstance(err, StartupError):
                raise
            raise StartupError(f'fuser parameters (method, sync_tolerance_s, max_gap_s, '
                               f'image_margin, max_speed_mps, workspace_*_m, trajectory_*): '
                               f'{err}') from err
        self._names = list(names)
        self._base_window_ns = _seconds_to_ns('reorder_window_s', window_s)
        self._window_ns = self._base_window_ns + self._offset_spread_ns()
        self._max_gap_ns = self.fuser.max_gap_ns
        self.buffer = ReorderBuffer(self._window_ns, sources=self._names)
        #: Counts: ``late`` (points older than one already fused, over all sessions),
        #: ``sessions`` (new sessions the core started: stamps jumped, or the rig paused),
        #: ``malformed`` (messages that are not a serialized PointStamped: dropped),
        #: ``internal_error`` (points the method failed on, a bug: dropped, logged).
        self.node_stats = Counter()
        #: Seconds from a point's arrival to its estimate's publication (no hold), recent ones.
        self.processing_times_s = deque(maxlen=10_000)
        # The same since the last /diagnostics (bounded: without diagnostics none reads it).
        self._period_times_s = deque(maxlen=100_000)
        self._inputs = Counter()
        self._inputs_reported = Counter()
        self._last_stamp = {}
        self._deltas = {}  # 'camera1->camera2' -> (count, sum ns, last ns)
        self._delta_keys = {(a, b): f'{a}->{b}' for a in names for b in names if a != b}
        self._processed_at = 0.0  # perf_counter() after the last point's update and publish
        self._trail = deque(maxlen=trail_length)
        self._newest_ns = None
        self._reported_at = time.monotonic()

        self._position_pub = self.create_publisher(PointStamped, 'ball/position', 10)
        # Serialized here (2 us) rather than converted by rclpy (50-100 us).
        self._encode_position = point_encoder(self.world_frame)
        #: Other publishers of /ball/position (a second fuser doubles every message).
        self.position_watch = PublisherWatch(
            self, self._position_pub, 'two fusers on the same topics? every position '
            'reaches subscribers twice')
        self._marker_pub = self.create_publisher(Marker, 'ball/marker', 10)
        self._diagnostics_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self._subscriptions = [
            self.create_subscription(PointStamped, f'{name}/ball/image_point',
                                     functools.partial(self._on_point, name), depth, raw=True)
            for name in names]
        self._flush_timer = None
        if self.buffer.window_ns > 0 or self.apply_estimates:
            self._flush_timer = self.create_timer(max(window_s, 0.005), self._on_flush_timer)
            self._flush_timer.cancel()
        if marker_period_s > 0:
            self.create_timer(marker_period_s, self._publish_marker)
        if diagnostics_period_s > 0:
            self.create_timer(diagnostics_period_s, self._publish_diagnostics)
        if self.offset_estimator is not None:
            # Started now: starting it at the first estimate stalled fusion for about a second.
            try:
                self._estimates = offset_worker()
                self._estimates.submit(int)
            except (OSError, RuntimeError) as err:  # e.g. no /dev/shm: fuse without the estimate
                self.get_logger().warning(f'no online time-offset estimate: cannot start its '
                                          f'worker process ({err})')
                self._estimates, self.offset_estimator = None, None
            else:
                self.create_timer(offset_period_s, self._estimate_offsets)
        self.get_logger().info(
            f'fusing {", ".join(names)} with method {method!r} -> '
            f'{self._position_pub.topic_name}')

    # -- callbacks ------------------------------------------------------------------------------

    def _configured_offsets(self, names, offsets_s) -> dict:
        """Return the offsets [s] in force at start-up (parameter over calibration files)."""
        overrides = None
        if list(offsets_s) != [0.0]:
            if len(offsets_s) != len(names):
                raise StartupError(f'parameter time_offsets_s: {len(offsets_s)} values for '
                                   f'{len(names)} camera_names (one per camera, same order)')
            overrides = dict(zip(names, offsets_s))
        try:
            return camera_time_offsets(self.cameras, overrides)
        except PseudoStereoError as err:
            raise StartupError(f'parameter time_offsets_s: {err}') from err

    def _offset_spread_ns(self) -> int:
        values = list(self._applied_ns.values()) + list(self._target_ns.values())
        return max(values) - min(values) if values else 0

    def _shift(self, observation: Observation) -> Observation:
        """Put a raw observation on the common clock (slewing the camera's applied offset)."""
        name, stamp = observation.camera, observation.stamp_ns
        applied, target = self._applied_ns[name], self._target_ns[name]
        last = self._last_raw_ns.get(name)
        if applied != target and last is not None and stamp > last:
            # At most max_slew seconds of change per second of stamps: below 1, a camera's
            # shifted stamps keep their order and never jump.
            room = int(self.max_slew * (stamp - last))
            applied += max(-room, min(room, target - applied))
            self._applied_ns[name] = applied
        if last is None or stamp > last or last - stamp > self._max_gap_ns:
            self._last_raw_ns[name] = stamp
        return shift_observation(observation, applied)

    def _estimate_offsets(self) -> None:
        """Take the finished estimate, start the next one (in a worker process: see below)."""
        # In another process, not a thread: an update holds Python's global lock for 10-60 ms,
        # which stalled fusion in a thread (p99 68-89 ms from source to /ball/position at
        # 2 x 1,000 Hz, against 7-20 ms without the estimate; README, Load).
        if self._closing:
            return
        pending = self._pending
        if pending is not None:
            if not pending.done():
                return
            self._pending = None
            try:
                self.offset_estimator.accept(pending.result())
            except Exception as err:  # noqa: B902 -- any failure of the worker: keep fusing
                self.get_logger().warning(f'time-offset estimate failed ({type(err).__name__}): '
                                          f'{err}; the previous estimate stays',
                                          throttle_duration_sec=60.0)
        estimate = self.offset_estimator.latest
        if estimate is not None and self.apply_estimates:
            for name in self._names[1:]:
                if self.offset_estimator.usable(name):
                    self._target_ns[name] = seconds_to_ns(estimate.offsets_s[name])
            self._window_ns = self._base_window_ns + self._offset_spread_ns()
            self.buffer.window_ns = self._window_ns
        if not self.offset_estimator.added:
            return
        job = self.offset_estimator.snapshot()
        if job is None:
            return
        try:
            if self._estimates is None:
                self._estimates = offset_worker()
            self._pending = self._estimates.submit(run_offset_job, job)
        except (BrokenProcessPool, OSError, RuntimeError) as err:  # the worker died: try again
            self.get_logger().warning(f'time-offset worker restarted: {err}',
                                      throttle_duration_sec=60.0)
            if self._estimates is not None:
                self._estimates.shutdown(wait=False, cancel_futures=True)
            self._estimates = None

    def destroy_node(self):
        """Stop the offset worker process, then destroy the node."""
        if self._estimates is not None:
            # Not waiting: a running job at idle priority may take long on a busy core; the
            # worker ends after it (or with this process).
            self._estimates.shutdown(wait=False, cancel_futures=True)
            self._estimates = None
        self._closing = True  # a timer after this starts no new worker
        return super().destroy_node()

    def _on_point(self, name: str, data: bytes) -> None:
        # Subscribed raw: decode_point reads the bytes in 1-2 us, rclpy's message object costs
        # 20-60 us before the callback. Bookkeeping not needed for the estimate (the offset
        # estimate's window, the stamp deltas) runs after the position is published.
        start = time.perf_counter()
        self._inputs[name] += 1
        try:
            stamp_ns, u, v, _ = decode_point(data)
        except EncodingError as err:
            self.node_stats['malformed'] += 1
            self.get_logger().warning(f'{name}/ball/image_point: message dropped (malformed): '
                                      f'{err}', throttle_duration_sec=1.0)
            return
        raw = Observation(name, stamp_ns, u, v)
        observation = self._shift(raw)
        if self.fuser.off_timeline(observation.stamp_ns):
            self._off_timeline(observation)
        else:
            late_before = self.buffer.stats['late']
            released = self.buffer.push(observation.stamp_ns, name, observation,
                                        time.monotonic_ns())
            self.node_stats['late'] += self.buffer.stats['late'] - late_before
            for item in released:
                self._process(item)
            if released and released[-1] is observation:
                elapsed = self._processed_at - start
                self.processing_times_s.append(elapsed)
                self._period_times_s.append(elapsed)
            if len(self.buffer) and self._flush_timer is not None and \
                    self._flush_timer.is_canceled():
                self._flush_timer.reset()
        if self.offset_estimator is not None:
            self.offset_estimator.add(raw)

    def _on_flush_timer(self) -> None:
        for item in self.buffer.pop_due(time.monotonic_ns()):
            self._process(item)
        if not len(self.buffer):
            self._flush_timer.cancel()

    def _off_timeline(self, observation: Observation) -> None:
        """Fuse what is held, then let the core decide on a stamp far from the session's."""
        for item in self.buffer.flush():
            self._process(item)
        session = self.fuser.session
        self._process(observation)
        if self.fuser.session != session:  # the cameras agreed on the jump: start over
            self.buffer = ReorderBuffer(self._window_ns, sources=self._names)
            self._last_stamp = {observation.camera: observation.stamp_ns}
            self.node_stats['sessions'] += 1

    def _process(self, observation: Observation) -> None:
        try:
            estimate = self.fuser.update(observation)
        except Exception as err:  # noqa: B902 -- the outermost handler of one point
            # A bug in a method must not end the node: drop the point, say so, keep fusing.
            estimate = None
            self.node_stats['internal_error'] += 1
            self.get_logger().error(
                f'{observation.camera}: point stamped {observation.stamp_ns} ns dropped: '
                f'{type(err).__name__}: {err} (a bug in method {self.fuser.method!r}: please '
                f'report it)', throttle_duration_sec=1.0)
        if estimate is not None:
            self._position_pub.publish(self._encode_position(estimate.stamp_ns, estimate.x,
                                                             estimate.y, estimate.z))
        self._processed_at = time.perf_counter()
        if estimate is not None:
            self._trail.append((estimate.x, estimate.y, estimate.z))
            self._newest_ns = estimate.stamp_ns
        # The stamp differences between cameras (delta12, delta21: /diagnostics).
        name, stamp = observation.camera, observation.stamp_ns
        for other, other_stamp in self._last_stamp.items():
            if other != name and other_stamp < stamp:
                key = self._delta_keys[other, name]
                count, total, _ = self._deltas.get(key, (0, 0, 0))
                self._deltas[key] = (count + 1, total + stamp - other_stamp, stamp - other_stamp)
        if stamp > self._last_stamp.get(name, -1):
            self._last_stamp[name] = stamp

    def _publish_marker(self) -> None:
        if self._newest_ns is not None and len(self._trail) >= 2:
            self._marker_pub.publish(trail_marker(self._trail, self._newest_ns,
                                                  self.world_frame))

    def _publish_diagnostics(self) -> None:
        now = time.monotonic()
        elapsed = max(now - self._reported_at, 1e-9)
        self._reported_at = now
        stats = self.fuser.stats
        values = {}
        for name in self.fuser.camera_names:
            values[f'{name} input rate [Hz]'] = (self._inputs[name]
                                                 - self._inputs_reported[name]) / elapsed
        estimates = stats['estimates']
        values['output rate [Hz]'] = (estimates - self._inputs_reported['_estimates']) / elapsed
        self._inputs_reported = Counter(self._inputs)
        self._inputs_reported['_estimates'] = estimates
        for key, (count, total, last) in sorted(self._deltas.items()):
            values[f'delta {key} mean [ms]'] = total / count / 1e6
            values[f'delta {key} last [ms]'] = last / 1e6
        values['observations'] = stats['observations']
        values['estimates'] = estimates
        # The node's own work per point (callback start -> position published), this period.
        times, self._period_times_s = self._period_times_s, deque(maxlen=100_000)
        if times:
            p50, p99 = np.percentile(times, (50, 99)) * 1e3
            values['point received -> published p50 [ms]'] = float(p50)
            values['point received -> published p99 [ms]'] = float(p99)
            values['point received -> published max [ms]'] = max(times) * 1e3
        # Every observation gives an estimate or exactly one drop reason; 'late' and 'resets'
        # are not drops (a late point is still estimated when the method can).
        for key, count in self.fuser.dropped().items():
            values[f'dropped: {key}'] = count
        values['resets'] = stats['resets']
        if self.fuser.method == 'trajectory':
            values['outliers (not fitted)'] = stats['outlier']
            values['impacts (breaks)'] = stats['breaks']
            values['detection noise [px]'] = self.fuser.sigma_px or 0.0
        values['late (older than a fused point, after the reorder window)'] = \
            self.node_stats['late']
        values['new sessions (time jumped or paused)'] = self.node_stats['sessions']
        # Outside the core's counts: a malformed message never became an observation, and a
        # point the method failed on has no drop reason there. So estimates + every 'dropped:'
        # value = observations + malformed messages.
        values['dropped: malformed message'] = self.node_stats['malformed']
        values['dropped: internal error'] = self.node_stats['internal_error']
        values[f'other publishers of {self._position_pub.topic_name}'] = \
            self.position_watch.others
        inputs = sum(self._inputs.values())
        if inputs and not estimates:
            level, message = 'warn', 'receiving image points but no estimates yet'
        elif values['output rate [Hz]'] == 0 and inputs:
            level, message = 'warn', 'no estimates in the last period (a camera stale?)'
        else:
            level, message = 'ok', f'{estimates} estimates'
        status = diagnostic_status(f'{self.get_name()}: pseudo stereo fuser', level, message,
                                   values)
        self._diagnostics_pub.publish(
            diagnostic_array(self.get_clock().now().nanoseconds, [status, self._offset_status()]))

    def _offset_status(self):
        """Return the /diagnostics status of the time offsets (applied and estimated)."""
        values = {}
        estimate = self.offset_estimator.latest if self.offset_estimator else None
        for name in self._names:
            values[f'time offset {name} applied [ms]'] = self._applied_ns[name] / 1e6
            if name == self._names[0] or self.offset_estimator is None:
                continue
            if estimate is None:
                values[f'time offset {name} status'] = 'no estimate yet'
                continue
            values[f'time offset {name} estimate [ms]'] = estimate.offsets_s[name] * 1e3
            values[f'time offset {name} uncertainty [ms]'] = estimate.uncertainty_s[name] * 1e3
            values[f'time offset {name} samples'] = estimate.samples[name]
            warnings = estimate.warnings.get(name)
            values[f'time offset {name} status'] = warnings[0] if warnings else (
                'applied' if self.apply_estimates else 'ok (report only)')
        troubled = [name for name in self._names[1:]
                    if estimate is not None and estimate.warnings.get(name)]
        if troubled:
            level, message = 'warn', f'offset not usable: {", ".join(troubled)}'
        else:
            level, message = 'ok', ', '.join(
                f'{name} {self._applied_ns[name] / 1e6:+.3f} ms' for name in self._names)
        return diagnostic_status(f'{self.get_name()} time offsets', level, message, values)


def main(args=None) -> int:
    """Run the fuser node (``ros2 run pseudo_stereo_ros fuser``)."""
    return run_node(FuserNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
