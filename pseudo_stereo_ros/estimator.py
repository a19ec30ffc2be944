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
What every estimation method shares: cameras, input and timing rules, plausibility gate.

:class:`GatedEstimator` is the base of :class:`~pseudo_stereo_ros.fusion.Fuser`
(``paper``, ``naive``) and :class:`~pseudo_stereo_ros.trajectory.TrajectoryFuser`
(``trajectory``).  It checks the cameras, builds the counters, the
:class:`~pseudo_stereo_ros.timing.InputGate` (validation, frame periods, max
gaps, sync tolerance, sessions) and the
:class:`~pseudo_stereo_ros.plausibility.PlausibilityGate` from the same
options, and answers the session questions the fuser node asks.  A method
adds its own ``update``, ``process`` and ``_forget``.  ROS-free.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Mapping, Sequence

from .camera import Camera
from .errors import FuserConfigError
from .plausibility import DEFAULT_MAX_SPEED_MPS, PlausibilityGate
from .records import Estimate, Observation
from .timing import Admitted, INPUT_DROP_REASONS, InputGate, stamp_sort_key

__all__ = ['GatedEstimator', 'camera_list', 'estimator_class']

# Method name -> the class implementing it, filled as the classes are defined (see
# GatedEstimator.methods).  The factory (pseudo_stereo_ros.fusion.make_fuser) looks classes
# up here, so that fusion need not import the modules that build on it (trajectory uses the
# paper method's Fuser as its stand-in): no import cycle.  The package imports every method.
_CLASSES: dict[str, type[GatedEstimator]] = {}


def estimator_class(method: str) -> type[GatedEstimator]:
    """
    Return the class that implements an estimation method.

    :param method: the method's name (``paper``, ``naive``, ``trajectory``)
    :raises FuserConfigError: no class implements it
    """
    try:
        return _CLASSES[method]
    except KeyError:
        raise FuserConfigError(f'unknown method {method!r} (known: '
                               f'{", ".join(sorted(_CLASSES))})') from None


def camera_list(cameras: Sequence[Camera] | Mapping[str, Camera]) -> list[Camera]:
    """
    Return the cameras of an estimator as a list, checked.

    :param cameras: a sequence, or a mapping name -> camera
    :raises FuserConfigError: fewer than two cameras, or a repeated name
    """
    cameras = list(cameras.values()) if isinstance(cameras, Mapping) else list(cameras)
    if len(cameras) < 2:
        raise FuserConfigError(f'the fuser needs at least two cameras, got {len(cameras)}')
    names = [camera.name for camera in cameras]
    if len(set(names)) != len(names):
        raise FuserConfigError(f'camera names must be unique, got {names}')
    return cameras


