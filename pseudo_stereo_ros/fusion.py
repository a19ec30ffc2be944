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
The event-driven fuser: one observation in, at most one 3D estimate out.

``paper`` is Section 2 of Shimizu et al., "A Pseudo Stereo Vision Method for
Unsynchronized Cameras", written over actual stamps so that delta12 and
delta21 come from the data at every event and the roles of the cameras swap
by themselves ("the suffixes are cycled").  At an observation of camera A at
time t, with partner camera B:

1. The two newest earlier frames of either camera (normally B's t'-1 and
   A's t-1) become anchors.  At each anchor frame of camera X the other
   camera Y's point is interpolated linearly in time between the two Y frames
   that bracket it (Step I; for A's t-1 that is B's t'-2 and t'-1, for B's
   t'-1 it is A's t-1 and the newest frame t), moved onto the epipolar line of
   the anchor (Step II) and triangulated with it (Step III).
2. The two anchor points are extrapolated linearly to t (Eq. 3).
3. The estimate is the nearest point on A's newest viewing ray (Eq. 5).

Step I interpolates *undistorted* image points (the paper's cameras have no
distortion; interpolation in raw distorted pixels would bend the motion).
Anchor points are cached on their frames: each event triangulates once.

``naive`` is the paper's "unsynchronized" baseline: the newest point with the
partner's latest point, as if simultaneous.

Every observation first passes the shared input and timing rules of
:class:`~pseudo_stereo_ros.timing.InputGate` (validation, frame periods, max
gaps, sessions; see :mod:`pseudo_stereo_ros.timing`), and every estimate the
physical plausibility gate of :mod:`pseudo_stereo_ros.plausibility`
(``max_speed_mps``, the optional workspace box).  Observations of two cameras
within the gate's sync tolerance (1 ms, never more than a quarter of the
frame period) are simultaneous and are triangulated directly (the paper's
Section 4.4 fallback).  With synchronized cameras the first observation of a
pair gives the method's prediction and the second the direct stereo point at
the same stamp, which supersedes it (:meth:`Fuser.process` keeps only the
latter).  Eq. 3 never extrapolates from two anchors closer than the gate's
baseline floor (at least the tolerance): nearer ones count as one instant
and an older anchor is taken instead, so the extrapolation gain stays
bounded whatever the phase, the tolerance or a double trigger.

Imperfect input: interpolation spans at most the camera's max gap (a few
measured frame periods, ``max_gap_ns`` at most); data older than that is
never used (a silent camera produces no estimates, and a camera or the whole
rig coming back after a pause starts a fresh history).  An observation that
arrives after a later one of another camera (detectors of unequal latency)
is not lost: the partner's frames on both sides of it give Steps I-III at
its own time (kind ``'interpolated'``, counted as ``late``).  Every
observation gives an estimate or exactly one drop reason of
:data:`DROP_REASONS` in :attr:`Fuser.stats`, and an estimate is never NaN or
infinite.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
import math

from .camera import Camera
from .errors import FuserConfigError
from .estimator import estimator_class, GatedEstimator
from .geometry import fundamental_matrix, nearest_point_on_line_one, triangulate_rays_one
from .plausibility import DEFAULT_MAX_SPEED_MPS
from .records import Estimate, Observation, Point3
from .timing import (Admitted, DEFAULT_IMAGE_MARGIN, DEFAULT_MAX_GAP_NS, DEFAULT_SYNC_TOLERANCE_NS,
                     INPUT_DROP_REASONS)

__all__ = [
    'DEFAULT_IMAGE_MARGIN',
    'DEFAULT_MAX_GAP_NS',
    'DEFAULT_MAX_SPEED_MPS',
    'DEFAULT_SYNC_TOLERANCE_NS',
    'DROP_REASONS',
    'Fuser',
    'FuserConfigError',
    'METHOD_ALIASES',
    'METHOD_NAMES',
    'METHODS',
    'fuse',
    'make_fuser',
    'resolve_method',
]

