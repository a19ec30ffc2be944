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
The physical plausibility gate every fusion method applies to its estimates.

An estimate [m] at a stamp [ns] is rejected (counted as ``implausible``,
never returned) when

- it lies outside the optional workspace box ``workspace_min_m`` ..
  ``workspace_max_m`` (per axis; an infinite bound is no bound), or
- it is farther from the last accepted estimate than the ball can travel at
  ``max_speed_mps`` (default 60 m/s, faster than any thrown or struck ball)
  in the time between them, plus the distance it covers in
  :data:`MIN_SPEED_INTERVAL_NS` (5 ms: 0.3 m at the default; two cameras'
  estimates of one instant differ by their noise, not by motion).

Recovery, so that a first wrong estimate cannot lock out the correct ones
after it: the speed test compares only with an accepted estimate at most
``window_ns`` old (the fuser sets it to the rig's max gap, a few frame
periods); after a longer gap the next estimate re-seeds the gate.  And a run
of consecutive rejected estimates that agree with each other (each within
the speed bound of the one before) replaces the accepted one: two against
an uncorroborated seed (no estimate agreed with it yet), three against an
estimate that continued a track (a bad detection spoils the two or three
events that extrapolate from it, and those may well agree with each
other; a ball that really is elsewhere, as when the detector switches to
the next ball, goes on agreeing).  So one gross estimate costs itself, a
wrong seed costs at most one correct estimate, and a real jump two.

This module is ROS-free.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Sequence
import math
import numbers

from .errors import FuserConfigError
from .records import Point3

__all__ = ['DEFAULT_MAX_SPEED_MPS', 'MIN_SPEED_INTERVAL_NS', 'PlausibilityGate']

#: Default fastest plausible ball speed [m/s].
DEFAULT_MAX_SPEED_MPS = 60.0
#: The speed bound never allows less than the motion in this time [ns].
MIN_SPEED_INTERVAL_NS = 5_000_000
# Consecutive mutually consistent estimates that replace an uncorroborated seed / a track.
_RUN_AGAINST_SEED = 2
_RUN_AGAINST_TRACK = 3


def _bound(name: str, values: Iterable[float] | None, default: float) -> Point3:
    """Return a validated (x, y, z) bound [m]."""
    if values is None:
        return (default, default, default)
    try:
        floats = tuple(float(v) for v in values)
    except (TypeError, ValueError) as err:
        raise FuserConfigError(f'{name} must be three numbers (x, y, z) [m], got {values!r}') \
            from err
    if len(floats) != 3 or any(math.isnan(v) for v in floats):
        raise FuserConfigError(f'{name} must be three numbers (x, y, z) [m], got {floats!r}')
    return floats[0], floats[1], floats[2]


