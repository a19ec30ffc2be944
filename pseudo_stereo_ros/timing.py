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
The input and timing rules every fusion method shares: :class:`InputGate`.

An estimator (``paper``, ``naive`` or any other) hands each observation to
:meth:`InputGate.admit` first and fuses only what comes back.  The gate
owns every rule about what an observation may be and how stamps behave;
the estimator owns its geometry.  Stamps are integer nanoseconds, pixels raw
(distorted) image coordinates [px].

Validation (one drop reason each, counted in the shared ``stats``):
``unknown_camera``; ``bad_stamp`` (not an integer, a bool, or outside the
int64 range of a ROS stamp); ``bad_pixel`` (u or v not a real number: a
string, None, a bool); ``non_finite`` (NaN, infinite, or an integer too large
for a float); ``outside_image`` (farther outside the image than
``image_margin`` times its width or height: no detector reports that);
``undistort_failed``; ``duplicate`` and ``out_of_order`` (a stamp not after
the camera's previous one).

Frame period: each camera's period is the lower quartile of its last 16
intervals between admitted frames (at each of the first four intervals, then
at every fourth), counting only intervals from
:data:`MIN_FRAME_INTERVAL_NS` (0.1 ms: two frames closer than that are one
instant delivered twice, never a frame rate) up to ``max_gap_ns``.  A double
trigger is one short interval among many and never sets the period (it can
for the first three intervals of a camera only when it is at least 0.1 ms
long); missed detections make long intervals, which the quartile ignores
unless three quarters of the recent frames are missing.  From the periods:

- ``max_gap_for(camera)`` = min(``max_gap_ns``, :data:`GAP_PERIODS` periods):
  the longest interval over which the camera's points are interpolated or
  used (``max_gap_ns`` until the period is known);
- ``sync_tolerance_ns`` = min(configured tolerance, a quarter of the
  shortest period): observations of two cameras closer than this are one
  instant;
- ``baseline_floor_ns`` = max(``sync_tolerance_ns``, 1/40 of the shortest
  period, 0.1 ms): no estimator may extrapolate from two instants closer
  than this (the extrapolation gain would multiply the pixel noise; with
  the defaults at 25 fps and faster it equals the tolerance).

Sessions: the gate keeps a session's newest stamp (the *timeline*).  An
observation more than ``rig_gap_ns`` (the largest camera max gap) before or
after it is held, not fused, until the next observations decide:

- another camera's observation within ``rig_gap_ns`` of the held one: the
  cameras agree on the jump (a replay looping, a restarted clock, the rig
  resuming after a pause): a **new session** (``session`` increments,
  ``resets`` counts it); the estimator forgets its history and fuses the
  held observations, then the new one;
- three consecutive frames of the held camera alone on its new timeline,
  with no camera on the old one in between: the rig paused and this camera
  resumed first: a new session likewise;
- an observation on the old timeline (or on a third one): the held stamps
  were that camera's outliers (a stamp of 0, a negative stamp, one 1e6 s
  ahead): dropped and counted as ``stamp_outlier``; the history is kept.

Held observations are counted in ``observations`` and in :attr:`InputGate.held`
until decided, so ``observations = estimates + drops + held`` at all
times; :meth:`InputGate.flush` decides the held ones at the end of a
recording (``stamp_outlier``).  A new session keeps the measured periods (the
rig is the same); :meth:`InputGate.reset` forgets them too, restoring the
configured tolerance and max gap.

Each camera's own history: an admitted frame more than the camera's max gap
after its previous one comes ``fresh`` (the estimator drops that camera's
older frames; counted in ``resets``).  A frame older than the newest admitted
frame of another camera comes ``late`` (a slower detector).

Use from an estimator (as :class:`~pseudo_stereo_ros.fusion.Fuser` does)::

    gate = InputGate(cameras, sync_tolerance_ns=..., max_gap_ns=..., stats=my_counter)
    admission = gate.admit(observation)          # at the top of every update
    if admission.new_session:
        forget_all_history()
    for item in admission.ready:                 # usually one; several opening a session
        if item.fresh:
            forget_history_of(item.observation.camera)
        fuse(item.observation.stamp_ns, item.x, item.y, late=item.late)
    # while fusing: partners' data at most gate.max_gaps[name] old; pairs within
    # gate.sync_tolerance_ns are one instant; never extrapolate over a baseline
    # <= gate.baseline_floor_ns; then PlausibilityGate.accept() before returning.
    gate.flush()                                 # at the end of a recording