#: Every fusion method: the paper's, naive pairing, and the causal trajectory fit
#: (:mod:`pseudo_stereo_ros.trajectory`).
METHODS = ('paper', 'naive', 'trajectory')
#: Other names a user may give a method: ``best`` is the most accurate method (a
#: configuration asking for ``best`` follows it if another method takes its place).
METHOD_ALIASES = {'best': 'trajectory'}
#: Every name :func:`make_fuser`, the ``fuser`` node and the CLI accept.
METHOD_NAMES = METHODS + tuple(METHOD_ALIASES)
# The methods of :class:`Fuser` itself.
_FUSER_METHODS = ('paper', 'naive')

#: Why an observation gave no estimate (keys of :attr:`Fuser.stats`): the input gate's
#: reasons, then the method's.
DROP_REASONS = {
    **INPUT_DROP_REASONS,
    'no_partner': 'no other camera has an observation within its max gap',
    'warming_up': 'not enough recent history yet for the method',
    'degenerate': 'parallel rays, a point behind a camera, or a non-finite result',
    'implausible': 'the estimate moved faster than max_speed_mps from the previous one, or '
                   'lies outside the workspace box',
}

# Frames kept per camera; the method needs three, the rest absorbs short bursts of one camera.
_HISTORY = 8


class _Frame:
    """One observation with its undistorted point, ray and cached anchor points."""

    __slots__ = ('stamp', 'ideal', 'direction', 'anchors')

    def __init__(self, stamp: int, ideal: tuple, direction: tuple):
        self.stamp = stamp
        self.ideal = ideal
        self.direction = direction
        # partner name -> pseudo-stereo point (or None when it could not be formed)
        self.anchors: dict[str, Point3 | None] = {}


class _View:
    """Per-camera state: the camera, its inverse intrinsics and its recent frames."""

    __slots__ = ('camera', 'name', 'center', 'k', 'frames', 'fundamental')

    def __init__(self, camera: Camera):
        self.camera = camera
        self.name = camera.name
        self.center = camera.center_tuple
        k = camera.K
        self.k = (float(k[0, 0]), float(k[0, 1]), float(k[0, 2]), float(k[1, 1]),
                  float(k[1, 2]))
        self.frames: list[_Frame] = []
        # partner name -> F rows (plain floats) mapping this camera's ideal pixels to lines
        self.fundamental: dict[str, tuple] = {}

    def ideal_to_direction(self, iu: float, iv: float) -> tuple:
        fx, skew, cx, fy, cy = self.k
        y = (iv - cy) / fy
        return self.camera.direction_of((iu - cx - skew * y) / fx, y)