class PlausibilityGate:
    """
    Reject estimates that no ball can produce (see the module docstring).

    :param max_speed_mps: fastest plausible speed [m/s]; None or 0 disables the speed test
    :param workspace_min_m: lower corner (x, y, z) of the workspace box [m]; None: unbounded
    :param workspace_max_m: upper corner (x, y, z) [m]; None: unbounded
    :param window_ns: the speed test compares with accepted estimates at most this old [ns]
        (an attribute: the fuser keeps it at the input gate's rig gap)
    :param stats: the counter to count ``implausible`` into; a new one if None
    :raises FuserConfigError: an invalid option, naming it
    """

    def __init__(self, *, max_speed_mps: float | None = DEFAULT_MAX_SPEED_MPS,
                 workspace_min_m: Sequence[float] | None = None,
                 workspace_max_m: Sequence[float] | None = None,
                 window_ns: int = 100_000_000, stats: Counter[str] | None = None) -> None:
        if max_speed_mps is None:
            max_speed_mps = 0.0
        if isinstance(max_speed_mps, bool) or not isinstance(max_speed_mps, numbers.Real) \
                or not max_speed_mps >= 0:
            raise FuserConfigError(f'max_speed_mps must be >= 0 m/s (0: no speed test), got '
                                   f'{max_speed_mps!r}')
        #: Fastest plausible speed [m/s]; 0 when the speed test is off.
        self.max_speed_mps: float = float(max_speed_mps)
        # Reach per ns of elapsed time [m/ns]; None when the speed test is off.
        self._speed: float | None = (self.max_speed_mps * 1e-9
                                     if 0 < self.max_speed_mps < math.inf else None)
        self.workspace_min_m: Point3 = _bound('workspace_min_m', workspace_min_m, -math.inf)
        self.workspace_max_m: Point3 = _bound('workspace_max_m', workspace_max_m, math.inf)
        for axis, low, high in zip('xyz', self.workspace_min_m, self.workspace_max_m):
            if not low < high:
                raise FuserConfigError(f'workspace_min_m must be below workspace_max_m on every '
                                       f'axis, got {low} >= {high} on {axis}')
        corners = self.workspace_min_m + self.workspace_max_m
        self._box: bool = any(math.isfinite(v) for v in corners)
        self.window_ns: int = int(window_ns)
        self.stats: Counter[str] = Counter() if stats is None else stats
        # (stamp, point, corroborated) of the last accepted estimate
        self._accepted: tuple[int, Point3, bool] | None = None
        # (stamp, point) of the last consecutive estimates rejected by the speed test that agree
        # with each other
        self._rejected: list[tuple[int, Point3]] = []

    def reset(self) -> None:
        """Forget the accepted and rejected estimates (a new session)."""
        self._accepted = None
        self._rejected = []

    def accept(self, stamp_ns: int, point: Point3) -> bool:
        """
        Tell whether an estimate is plausible; count ``implausible`` when it is not.

        :param stamp_ns: the estimate's stamp [ns]
        :param point: (x, y, z) [m], finite
        :return: True to publish the estimate
        """
        if self._box:
            low, high = self.workspace_min_m, self.workspace_max_m
            if not (low[0] <= point[0] <= high[0] and low[1] <= point[1] <= high[1]
                    and low[2] <= point[2] <= high[2]):
                self.stats['implausible'] += 1
                return False
        speed = self._speed
        if speed is None:
            return True
        accepted = self._accepted
        if accepted is None or abs(stamp_ns - accepted[0]) > self.window_ns:
            self._accepted = (stamp_ns, point, False)  # a seed, not yet corroborated
            self._rejected.clear()
            return True
        # The common case, inline: within the speed bound of the accepted estimate.
        reach = speed * max(abs(stamp_ns - accepted[0]), MIN_SPEED_INTERVAL_NS)
        other = accepted[1]
        dx, dy, dz = point[0] - other[0], point[1] - other[1], point[2] - other[2]
        if dx * dx + dy * dy + dz * dz <= reach * reach:
            self._accepted = (stamp_ns, point, True)
            if self._rejected:
                self._rejected.clear()
            return True
        rejected = self._rejected
        if rejected and not self._near(rejected[-1], stamp_ns, point, speed):
            rejected.clear()  # not a consistent run: start a new one
        rejected.append((stamp_ns, point))
        if len(rejected) >= (_RUN_AGAINST_TRACK if accepted[2] else _RUN_AGAINST_SEED):
            # A run of consecutive estimates that agree with each other but not with the
            # accepted one: the ball is there (another ball, or the seed was wrong).
            self._accepted = (stamp_ns, point, True)
            rejected.clear()
            return True
        self.stats['implausible'] += 1
        return False

    def _near(self, reference: tuple[int, Point3], stamp_ns: int, point: Point3,
              speed: float) -> bool:
        """Return True when point is within the speed bound (``speed`` [m/ns]) of a reference."""
        dt = abs(stamp_ns - reference[0])
        if dt > self.window_ns:
            return False
        reach = speed * max(dt, MIN_SPEED_INTERVAL_NS)
        other = reference[1]
        dx, dy, dz = point[0] - other[0], point[1] - other[1], point[2] - other[2]
        return dx * dx + dy * dy + dz * dz <= reach * reach