class GatedEstimator:
    """
    The shared part of every method: counters, the input gate and the plausibility gate.

    :param cameras: the calibrated cameras (checked by :func:`camera_list`)
    :param sync_tolerance_ns: see :class:`~pseudo_stereo_ros.fusion.Fuser` [ns]
    :param max_gap_ns: see :class:`~pseudo_stereo_ros.fusion.Fuser` [ns]
    :param image_margin: see :class:`~pseudo_stereo_ros.fusion.Fuser`
    :param max_speed_mps: see :class:`~pseudo_stereo_ros.fusion.Fuser` [m/s]
    :param workspace_min_m: see :class:`~pseudo_stereo_ros.fusion.Fuser` [m]
    :param workspace_max_m: see :class:`~pseudo_stereo_ros.fusion.Fuser` [m]
    :raises FuserConfigError: an invalid option, naming it
    """

    #: The methods a subclass implements, registered for :func:`estimator_class`.
    methods: tuple[str, ...] = ()
    #: Why an observation gave no estimate: reason (a key of :attr:`stats`) -> what it means.
    #: Each method extends the input gate's reasons with its own.
    drop_reasons: Mapping[str, str] = INPUT_DROP_REASONS

    def __init_subclass__(cls, **kwargs) -> None:
        """Register a method's class under its :attr:`methods`."""
        super().__init_subclass__(**kwargs)
        for method in cls.__dict__.get('methods', ()):
            _CLASSES[method] = cls

    def __init__(self, cameras: Sequence[Camera] | Mapping[str, Camera], *,
                 sync_tolerance_ns: int | None = None, max_gap_ns: int | None = None,
                 image_margin: float | None = None,
                 max_speed_mps: float | None = DEFAULT_MAX_SPEED_MPS,
                 workspace_min_m: Sequence[float] | None = None,
                 workspace_max_m: Sequence[float] | None = None) -> None:
        cameras = camera_list(cameras)
        #: The cameras, in order.
        self.cameras = cameras
        #: Counts: ``observations``, ``estimates`` and one key per drop reason (each method
        #: documents its own); ``observations`` = ``estimates`` + drops + ``gate.held``.
        self.stats: Counter[str] = Counter()
        #: The shared input and timing rules (:class:`~pseudo_stereo_ros.timing.InputGate`).
        self.gate = InputGate(cameras, sync_tolerance_ns=sync_tolerance_ns,
                              max_gap_ns=max_gap_ns, image_margin=image_margin,
                              stats=self.stats)
        #: The plausibility gate of the estimates.
        self.plausibility = PlausibilityGate(max_speed_mps=max_speed_mps,
                                             workspace_min_m=workspace_min_m,
                                             workspace_max_m=workspace_max_m,
                                             window_ns=self.gate.max_gap_ns, stats=self.stats)
        #: The configured tolerance [ns]; :attr:`sync_tolerance_ns` is the one in force.
        self.max_sync_tolerance_ns = self.gate.max_sync_tolerance_ns
        #: The configured upper bound of the max gap [ns].
        self.max_gap_ns = self.gate.max_gap_ns

    def dropped(self) -> dict[str, int]:
        """Return the observations dropped so far, per reason (the reasons that occurred)."""
        return {reason: self.stats[reason] for reason in self.drop_reasons
                if self.stats[reason]}

    def unaccounted(self) -> int:
        """
        Return the observations neither estimated, dropped nor held: 0 (else a bug).

        Every observation gives an estimate, exactly one drop reason, or waits in the gate
        (``gate.held``) until a new session is confirmed or it proves an outlier.
        """
        stats = self.stats
        return stats['observations'] - (stats['estimates'] + sum(self.dropped().values())
                                        + self.gate.held)

    @property
    def camera_names(self) -> list[str]:
        """Return the configured camera names, in order."""
        return [camera.name for camera in self.cameras]

    @property
    def sync_tolerance_ns(self) -> int:
        """Return the sync tolerance in force [ns] (the gate's)."""
        return self.gate.sync_tolerance_ns

    @property
    def session(self) -> int:
        """Return the session number: it increments whenever the gate starts a new session."""
        return self.gate.session

    def off_timeline(self, stamp_ns: int) -> bool:
        """
        Tell whether a stamp jumps away from the current session (see the gate).

        The fuser node asks this before buffering a point: such a point goes to
        ``update`` directly, which holds it until the cameras agree on a new session
        (:attr:`session` changes) or drops it as one camera's ``stamp_outlier``.

        :param stamp_ns: the stamp [ns]
        :return: True when farther than the rig's max gap from the session's newest stamp
        """
        return self.gate.off_timeline(stamp_ns)

    def reset(self) -> None:
        """Forget all history, the measured frame periods included (counters are kept)."""
        self.gate.reset()
        self._forget()

    def _forget(self) -> None:
        """Forget the flight (a new session); a method extends this with its own state."""
        self.plausibility.reset()

    def update(self, observation: Observation) -> Estimate | None:
        """
        Process one observation.

        :param observation: camera name, stamp [ns], raw pixel
        :return: the estimate at this shutter event, or None (the reason is counted in stats,
            or the observation is held by the gate until a new session is confirmed)
        """
        admission = self.gate.admit(observation)
        if admission.new_session:
            self._forget()
        result = None
        for item in admission.ready:
            # Only the last can give an estimate: the others open a session from one camera.
            result = self._fuse(item)
        return result

    def _fuse(self, item: Admitted) -> Estimate | None:
        """Estimate at one admitted observation (the method), or None (counted)."""
        raise NotImplementedError

    def _supersedes(self, estimate: Estimate, previous: Estimate) -> bool:
        """Whether ``estimate``, within the sync tolerance of another camera's, replaces it."""
        return True

    def process(self, observations: Iterable[Observation]) -> list[Estimate]:
        """
        Process recorded observations: the offline code path of ``track``, Table 1 and holdout.

        Observations are sorted by stamp first (ties keep their given order), so
        rows of a file may come in any order.  One estimate per shutter event:
        where two cameras' estimates are within ``sync_tolerance_ns`` of each
        other (synchronized cameras), the later one, which saw both, supersedes
        the first (as the method's :meth:`_supersedes` allows).  At the end, an
        observation still held by the gate (a jump no camera confirmed) is
        dropped as ``stamp_outlier``.

        :param observations: the observations, any order
        :return: the estimates in stamp order
        """
        estimates: list[Estimate] = []
        for observation in sorted(observations, key=stamp_sort_key):
            estimate = self.update(observation)
            if estimate is None:
                continue
            if (estimates and estimate.stamp_ns - estimates[-1].stamp_ns <= self.sync_tolerance_ns
                    and estimates[-1].camera != estimate.camera
                    and self._supersedes(estimate, estimates[-1])):
                estimates[-1] = estimate
            else:
                estimates.append(estimate)
        self.gate.flush()
        return estimates