class Fuser(GatedEstimator):
    """
    Event-driven fusion of stamped image points from unsynchronized cameras.

    :param cameras: the calibrated cameras (a sequence, or a mapping name -> camera)
    :param method: ``'paper'`` or ``'naive'``
    :param sync_tolerance_ns: observations of two cameras closer than this are simultaneous
        [ns] (default 1 ms; never more than a quarter of the measured frame period)
    :param max_gap_ns: upper bound of the longest interval bridged by interpolation; older
        data is not used [ns] (default 0.1 s; each camera uses at most 4.5 of its measured
        frame periods)
    :param image_margin: observations farther outside the image than this fraction of its
        width or height are dropped (default 0.1; ``math.inf``: no check)
    :param max_speed_mps: estimates implying a faster motion are dropped [m/s]
        (default 60; None or 0: no speed test)
    :param workspace_min_m: lower corner (x, y, z) of the workspace [m]; estimates outside
        are dropped (default None: unbounded; infinite entries are no bound)
    :param workspace_max_m: upper corner (x, y, z) of the workspace [m]
    :raises FuserConfigError: an invalid option, naming it
    """

    methods = _FUSER_METHODS
    drop_reasons = DROP_REASONS

    def __init__(self, cameras: Sequence[Camera] | Mapping[str, Camera], *,
                 method: str = 'paper', sync_tolerance_ns: int | None = None,
                 max_gap_ns: int | None = None, image_margin: float | None = None,
                 max_speed_mps: float | None = DEFAULT_MAX_SPEED_MPS,
                 workspace_min_m: Sequence[float] | None = None,
                 workspace_max_m: Sequence[float] | None = None):
        if method not in _FUSER_METHODS:
            raise FuserConfigError(f'unknown method {method!r} for Fuser (known: '
                                   f'{", ".join(_FUSER_METHODS)}; make_fuser() builds any of '
                                   f'{", ".join(METHODS)})')
        super().__init__(cameras, sync_tolerance_ns=sync_tolerance_ns, max_gap_ns=max_gap_ns,
                         image_margin=image_margin, max_speed_mps=max_speed_mps,
                         workspace_min_m=workspace_min_m, workspace_max_m=workspace_max_m)
        cameras = self.cameras
        self.method = method
        self._views = {camera.name: _View(camera) for camera in cameras}
        for view in self._views.values():
            for other in self._views.values():
                if other is not view:
                    f = fundamental_matrix(view.camera, other.camera)
                    view.fundamental[other.name] = tuple(tuple(float(x) for x in row)
                                                         for row in f)
        self._update = self._paper if method == 'paper' else self._naive

    def _forget(self) -> None:
        super()._forget()
        for view in self._views.values():
            view.frames.clear()

    def _fuse(self, item: Admitted) -> Estimate | None:
        stats = self.stats
        camera, stamp, _, _ = item.observation
        view = self._views[camera]
        frames = view.frames
        if item.fresh:
            frames.clear()
        x, y = item.x, item.y
        fx, skew, cx, fy, cy = view.k
        frame = _Frame(stamp, (fx * x + skew * y + cx, fy * y + cy),
                       view.camera.direction_of(x, y))
        frames.append(frame)
        if len(frames) > _HISTORY:
            del frames[0]
        late = item.late

        partner = self._partner(view, stamp)
        if partner is None:
            stats['no_partner'] += 1
            return None
        result = None
        if late and self.method == 'paper':
            # The partner has frames on both sides of this one: Steps I-III at the event itself
            # (what the method computes for its anchors) beat a prediction.
            point = self._anchor(frame, view, partner)
            if point is not None:
                stats['late'] += 1
                result = (point, 'interpolated')
        if result is None:
            result = self._update(view, frame, partner)
        if result is None:
            return None
        point, kind = result
        if not (math.isfinite(point[0]) and math.isfinite(point[1]) and math.isfinite(point[2])):
            stats['degenerate'] += 1
            return None
        plausibility = self.plausibility
        plausibility.window_ns = self.gate.rig_gap_ns  # "recent": a few frame periods
        if not plausibility.accept(stamp, point):
            return None
        stats['estimates'] += 1
        return Estimate(stamp, camera, point[0], point[1], point[2], kind)

    def _supersedes(self, estimate: Estimate, previous: Estimate) -> bool:
        """Only the direct stereo point of a synchronized pair replaces the prediction."""
        return estimate.kind == 'sync'

    # -- methods --------------------------------------------------------------------------------

    def _partner(self, view: _View, stamp: int) -> _View | None:
        """Return the other camera that fired most recently within its max gap, if any."""
        best = None
        gaps = self.gate.max_gaps
        for other in self._views.values():
            if other is view or not other.frames:
                continue
            if stamp - other.frames[-1].stamp > gaps[other.name]:
                continue
            if best is None or other.frames[-1].stamp > best.frames[-1].stamp:
                best = other
        return best

    def _direct(self, view: _View, frame: _Frame, partner: _View, other: _Frame):
        point = triangulate_rays_one(view.center, frame.direction, partner.center, other.direction)
        if point is None:
            self.stats['degenerate'] += 1
            return None
        return point

    def _naive(self, view: _View, frame: _Frame, partner: _View):
        point = self._direct(view, frame, partner, partner.frames[-1])
        return None if point is None else (point, 'naive')

    def _paper(self, view: _View, frame: _Frame, partner: _View):
        gate = self.gate
        partner_newest = partner.frames[-1]
        if abs(frame.stamp - partner_newest.stamp) <= gate.sync_tolerance_ns:
            point = self._direct(view, frame, partner, partner_newest)
            return None if point is None else (point, 'sync')
        if frame.stamp < partner_newest.stamp:
            # A late frame with no partner frame before it (the partner's history starts after
            # it, e.g. it resumed): no interpolation exists, and a prediction from later frames
            # is no estimate of this instant.
            self.stats['warming_up'] += 1
            return None

        # Anchors: the two newest earlier frames of either camera at which a pseudo-stereo point
        # exists, more than the baseline floor apart (normally B's t'-1 and A's t-1): Eq. 3
        # never divides by a shorter baseline, whatever the phase or a double trigger.
        floor = gate.baseline_floor_ns
        gaps = gate.max_gaps
        oldest = frame.stamp - max(gaps[view.name], gaps[partner.name])
        own, theirs = view.frames, partner.frames
        i, j = len(own) - 2, len(theirs) - 1
        anchors: list[tuple] = []
        while len(anchors) < 2 and (i >= 0 or j >= 0):
            if j < 0 or (i >= 0 and own[i].stamp > theirs[j].stamp):
                candidate, x_view, y_view = own[i], view, partner
                i -= 1
            else:
                candidate, x_view, y_view = theirs[j], partner, view
                j -= 1
            if candidate.stamp < oldest:
                break
            if anchors and anchors[0][0] - candidate.stamp <= floor:
                continue
            point = self._anchor(candidate, x_view, y_view)
            if point is not None:
                anchors.append((candidate.stamp, point))
        if len(anchors) < 2:
            self.stats['warming_up'] += 1
            return None

        # Eq. 3: linear prediction to the newest shutter time, from actual stamps.
        (t1, p1), (t0, p0) = anchors
        gain = (frame.stamp - t1) / (t1 - t0)
        predicted = (p1[0] + gain * (p1[0] - p0[0]), p1[1] + gain * (p1[1] - p0[1]),
                     p1[2] + gain * (p1[2] - p0[2]))
        # Eq. 5: the nearest point on the newest observation's viewing ray.
        point = nearest_point_on_line_one(predicted, view.center, frame.direction)
        center, direction = view.center, frame.direction
        if ((point[0] - center[0]) * direction[0] + (point[1] - center[1]) * direction[1]
                + (point[2] - center[2]) * direction[2]) <= 0.0:
            self.stats['degenerate'] += 1  # behind the camera
            return None
        return point, 'pseudo'

    def _anchor(self, frame: _Frame, x_view: _View, y_view: _View) -> Point3 | None:
        """Return the Steps I-III point at ``frame`` of camera X with camera Y (cached)."""
        if y_view.name in frame.anchors:
            return frame.anchors[y_view.name]
        frames = y_view.frames
        stamp = frame.stamp
        k = len(frames) - 1
        while k >= 0 and frames[k].stamp > stamp:
            k -= 1
        before = frames[k] if k >= 0 else None
        after = frames[k + 1] if k + 1 < len(frames) else None
        if after is None:
            # No Y frame after this one yet; one may come, so cache nothing. (A Y frame at the
            # same stamp is found as `before` and interpolated with weight 1 once `after` exists.)
            return None
        if before is None:
            # Y's history starts after this frame: only a simultaneous Y frame can serve.
            point = None
            if after.stamp - stamp <= self.gate.sync_tolerance_ns:
                point = triangulate_rays_one(x_view.center, frame.direction, y_view.center,
                                             after.direction)
        else:
            # Step I: linear interpolation over stamps (consecutive frames of a camera are never
            # more than its max gap apart: the gate marks the frame after a longer silence
            # fresh and the camera's older frames are cleared). For X = camera 1 at t-1 this is
            # Eq. 1, (delta12 * u(t'-2) + delta21 * u(t'-1)) / (delta12 + delta21): each sample
            # is weighted by the *other* sample's distance in time.
            w_after = (stamp - before.stamp) / (after.stamp - before.stamp)
            w_before = 1.0 - w_after
            iu = w_before * before.ideal[0] + w_after * after.ideal[0]
            iv = w_before * before.ideal[1] + w_after * after.ideal[1]
            # Step II: the nearest point on the epipolar line of X's point in Y's image.
            f0, f1, f2 = x_view.fundamental[y_view.name]
            pu, pv = frame.ideal
            a = f0[0] * pu + f0[1] * pv + f0[2]
            b = f1[0] * pu + f1[1] * pv + f1[2]
            c = f2[0] * pu + f2[1] * pv + f2[2]
            norm2 = a * a + b * b
            if norm2 > 0.0:
                distance = (a * iu + b * iv + c) / norm2
                iu -= distance * a
                iv -= distance * b
            # Step III: triangulate X's ray with the ray through the corrected point.
            point = triangulate_rays_one(x_view.center, frame.direction, y_view.center,
                                         y_view.ideal_to_direction(iu, iv))
        frame.anchors[y_view.name] = point
        return point