This module is ROS-free; its clock is the stamps only.
"""

from __future__ import annotations

from collections import Counter, deque
from collections.abc import Mapping, Sequence
import math
import numbers
import operator
from typing import NamedTuple, TypeAlias

import numpy as np

from .camera import Camera
from .errors import FuserConfigError
from .records import Observation

__all__ = [
    'Admission',
    'Admitted',
    'DEFAULT_IMAGE_MARGIN',
    'DEFAULT_MAX_GAP_NS',
    'DEFAULT_SYNC_TOLERANCE_NS',
    'GAP_PERIODS',
    'INPUT_DROP_REASONS',
    'InputGate',
    'MIN_FRAME_INTERVAL_NS',
    'stamp_sort_key',
]

#: Default for treating two cameras' observations as simultaneous: 1 ms, 3% of a 30 fps period.
DEFAULT_SYNC_TOLERANCE_NS = 1_000_000
#: Default upper bound of the max gap: 0.1 s (3 periods at 30 fps).
DEFAULT_MAX_GAP_NS = 100_000_000
#: Default margin around the image, as a fraction of its width and height.
DEFAULT_IMAGE_MARGIN = 0.1
#: A camera's max gap in frame periods: bridges up to three missed detections (an interval of
#: four periods, with jitter), never four.
GAP_PERIODS = 4.5
#: Intervals shorter than this are one instant delivered twice (a double trigger), never a frame
#: period; the baseline floor never goes below it [ns]. Cameras above 10 kHz are not supported.
MIN_FRAME_INTERVAL_NS = 100_000

#: Why the gate dropped an observation (keys of the shared stats).
INPUT_DROP_REASONS = {
    'unknown_camera': 'the camera name is not one of the configured cameras',
    'bad_stamp': 'the stamp is not an integer number of nanoseconds in the int64 range '
                 '(a float or a bool is refused)',
    'bad_pixel': 'u or v is not a real number (a string, None, a bool)',
    'non_finite': 'u or v is NaN, infinite or too large for a float',
    'outside_image': 'the pixel lies outside the image by more than image_margin',
    'undistort_failed': 'the pixel could not be undistorted (far outside the lens model)',
    'stamp_outlier': "the stamp jumped away from the other cameras' (one camera's bad stamp)",
    'duplicate': 'same stamp as the previous observation of that camera',
    'out_of_order': 'stamp older than the previous observation of that camera',
}

# The sync tolerance never exceeds this fraction of the shortest frame period.
_SYNC_PERIOD_FRACTION = 0.25
# The extrapolation baseline never falls below this fraction of the shortest frame period.
_BASELINE_PERIOD_FRACTION = 1 / 40
# Intervals kept per camera for its period.
_PERIOD_WINDOW = 16
# Consecutive frames of one camera alone on a new timeline that start a new session.
_CONFIRM_FRAMES = 3
_INT64 = (-2 ** 63, 2 ** 63)

# A validated observation and its normalized coordinates (x, y), as the gate keeps it.
_Item: TypeAlias = tuple[Observation, float, float]


class Admitted(NamedTuple):
    """
    One observation the gate passed, with what the estimator needs to fuse it.

    ``observation`` has an ``int`` stamp and ``float`` pixels; ``x, y`` are
    its undistorted normalized coordinates (X/Z, Y/Z); ``late`` is True when
    another camera already delivered a later frame; ``fresh`` is True when
    the camera's previous frame is older than its max gap, so its older
    frames must not be used.
    """

    observation: Observation
    x: float
    y: float
    late: bool
    fresh: bool


class Admission(NamedTuple):
    """
    What :meth:`InputGate.admit` decided for one observation.

    When ``new_session`` is True the estimator forgets all its history
    first; then it fuses ``ready`` in order (empty: dropped or held).  Only
    the last item can give an estimate: the others are held observations of a
    single camera opening a new session.
    """

    new_session: bool
    ready: tuple[Admitted, ...]


_NOTHING = Admission(False, ())


class InputGate:
    """
    Validate observations and apply the shared timing rules (see the module docstring).

    :param cameras: the calibrated cameras (a sequence, or a mapping name -> camera)
    :param sync_tolerance_ns: configured tolerance for simultaneous observations [ns]
        (default 1 ms); the one in force is :attr:`sync_tolerance_ns`
    :param max_gap_ns: upper bound of every camera's max gap [ns] (default 0.1 s)
    :param image_margin: how far outside the image a pixel may lie, as a fraction of the
        image width and height (default 0.1; ``math.inf`` disables the check)
    :param stats: the counter to count into (shared with the estimator); a new one if None
    :raises FuserConfigError: an invalid option, naming it
    """

    def __init__(self, cameras: Sequence[Camera] | Mapping[str, Camera], *,
                 sync_tolerance_ns: int | None = None, max_gap_ns: int | None = None,
                 image_margin: float | None = None, stats: Counter[str] | None = None) -> None:
        if isinstance(cameras, Mapping):
            cameras = list(cameras.values())
        self._cameras: dict[str, Camera] = {camera.name: camera for camera in cameras}
        tolerance = DEFAULT_SYNC_TOLERANCE_NS if sync_tolerance_ns is None else sync_tolerance_ns
        gap = DEFAULT_MAX_GAP_NS if max_gap_ns is None else max_gap_ns
        margin = DEFAULT_IMAGE_MARGIN if image_margin is None else image_margin
        for name, value in (('sync_tolerance_ns', tolerance), ('max_gap_ns', gap)):
            if isinstance(value, bool) or not isinstance(value, numbers.Real) \
                    or not math.isfinite(value):
                raise FuserConfigError(f'{name} must be a finite number of ns, got {value!r}')
        #: The configured tolerance [ns]; :attr:`sync_tolerance_ns` is the one in force.
        self.max_sync_tolerance_ns = int(tolerance)
        #: The configured upper bound of every camera's max gap [ns].
        self.max_gap_ns = int(gap)
        if self.max_sync_tolerance_ns < 0:
            raise FuserConfigError(f'sync_tolerance_ns must be >= 0, got '
                                   f'{self.max_sync_tolerance_ns}')
        if self.max_gap_ns <= self.max_sync_tolerance_ns:
            raise FuserConfigError(f'max_gap_ns ({self.max_gap_ns}) must exceed '
                                   f'sync_tolerance_ns ({self.max_sync_tolerance_ns})')
        if isinstance(margin, bool) or not isinstance(margin, numbers.Real) \
                or not margin >= 0:
            raise FuserConfigError(f'image_margin must be a fraction >= 0 of the image size '
                                   f'(inf: no check), got {margin!r}')
        #: The margin around the image, a fraction of its width and height.
        self.image_margin = float(margin)
        # name -> (u_min, u_max, v_min, v_max) [px]
        self._bounds: dict[str, tuple[float, float, float, float]] = {}
        for name, camera in self._cameras.items():
            width, height = camera.image_size
            du, dv = self.image_margin * width, self.image_margin * height
            self._bounds[name] = (-du, width - 1 + du, -dv, height - 1 + dv)
        #: Counts: ``observations``, ``resets`` and one key per drop reason of
        #: :data:`INPUT_DROP_REASONS` (shared with the estimator when given).
        self.stats: Counter[str] = Counter() if stats is None else stats
        #: Incremented at every new session (a jump agreed by the cameras, or a pause).
        self.session: int = 0
        self._intervals: dict[str, deque[int]] = {
            name: deque(maxlen=_PERIOD_WINDOW) for name in self._cameras}
        self._period: dict[str, int | None] = dict.fromkeys(self._cameras)
        self._since_estimate: dict[str, int] = dict.fromkeys(self._cameras, 0)
        #: Camera name -> its max gap [ns] (read-only for estimators; see :meth:`max_gap_for`).
        self.max_gaps: dict[str, int] = dict.fromkeys(self._cameras, self.max_gap_ns)
        self._gap: dict[str, int] = self.max_gaps
        self._tolerance: int = self.max_sync_tolerance_ns
        self._floor: int = max(self._tolerance, MIN_FRAME_INTERVAL_NS)
        self._rig_gap: int = self.max_gap_ns
        self._last: dict[str, int] = {}
        self._newest: int | None = None
        self._held: list[_Item] = []  # observations of one camera, stamp order

    # -- what the estimator asks ----------------------------------------------------------------

    @property
    def camera_names(self) -> list[str]:
        """Return the configured camera names, in order."""
        return list(self._cameras)

    @property
    def sync_tolerance_ns(self) -> int:
        """Return the tolerance in force [ns]: min(configured, shortest period / 4)."""
        return self._tolerance

    @property
    def baseline_floor_ns(self) -> int:
        """Return the shortest time baseline an estimator may extrapolate from [ns]."""
        return self._floor

    @property
    def rig_gap_ns(self) -> int:
        """Return the largest camera max gap [ns]: farther from the timeline is a jump."""
        return self._rig_gap

    @property
    def held(self) -> int:
        """Return the number of observations held until a jump is confirmed or refuted."""
        return len(self._held)

    def period_ns(self, camera: str) -> int | None:
        """Return the camera's measured frame period [ns], or None before it is known."""
        return self._period[camera]

    def max_gap_for(self, camera: str) -> int:
        """Return the camera's max gap [ns]: min(max_gap_ns, GAP_PERIODS periods)."""
        return self._gap[camera]

    def off_timeline(self, stamp_ns: object) -> bool:
        """
        Tell whether a stamp is farther than :attr:`rig_gap_ns` from the session's timeline.

        Such an observation is held by :meth:`admit` until the cameras agree on a jump (a
        new session) or it proves to be an outlier.  A node asks this before buffering an
        observation, so that a new timeline never enters a buffer ordered by the old one.

        :param stamp_ns: a stamp [ns] (anything else: False)
        :return: True for a jump away from the current session
        """
        if self._newest is None or isinstance(stamp_ns, bool) \
                or not isinstance(stamp_ns, numbers.Integral):
            return False
        return abs(int(stamp_ns) - self._newest) > self._rig_gap

    # -- the rules ------------------------------------------------------------------------------

    def admit(self, observation: Observation) -> Admission:
        """
        Validate one observation and apply the timing rules.

        :param observation: camera name, stamp [ns], raw pixel (any values: bad ones are
            dropped and counted, never raised)
        :return: whether a new session starts, and the observations to fuse now
        """
        stats = self.stats
        stats['observations'] += 1
        camera, stamp, u, v = observation
        try:
            bounds = self._bounds.get(camera)
        except TypeError:  # an unhashable camera "name"
            bounds = None
        if bounds is None:
            stats['unknown_camera'] += 1
            return _NOTHING
        converted = False
        if type(stamp) is not int:  # the common case is fast; bools are not int here
            if isinstance(stamp, (bool, np.bool_)):
                stats['bad_stamp'] += 1
                return _NOTHING
            try:
                stamp = operator.index(stamp)  # numpy integers; floats would lose ns
            except TypeError:
                stats['bad_stamp'] += 1
                return _NOTHING
            converted = True
        if not _INT64[0] <= stamp < _INT64[1]:
            stats['bad_stamp'] += 1
            return _NOTHING
        if type(u) is not float or type(v) is not float:
            pixel = _pixel_values(u, v)
            if isinstance(pixel, str):
                stats[pixel] += 1
                return _NOTHING
            u, v = pixel
            converted = True
        elif not (math.isfinite(u) and math.isfinite(v)):
            stats['non_finite'] += 1
            return _NOTHING
        if not (bounds[0] <= u <= bounds[1] and bounds[2] <= v <= bounds[3]):
            stats['outside_image'] += 1
            return _NOTHING
        x, y = self._cameras[camera].normalize_one(u, v)
        if not (math.isfinite(x) and math.isfinite(y)):
            stats['undistort_failed'] += 1
            return _NOTHING
        if converted or type(observation) is not Observation:
            observation = Observation(camera, stamp, u, v)
        item: _Item = (observation, x, y)

        newest = self._newest
        if self._held:
            return self._decide(item)
        if newest is not None and abs(stamp - newest) > self._rig_gap:
            self._held.append(item)
            return _NOTHING
        admitted = self._accept(item)
        return _NOTHING if admitted is None else Admission(False, (admitted,))

    def flush(self) -> int:
        """
        Decide the held observations at the end of a recording: no camera agreed, outliers.

        :return: how many were dropped (counted as ``stamp_outlier``)
        """
        count = len(self._held)
        self.stats['stamp_outlier'] += count
        self._held.clear()
        return count

    def reset(self) -> None:
        """Forget everything but the counters: session, held observations, measured periods."""
        self.flush()
        self._last.clear()
        self._newest = None
        for intervals in self._intervals.values():
            intervals.clear()
        for name in self._period:
            self._period[name] = None
            self._since_estimate[name] = 0
        self._derive()

    # -- internals ------------------------------------------------------------------------------

    def _decide(self, item: _Item) -> Admission:
        """Decide held observations with the next valid one (see the module rules)."""
        held = self._held
        newest = self._newest
        assert newest is not None, 'observations are held only away from a timeline'
        camera, stamp = item[0].camera, item[0].stamp_ns
        held_camera, held_stamp = held[-1][0].camera, held[-1][0].stamp_ns
        if abs(stamp - newest) <= self._rig_gap:
            # The old timeline goes on: the held stamps were one camera's outliers.
            self.flush()
            admitted = self._accept(item)
            return _NOTHING if admitted is None else Admission(False, (admitted,))
        if camera != held_camera and abs(stamp - held_stamp) <= self._rig_gap:
            return self._new_session(held + [item])
        if camera == held_camera and abs(stamp - held_stamp) <= self._gap[camera]:
            if stamp <= held_stamp:  # the held camera repeating itself
                self.stats['duplicate' if stamp == held_stamp else 'out_of_order'] += 1
                return _NOTHING
            held.append(item)
            if len(held) >= _CONFIRM_FRAMES:
                return self._new_session(list(held))
            return _NOTHING
        # Neither timeline: what was held is an outlier; this one may start the next.
        self.flush()
        held.append(item)
        return _NOTHING

    def _new_session(self, items: list[_Item]) -> Admission:
        self._held.clear()
        self._last.clear()
        self._newest = None
        self.session += 1
        self.stats['resets'] += 1
        ready: list[Admitted] = []
        for item in items:
            admitted = self._accept(item)
            if admitted is not None:
                ready.append(admitted)
        return Admission(True, tuple(ready))

    def _accept(self, item: _Item) -> Admitted | None:
        """Admit an observation on the current timeline (or drop a duplicate)."""
        observation, x, y = item
        camera, stamp = observation.camera, observation.stamp_ns
        last = self._last.get(camera)
        fresh = False
        if last is not None:
            interval = stamp - last
            if interval <= 0:
                self.stats['duplicate' if interval == 0 else 'out_of_order'] += 1
                return None
            if interval > self._gap[camera]:
                fresh = True  # this camera was silent: its old frames say nothing now
                self.stats['resets'] += 1
            if MIN_FRAME_INTERVAL_NS <= interval <= self.max_gap_ns:
                self._add_interval(camera, interval)
        self._last[camera] = stamp
        newest = self._newest
        late = newest is not None and stamp < newest
        if not late:
            self._newest = stamp
        return Admitted(observation, x, y, late, fresh)

    def _add_interval(self, camera: str, interval: int) -> None:
        intervals = self._intervals[camera]
        intervals.append(interval)
        count = len(intervals)
        if count > 4 and self._since_estimate[camera] < 3:
            self._since_estimate[camera] += 1  # re-estimated every fourth interval: cheaper
            return
        self._since_estimate[camera] = 0
        period = sorted(intervals)[count // 4]
        old = self._period[camera]
        # Jitter moves the quartile by a few us at every frame: re-derive on changes over 1%.
        if old is None or abs(period - old) * 100 > old:
            self._period[camera] = period
            self._derive()

    def _derive(self) -> None:
        """Recompute the max gaps, the tolerance, the floor and the rig gap from the periods."""
        known = [p for p in self._period.values() if p is not None]
        for name, period in self._period.items():
            self._gap[name] = (self.max_gap_ns if period is None
                               else min(self.max_gap_ns, int(GAP_PERIODS * period)))
        shortest = min(known) if known else None
        tolerance = self.max_sync_tolerance_ns
        floor = MIN_FRAME_INTERVAL_NS
        if shortest is not None:
            tolerance = min(tolerance, int(shortest * _SYNC_PERIOD_FRACTION))
            floor = max(floor, int(shortest * _BASELINE_PERIOD_FRACTION))
        self._tolerance = tolerance
        self._floor = max(floor, tolerance)
        self._rig_gap = max(self._gap.values())


def stamp_sort_key(observation: Observation) -> tuple[int, object]:
    """
    Order observations by stamp for offline processing; stamps that are not numbers go last.

    (They are dropped by :meth:`InputGate.admit`; sorting must not fail on them.)

    :param observation: an observation (any stamp)
    :return: a sort key
    """
    stamp = observation[1]
    if isinstance(stamp, numbers.Real) and stamp == stamp:
        return (0, stamp)
    return (1, 0)


def _pixel_values(u: object, v: object) -> tuple[float, float] | str:
    """Return the pixel ``(u, v)`` as finite floats, or the drop reason."""
    values = []
    for value in (u, v):
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
            return 'bad_pixel'
        try:
            number = float(value)
        except (OverflowError, ValueError, TypeError):
            return 'non_finite'
        if not math.isfinite(number):
            return 'non_finite'
        values.append(number)
    return values[0], values[1]