def resolve_method(name: str) -> str:
    """
    Return the method a name stands for (itself, or the method an alias names).

    :param name: a name from :data:`METHOD_NAMES`
    :return: a name from :data:`METHODS`
    :raises FuserConfigError: an unknown name
    """
    method = METHOD_ALIASES.get(name, name)
    if method not in METHODS:
        raise FuserConfigError(f'unknown method {name!r} (known: {", ".join(METHOD_NAMES)})')
    return method


def make_fuser(cameras: Sequence[Camera] | Mapping[str, Camera], *,
               method: str = 'paper', sync_tolerance_ns: int | None = None,
               max_gap_ns: int | None = None, image_margin: float | None = None,
               max_speed_mps: float | None = DEFAULT_MAX_SPEED_MPS,
               workspace_min_m: Sequence[float] | None = None,
               workspace_max_m: Sequence[float] | None = None, **method_options):
    """
    Build the fuser of a method: the one factory of ``track``, holdout, Table 1 and the node.

    :param cameras: the calibrated cameras
    :param method: one of :data:`METHOD_NAMES` (an alias builds the method it names)
    :param sync_tolerance_ns: see :class:`Fuser` [ns]
    :param max_gap_ns: see :class:`Fuser` [ns]
    :param image_margin: see :class:`Fuser` (the shared input rules)
    :param max_speed_mps: see :class:`Fuser` (the shared plausibility gate) [m/s]
    :param workspace_min_m: see :class:`Fuser` [m]
    :param workspace_max_m: see :class:`Fuser` [m]
    :param method_options: options of the method (``trajectory``: those of
        :class:`~pseudo_stereo_ros.trajectory.TrajectoryFuser`)
    :return: a :class:`Fuser` or :class:`~pseudo_stereo_ros.trajectory.TrajectoryFuser`
        (``update``, ``process``, ``reset``, ``stats``)
    :raises FuserConfigError: an unknown method or an invalid option
    """
    method = resolve_method(method)
    if method not in _FUSER_METHODS:
        # Looked up, not imported: the trajectory module imports this one (the paper
        # method stands in for its first frames).
        return estimator_class(method)(
            cameras, sync_tolerance_ns=sync_tolerance_ns, max_gap_ns=max_gap_ns,
            image_margin=image_margin, max_speed_mps=max_speed_mps,
            workspace_min_m=workspace_min_m, workspace_max_m=workspace_max_m, **method_options)
    if method_options:
        raise FuserConfigError(f'method {method!r} takes no option '
                               f'{", ".join(sorted(method_options))}')
    return Fuser(cameras, method=method, sync_tolerance_ns=sync_tolerance_ns,
                 max_gap_ns=max_gap_ns, image_margin=image_margin, max_speed_mps=max_speed_mps,
                 workspace_min_m=workspace_min_m, workspace_max_m=workspace_max_m)


def fuse(cameras: Sequence[Camera] | Mapping[str, Camera],
         observations: Iterable[Observation], **options) -> tuple[list[Estimate], Counter]:
    """
    Run a new fuser over recorded observations (see :meth:`Fuser.process`).

    :param cameras: the calibrated cameras
    :param observations: the observations, any order
    :param options: keyword options of :func:`make_fuser` (``method`` among them)
    :return: ``(estimates, stats)``: the estimates in stamp order and the fuser's counters
    :raises FuserConfigError: an invalid option
    """
    fuser = make_fuser(cameras, **options)
    return fuser.process(observations), fuser.stats
