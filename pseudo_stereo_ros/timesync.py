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
Per-camera time offsets estimated from ball flights.

A camera's offset ``o`` [s] is added to its stamps to put them on the rig's
common shutter clock (``true = stamp + o``; see :mod:`pseudo_stereo_ros.offsets`,
where they are applied).

**Estimation** (``pseudo_stereo sync`` and the fuser node's online estimate).
Only differences of offsets are observable, so each camera's offset is
estimated relative to a reference camera (the first), which keeps its given
offset.  For a pair of cameras A, B and a candidate difference
``d = o_B - o_A``, every detection of A at raw time ``t`` is compared with B's
track at B's raw time ``t - d`` (and every detection of B with A's track at
``t + d``): the signed distance of the interpolated point to the epipolar line
of the detection [ideal px] is the residual.  Tracks are interpolated in
undistorted (ideal) pixels by cubic splines within segments without gaps over
``max_gap``: a straight chord of a curved image track would bias the offset
(about 0.7 ms on the simulated spiral at 30 fps).  A coarse search over
``+-max(frame period, search_s)`` (median residual, robust to the samples
that enter and leave) is followed by a robust least-squares refinement of
``d`` (:func:`scipy.optimize.least_squares`, soft-L1 loss).

**Uncertainty** (1 sigma) is the larger of the least-squares value
(residual scale over the sensitivity ``d residual / d d``, which is the
image velocity across the epipolar lines) and a block jackknife over the
recording (leave out one of 8 stretches of time, refit): the jackknife also
sees model errors that do not average out, such as a calibration error whose
apparent time shift depends on the flight direction.

**Warnings.**  *too short*: fewer than :data:`MIN_SAMPLES` compared
samples.  *unobservable*: an uncertainty above ``max_uncertainty_s``; when
less than :data:`MIN_CROSSING` of the image motion crosses the epipolar
lines, the ball moves along them and a time shift does not move the
residual.  *varies*: the jackknife spread exceeds :data:`VARIES_RATIO` times
the noise value (on correct simulated data it stays within 2): the apparent
offset changes across the recording, from a drifting clock or, more often, a
calibration error that mimics a time shift differently for different
flights.  The jackknife then widens the uncertainty, but a bias shared by all
flights (throws all in one direction) it cannot see: on the real table-tennis
rig a calibration error of camera_2 passes for an 8 ms offset with a 1 sigma
of 0.65 ms.  *confounded*: with three or more cameras every pair gives a
difference; they must close (``d12 + d23 = d13``).  When they do not
(chi-square test), a calibration error mimics a time shift in some pair and
no pair alone can tell them apart: ``pseudo_stereo refine`` estimates
calibration and offsets jointly.

ROS-free (numpy, scipy).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
import math
import threading
from typing import Deque, Dict, List, Mapping, NamedTuple, Optional, Sequence, Tuple

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.optimize import least_squares
from scipy.special import chdtrc

from .camera import Camera
from .errors import UsageError
from .geometry import fundamental_matrix
from .offsets import camera_time_offsets
from .records import Observation
from .stamps import NS_PER_S, seconds_to_ns

__all__ = [
    'DEFAULT_MAX_GAP_S',
    'DEFAULT_MAX_UNCERTAINTY_S',
    'MIN_CROSSING',
    'MIN_SAMPLES',
    'VARIES_RATIO',
    'OffsetEstimate',
    'OffsetJob',
    'OnlineOffsetEstimator',
    'PairOffset',
    'estimate_time_offsets',
    'run_offset_job',
]

#: Fewest compared samples of a pair for an estimate (fewer: "too short").
MIN_SAMPLES = 30
#: Below this fraction of image motion across the epipolar lines the ball moves along them.
MIN_CROSSING = 0.2
#: Default 1-sigma above which an offset counts as unobservable [s].
DEFAULT_MAX_UNCERTAINTY_S = 0.001
#: Default longest gap inside one interpolated segment of a track [s].
DEFAULT_MAX_GAP_S = 0.1
#: Jackknife spread over the noise value above which the offset "varies" (correct simulated
#: data: up to 2; a camera rotated by 0.3 to 1 degree: 6 to 8; the real rig: 5 to 12).
VARIES_RATIO = 4.0
#: Blocks of the jackknife.
_JACKKNIFE_BLOCKS = 8
#: Fewest detections of a segment for a cubic spline.
_MIN_SEGMENT = 4
#: Smallest residual scale for the robust loss [px] (noise-free data has ~0).
_MIN_SCALE_PX = 1e-3
#: A detection this many robust scales off the cubic through its neighbours is a stray.
_STRAY_SCALES = 5.0
#: Half width of the online search once every camera has a usable estimate [s].
_ONLINE_HALF_WIDTH_S = 0.002
#: p-value below which pairwise differences that do not close are "confounded".
_CLOSURE_P = 0.001


# -- tracks -------------------------------------------------------------------------------------

class _Track:
    """
    One camera's detections of one recording as cubic splines of its raw clock.

    ``times`` (N,) are seconds from the recording's epoch, ``ideal`` (N, 2)
    the undistorted pixels; segments split where detections are more than
    ``max_gap_s`` apart.  The splines' pieces are kept in flat arrays so that
    evaluation is vectorized over segments; a query assigned to a segment but
    just outside it is extrapolated with the segment's end piece.
    """

    def __init__(self, times: np.ndarray, ideal: np.ndarray, max_gap_s: float):
        self.times = times
        self.ideal = ideal
        cuts = np.nonzero(np.diff(times) > max_gap_s)[0] + 1
        starts, ends, steps, knots, coefficients, first, last = [], [], [], [], [], [], []
        pieces = 0
        for chunk in np.split(np.arange(len(times)), cuts):
            if len(chunk) < _MIN_SEGMENT:
                continue
            spline = CubicSpline(times[chunk], ideal[chunk])
            starts.append(times[chunk[0]])
            ends.append(times[chunk[-1]])
            steps.append(np.diff(times[chunk]))
            knots.append(spline.x[:-1])
            coefficients.append(spline.c)
            first.append(pieces)
            pieces += len(chunk) - 1
            last.append(pieces - 1)
        self.starts = np.array(starts)
        self.ends = np.array(ends)
        self._knots = np.concatenate(knots) if knots else np.zeros(0)
        self._coefficients = (np.concatenate(coefficients, axis=1) if coefficients
                              else np.zeros((4, 0, 2)))
        self._first = np.array(first, dtype=int)
        self._last = np.array(last, dtype=int)
        #: Median interval between detections inside segments [s] (NaN without segments).
        self.period = float(np.median(np.concatenate(steps))) if steps else math.nan

    @property
    def segments(self) -> int:
        """Return the number of interpolated segments."""
        return len(self.starts)

    def locate(self, query: np.ndarray) -> np.ndarray:
        """Return the segment index of each query time, -1 outside every segment."""
        if not len(self.starts):
            return np.full(len(query), -1)
        index = np.searchsorted(self.starts, query, side='right') - 1
        inside = (index >= 0) & (query <= self.ends[np.maximum(index, 0)])
        return np.where(inside, index, -1)

    def evaluate(self, query: np.ndarray, index: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """Return points (M, 2) and velocities (M, 2) [px/s] at query times of given segments."""
        piece = np.searchsorted(self._knots, query, side='right') - 1
        piece = np.clip(piece, self._first[index], self._last[index])
        dt = (query - self._knots[piece])[:, None]
        c0, c1, c2, c3 = (self._coefficients[k, piece] for k in range(4))
        points = ((c0 * dt + c1) * dt + c2) * dt + c3
        velocities = (3.0 * c0 * dt + 2.0 * c1) * dt + c2
        return points, velocities


def _ideal_track(camera: Camera, rows: Sequence[Tuple[int, float, float]], epoch_ns: int,
                 max_gap_s: float) -> Optional[_Track]:
    """Build a track from ``(stamp_ns, u, v)`` rows (any order; duplicates dropped)."""
    rows = sorted({row[0]: row for row in rows
                   if math.isfinite(row[1]) and math.isfinite(row[2])}.values())
    if len(rows) < _MIN_SEGMENT:
        return None
    stamps = np.array([row[0] for row in rows], dtype=np.int64)
    ideal = camera.ideal_pixels(np.array([row[1:] for row in rows], dtype=float))
    keep = np.all(np.isfinite(ideal), axis=1)
    times = (stamps[keep] - np.int64(epoch_ns)).astype(float) / NS_PER_S
    ideal = ideal[keep]
    keep = _without_strays(times, ideal, max_gap_s)
    track = _Track(times[keep], ideal[keep], max_gap_s)
    return track if track.segments else None


def _without_strays(times: np.ndarray, ideal: np.ndarray, max_gap_s: float) -> np.ndarray:
    """
    Return a mask without stray detections: a spline through one would bend its neighbours.

    Each detection is compared with the cubic through its two neighbours on
    either side (leave one out); one that deviates by more than
    :data:`_STRAY_SCALES` robust scales (and 0.5 px) and more than its
    neighbours do is dropped, a few rounds (a stray also moves its
    neighbours' predictions).  A bounce may lose its kink detection: harmless.
    """
    keep = np.ones(len(times), dtype=bool)
    for _ in range(3):
        index = np.nonzero(keep)[0]
        if len(index) < 5:
            break
        t, p = times[index], ideal[index]
        centre = np.arange(2, len(index) - 2)
        neighbours = centre[:, None] + np.array([-2, -1, 1, 2])[None, :]
        span = t[neighbours[:, -1]] - t[neighbours[:, 0]]
        inside = span <= 2 * max_gap_s
        weights = _lagrange_weights(t[centre], t[neighbours])
        predicted = np.einsum('mk,mkj->mj', weights, p[neighbours])
        deviation = np.full(len(index), 0.0)
        deviation[centre] = np.where(inside, np.hypot(*(predicted - p[centre]).T), 0.0)
        scale = 1.4826 * float(np.median(deviation[centre][inside])) if inside.any() else 0.0
        threshold = max(_STRAY_SCALES * scale, 0.5)
        peak = np.zeros(len(index), dtype=bool)
        peak[centre] = ((deviation[centre] > threshold)
                        & (deviation[centre] >= deviation[centre - 1])
                        & (deviation[centre] >= deviation[centre + 1]))
        if not peak.any():
            break
        keep[index[peak]] = False
    return keep


def _lagrange_weights(s: np.ndarray, knots: np.ndarray) -> np.ndarray:
    """Return (M, k) Lagrange weights at times (M,) for knot times (M, k)."""
    weights = np.ones_like(knots)
    for m in range(knots.shape[1]):
        for n in range(knots.shape[1]):
            if n != m:
                weights[:, m] *= (s - knots[:, n]) / (knots[:, m] - knots[:, n])
    return weights


@dataclass
class _Direction:
    """Detections of camera X compared with camera Y's track (one recording, one direction)."""

    times: np.ndarray      # (M,) X's detection times [s]
    lines: np.ndarray      # (M, 3) X's epipolar lines in Y's ideal image, a^2 + b^2 = 1
    track: _Track          # Y's track
    sign: float            # Y's query time is times - sign * d


class _PairProblem:
    """The residuals of a camera pair as a function of ``d = o_B - o_A`` over recordings."""

    def __init__(self, camera_a: Camera, camera_b: Camera,
                 tracks: Sequence[Tuple[Optional[_Track], Optional[_Track]]]):
        f_ab = fundamental_matrix(camera_a, camera_b)
        self.directions: List[_Direction] = []
        periods = []
        for track_a, track_b in tracks:
            if track_a is None or track_b is None:
                continue
            periods += [track_a.period, track_b.period]
            for x_track, y_track, f, sign in ((track_a, track_b, f_ab, 1.0),
                                              (track_b, track_a, f_ab.T, -1.0)):
                homogeneous = np.hstack((x_track.ideal, np.ones((len(x_track.ideal), 1))))
                lines = homogeneous @ f.T
                lines /= np.hypot(lines[:, 0], lines[:, 1])[:, None]
                self.directions.append(_Direction(x_track.times, lines, y_track, sign))
        #: The longer median frame period of the two cameras [s] (NaN without data).
        self.period = float(np.nanmax(periods)) if periods else math.nan

    def assign(self, d: float) -> List[np.ndarray]:
        """Return, per direction, the segment of each sample at ``d`` (-1: not compared)."""
        return [item.track.locate(item.times - item.sign * d) for item in self.directions]

    def evaluate(self, d: float, assignment: List[np.ndarray]) -> Tuple[np.ndarray, ...]:
        """
        Return residuals [px], sensitivities d r / d d [px/s], image speeds [px/s], times [s].

        Only samples with a segment in ``assignment`` enter (splines extrapolate
        a little when ``d`` moved since the assignment).
        """
        residuals, slopes, speeds, times = [], [], [], []
        for item, index in zip(self.directions, assignment):
            used = index >= 0
            query = item.times[used] - item.sign * d
            points, velocities = item.track.evaluate(query, index[used])
            lines = item.lines[used]
            residuals.append(np.einsum('ij,ij->i', points, lines[:, :2]) + lines[:, 2])
            slopes.append(-item.sign * np.einsum('ij,ij->i', velocities, lines[:, :2]))
            speeds.append(np.hypot(velocities[:, 0], velocities[:, 1]))
            times.append(item.times[used])
        if not residuals:
            return (np.zeros(0),) * 4
        return tuple(np.concatenate(parts) for parts in (residuals, slopes, speeds, times))


# -- one pair -----------------------------------------------------------------------------------

@dataclass(frozen=True)
class PairOffset:
    """
    The estimated difference of two cameras' offsets, ``offset_s = o_b - o_a``.

    ``uncertainty_s`` is 1 sigma (the larger of ``noise_s``, from the
    residual scale, and ``spread_s``, the block jackknife); ``samples`` the
    compared detections; ``median_before_px`` / ``median_after_px`` the median
    absolute epipolar residual at the given and the estimated difference;
    ``crossing`` the fraction of image motion across the epipolar lines (0:
    along them, unobservable); ``warnings`` why the estimate cannot be used
    (empty when it can).
    """

    camera_a: str
    camera_b: str
    offset_s: float
    uncertainty_s: float
    samples: int
    median_before_px: float
    median_after_px: float
    crossing: float
    noise_s: float
    spread_s: float
    warnings: Tuple[str, ...] = ()


def _robust_scale(residuals: np.ndarray) -> float:
    return max(1.4826 * float(np.median(np.abs(residuals - np.median(residuals)))),
               _MIN_SCALE_PX)


def _median_at(problem: _PairProblem, d: float, minimum: int) -> Tuple[float, int]:
    residuals = problem.evaluate(d, problem.assign(d))[0]
    if len(residuals) < minimum:
        return math.nan, len(residuals)
    return float(np.median(np.abs(residuals))), len(residuals)


def _fit(problem: _PairProblem, d0: float, assignment: List[np.ndarray], scale: float,
         keep: Optional[np.ndarray] = None) -> float:
    """Robust least squares of d from d0 with a fixed sample assignment (optionally a subset)."""
    def fun(x: np.ndarray) -> np.ndarray:
        r = problem.evaluate(x[0], assignment)[0]
        return r if keep is None else r[keep]

    def jac(x: np.ndarray) -> np.ndarray:
        j = problem.evaluate(x[0], assignment)[1]
        return (j if keep is None else j[keep])[:, None]

    result = least_squares(fun, [d0], jac=jac, loss='soft_l1', f_scale=scale, method='trf',
                           x_scale=[1e-3], xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=50)
    return float(result.x[0])


def estimate_pair_offset(camera_a: Camera, camera_b: Camera,
                         tracks: Sequence[Tuple[Optional[_Track], Optional[_Track]]], *,
                         center_s: float = 0.0, search_s: float = 0.0,
                         max_uncertainty_s: float = DEFAULT_MAX_UNCERTAINTY_S,
                         jackknife: bool = True,
                         half_width_s: Optional[float] = None) -> Optional[PairOffset]:
    """
    Estimate ``o_b - o_a`` for one pair from its tracks (see the module rules).

    :param camera_a: the first camera
    :param camera_b: the second camera
    :param tracks: per recording, (A's track, B's track); either may be None
    :param center_s: the given difference [s] (the search is centred on it)
    :param search_s: search at least this far either side [s] (default: one frame period)
    :param max_uncertainty_s: a larger 1 sigma is "unobservable" [s]
    :param jackknife: include the block jackknife in the uncertainty
    :param half_width_s: search exactly this far either side (default: the larger of one
        frame period and ``search_s``)
    :return: the estimate, or None when the pair has no detections in common
    """
    problem = _PairProblem(camera_a, camera_b, tracks)
    if not problem.directions or not math.isfinite(problem.period):
        return None
    half = max(problem.period, float(search_s)) if half_width_s is None else half_width_s
    step = min(problem.period / 12.0, half / 2.0)
    grid = center_s + np.arange(-half, half + 0.5 * step, step)
    at_grid = [_median_at(problem, float(d), 1) for d in grid]
    counts = np.array([count for _, count in at_grid])
    if counts.max(initial=0) < 2:
        return None
    medians = np.where(counts >= 0.5 * counts.max(),
                       np.array([median for median, _ in at_grid]), np.inf)
    d = float(grid[int(np.argmin(medians))])
    for _ in range(5):  # refit when d left the neighbourhood its assignment was made for
        assignment = problem.assign(d)
        residuals = problem.evaluate(d, assignment)[0]
        if len(residuals) < 2:
            break
        scale = _robust_scale(residuals)
        fitted = _fit(problem, d, assignment, scale)
        moved = abs(fitted - d)
        d = fitted
        if moved < step:
            break
    assignment = problem.assign(d)
    residuals, slopes, speeds, times = problem.evaluate(d, assignment)
    samples = len(residuals)
    warnings = []
    if samples < 2:
        return None
    scale = _robust_scale(residuals)
    inliers = np.abs(residuals - np.median(residuals)) <= 3.0 * scale
    information = float(np.sum(slopes[inliers] ** 2))
    noise = scale / math.sqrt(information) if information > 0 else math.inf
    spread = 0.0
    blocks = min(_JACKKNIFE_BLOCKS, samples // 25)
    if jackknife and blocks >= 4 and math.isfinite(noise):
        order = np.argsort(times, kind='stable')
        labels = np.empty(samples, dtype=int)
        labels[order] = np.arange(samples) * blocks // samples
        estimates = np.array([_fit(problem, d, assignment, scale, keep=labels != k)
                              for k in range(blocks)])
        spread = math.sqrt((blocks - 1) / blocks
                           * float(np.sum((estimates - estimates.mean()) ** 2)))
    uncertainty = max(noise, spread)
    crossing = math.sqrt(float(np.sum(slopes ** 2)) / max(float(np.sum(speeds ** 2)), 1e-300))
    if samples < MIN_SAMPLES:
        warnings.append(f'too short: {samples} compared detections (need {MIN_SAMPLES})')
    if not uncertainty <= max_uncertainty_s:
        reason = (f'the ball moves along the epipolar lines (only {crossing:.0%} of its image '
                  'motion crosses them)' if crossing < MIN_CROSSING
                  else 'too little motion across the epipolar lines for the noise')
        warnings.append(f'unobservable: 1 sigma {_ms(uncertainty)} > {_ms(max_uncertainty_s)}:'
                        f' {reason}')
    if spread > VARIES_RATIO * noise and spread > 1e-4:
        warnings.append(f'varies: the apparent offset changes across the recording (spread '
                        f'{_ms(spread)}, noise alone {_ms(noise)}): a drifting clock, or a '
                        'calibration error that mimics a time shift')
    before, _ = _median_at(problem, center_s, MIN_SAMPLES)
    return PairOffset(camera_a.name, camera_b.name, d, uncertainty, samples, before,
                      float(np.median(np.abs(residuals))), crossing, noise, spread,
                      tuple(warnings))


def _ms(seconds: float) -> str:
    return f'{seconds * 1e3:.3g} ms' if math.isfinite(seconds) else 'inf'


# -- all cameras --------------------------------------------------------------------------------

@dataclass(frozen=True)
class OffsetEstimate:
    """
    Every camera's estimated offset [s] on the reference camera's clock.

    ``offsets_s`` and ``uncertainty_s`` (1 sigma; 0 for the reference, inf
    without data) map camera names in rig order; ``pairs`` holds every pair's
    difference; ``warnings`` camera -> reasons the offset cannot be used
    (empty lists when it can);
    ``median_before_px`` / ``median_after_px`` the epipolar residual of the
    pair (reference, camera) at the given and the estimated offsets;
    ``closure_p`` the chi-square p-value of the pairwise differences (NaN with
    fewer than three cameras).
    """

    reference: str
    offsets_s: Dict[str, float]
    uncertainty_s: Dict[str, float]
    pairs: List[PairOffset]
    warnings: Dict[str, List[str]]
    median_before_px: Dict[str, float]
    median_after_px: Dict[str, float]
    samples: Dict[str, int]
    closure_p: float = math.nan
    given_s: Dict[str, float] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        """Return True when no camera has a warning."""
        return not any(self.warnings.values())


def _recording_tracks(cameras: Sequence[Camera], observations: Sequence[Observation],
                      max_gap_s: float) -> Dict[str, Optional[_Track]]:
    rows: Dict[str, List[Tuple[int, float, float]]] = {camera.name: [] for camera in cameras}
    for obs in observations:
        if obs.camera in rows:
            rows[obs.camera].append((int(obs.stamp_ns), float(obs.u), float(obs.v)))
    stamps = [row[0] for values in rows.values() for row in values]
    epoch = min(stamps) if stamps else 0
    return {camera.name: _ideal_track(camera, rows[camera.name], epoch, max_gap_s)
            for camera in cameras}


def estimate_time_offsets(cameras: Mapping[str, Camera] | Sequence[Camera],
                          recordings: Sequence[Sequence[Observation]], *,
                          offsets_s: Optional[Mapping[str, float]] = None,
                          search_s: float = 0.0, max_gap_s: float = DEFAULT_MAX_GAP_S,
                          max_uncertainty_s: float = DEFAULT_MAX_UNCERTAINTY_S,
                          all_pairs: bool = True, jackknife: bool = True,
                          half_width_s: Optional[float] = None) -> OffsetEstimate:
    """
    Estimate every camera's time offset relative to the first from recorded flights.

    :param cameras: the cameras in order (a Rig or a sequence); the first is the reference
    :param recordings: one or more recordings (a bag, a CSV): observations with *raw* stamps
    :param offsets_s: the given offsets [s] (default: the calibrations'); the reference keeps
        its own, the search is centred on the others' and "before" is measured there
    :param search_s: search at least this far either side of the given offsets [s]
    :param max_gap_s: longest gap inside one interpolated track segment [s]
    :param max_uncertainty_s: a larger 1 sigma is reported as unobservable [s]
    :param all_pairs: use every pair (closure check with 3+ cameras), not only the reference's
    :param jackknife: include the block jackknife in the uncertainties (slower)
    :param half_width_s: search exactly this far either side of the given offsets [s]
        (default: the larger of one frame period and ``search_s``)
    :return: the estimate
    """
    cameras = list(cameras.values()) if isinstance(cameras, Mapping) else list(cameras)
    names = [camera.name for camera in cameras]
    given = camera_time_offsets(cameras, offsets_s)
    tracks = [_recording_tracks(cameras, list(obs), max_gap_s) for obs in recordings]
    pair_indices = ([(i, j) for i in range(len(cameras)) for j in range(i + 1, len(cameras))]
                    if all_pairs else [(0, j) for j in range(1, len(cameras))])
    pairs = []
    for i, j in pair_indices:
        a, b = cameras[i], cameras[j]
        result = estimate_pair_offset(
            a, b, [(t[a.name], t[b.name]) for t in tracks],
            center_s=given[b.name] - given[a.name], search_s=search_s,
            max_uncertainty_s=max_uncertainty_s, jackknife=jackknife,
            half_width_s=half_width_s)
        if result is not None:
            pairs.append(result)
    offsets, sigmas, closure_p = _combine(names, given, pairs)
    warnings: Dict[str, List[str]] = {name: [] for name in names}
    samples = dict.fromkeys(names, 0)
    by_pair = {(p.camera_a, p.camera_b): p for p in pairs}
    before, after = {}, {}
    for k, name in enumerate(names[1:], start=1):
        mine = [p for p in pairs if name in (p.camera_a, p.camera_b)]
        samples[name] = sum(p.samples for p in mine)
        with_reference = by_pair.get((names[0], name))
        before[name] = with_reference.median_before_px if with_reference else math.nan
        after[name] = math.nan
        if with_reference is not None:
            # At the combined offsets (with 3+ cameras not the pair's own optimum).
            problem = _PairProblem(cameras[0], cameras[k],
                                   [(t[names[0]], t[name]) for t in tracks])
            after[name] = _median_at(problem, offsets[name] - offsets[names[0]], 1)[0]
        if not mine:
            warnings[name].append('no data: no detections in common with another camera')
            continue
        if samples[name] < MIN_SAMPLES:
            warnings[name].append(f'too short: {samples[name]} compared detections '
                                  f'(need {MIN_SAMPLES})')
        if not sigmas[name] <= max_uncertainty_s:
            reasons = [w for p in mine for w in p.warnings if w.startswith('unobservable')]
            warnings[name].append(reasons[0] if reasons else
                                  f'unobservable: 1 sigma {_ms(sigmas[name])} > '
                                  f'{_ms(max_uncertainty_s)}')
        warnings[name] += [f'{p.camera_a}->{p.camera_b}: {w}' for p in mine
                           for w in p.warnings if w.startswith('varies')]
    if closure_p < _CLOSURE_P:
        detail = ', '.join(f'{p.camera_a}->{p.camera_b} {p.offset_s * 1e3:+.2f} '
                           f'+- {p.uncertainty_s * 1e3:.2f} ms' for p in pairs)
        for name in names[1:]:
            warnings[name].append(
                f'confounded: the pairwise offsets do not add up ({detail}; p = '
                f'{closure_p:.2g}): a calibration error mimics a time shift in some pair; '
                'estimate calibration and offsets together (pseudo_stereo refine)')
    return OffsetEstimate(names[0], offsets, sigmas, pairs, warnings, before, after, samples,
                          closure_p, dict(given))


def _combine(names: List[str], given: Mapping[str, float],
             pairs: Sequence[PairOffset]) -> Tuple[Dict[str, float], Dict[str, float], float]:
    """Weighted least squares of the offsets from pairwise differences (reference fixed)."""
    index = {name: k - 1 for k, name in enumerate(names)}
    usable = [p for p in pairs if math.isfinite(p.uncertainty_s) and p.uncertainty_s > 0
              and p.samples >= 2]
    offsets = {name: float(given[name]) for name in names}
    sigmas = {name: (0.0 if k == 0 else math.inf) for k, name in enumerate(names)}
    unknowns = len(names) - 1
    if not usable or not unknowns:
        return offsets, sigmas, math.nan
    design = np.zeros((len(usable), unknowns))
    target = np.zeros(len(usable))
    weights = np.zeros(len(usable))
    for row, pair in enumerate(usable):
        # d_ab = o_b - o_a, with o_ref = given[ref] known.
        target[row] = pair.offset_s
        for name, sign in ((pair.camera_b, 1.0), (pair.camera_a, -1.0)):
            if index[name] < 0:
                target[row] -= sign * given[name]
            else:
                design[row, index[name]] = sign
        weights[row] = 1.0 / pair.uncertainty_s ** 2
    determined = np.nonzero(np.any(design != 0, axis=0))[0]
    weighted = design[:, determined] * np.sqrt(weights)[:, None]
    normal = weighted.T @ weighted
    if np.linalg.matrix_rank(normal) < len(determined):
        return offsets, sigmas, math.nan
    covariance = np.linalg.inv(normal)
    solution = covariance @ (weighted.T @ (target * np.sqrt(weights)))
    misfit = design[:, determined] @ solution - target
    chi_square = float(np.sum(weights * misfit ** 2))
    dof = len(usable) - len(determined)
    closure_p = float(chdtrc(dof, chi_square)) if dof > 0 else math.nan
    if dof > 0 and chi_square > dof:  # Birge ratio: inconsistent pairs widen the uncertainty
        covariance = covariance * chi_square / dof
    for column, k in enumerate(determined):
        name = names[k + 1]
        offsets[name] = float(solution[column])
        sigmas[name] = float(math.sqrt(covariance[column, column]))
    return offsets, sigmas, closure_p


# -- online -------------------------------------------------------------------------------------

class OffsetJob(NamedTuple):
    """
    One online estimate's input, cheap to pickle (it may run in another process).

    ``stamps`` and ``pixels`` hold each camera's window: (N,) int64 raw stamps [ns] and
    (N, 2) raw pixels [px].
    """

    cameras: List[Camera]
    stamps: Dict[str, np.ndarray]
    pixels: Dict[str, np.ndarray]
    offsets_s: Dict[str, float]
    max_gap_s: float
    max_uncertainty_s: float
    half_width_s: Optional[float]


def run_offset_job(job: OffsetJob) -> OffsetEstimate:
    """
    Run one online estimate (reference pairs only, no jackknife: bounded work).

    :param job: from :meth:`OnlineOffsetEstimator.snapshot`
    :return: the estimate
    """
    observations = [Observation(name, stamp, u, v) for name, stamps in job.stamps.items()
                    for stamp, (u, v) in zip(stamps.tolist(), job.pixels[name].tolist())]
    return estimate_time_offsets(
        job.cameras, [observations], offsets_s=job.offsets_s, max_gap_s=job.max_gap_s,
        max_uncertainty_s=job.max_uncertainty_s, all_pairs=False, jackknife=False,
        half_width_s=job.half_width_s)


class OnlineOffsetEstimator:
    """
    The sliding-window estimate of the fuser node: feed raw observations, ask for offsets.

    Keeps the last ``window_s`` seconds of detections (at most ``max_samples``
    per camera) and runs :func:`estimate_time_offsets` on them (pairs with the
    reference camera only, to bound the work per update).  Each update
    searches around the previous estimate, so a slowly drifting offset is
    followed.  :meth:`add` and :meth:`update` may run in different threads;
    :meth:`update` is :meth:`snapshot`, :func:`run_offset_job` and
    :meth:`accept`, so the work can also run in another process (the fuser
    node does: a thread would hold Python's global lock for tens of
    milliseconds per update and stall fusion).

    :param cameras: the cameras in order; the first is the reference
    :param offsets_s: the configured offsets [s] (the reference keeps its own)
    :param window_s: length of the sliding window [s]
    :param max_samples: most detections kept per camera
    :param max_uncertainty_s: a larger 1 sigma is not :attr:`usable`
    """

    def __init__(self, cameras: Sequence[Camera], offsets_s: Mapping[str, float], *,
                 window_s: float = 10.0, max_samples: int = 1000,
                 max_uncertainty_s: float = DEFAULT_MAX_UNCERTAINTY_S,
                 max_gap_s: float = DEFAULT_MAX_GAP_S):
        if not (window_s > 0 and math.isfinite(window_s)):
            raise UsageError(f'window_s must be a positive number of seconds, got {window_s}')
        self.cameras = list(cameras)
        self.window_ns = seconds_to_ns(window_s)
        self.max_uncertainty_s = float(max_uncertainty_s)
        self.max_gap_s = float(max_gap_s)
        self._given = camera_time_offsets(self.cameras, offsets_s)
        self._samples: Dict[str, Deque[Tuple[int, float, float]]] = {
            camera.name: deque(maxlen=int(max_samples)) for camera in self.cameras}
        self._center = dict(self._given)
        self._settled = False
        self._lock = threading.Lock()
        #: Observations stored since the last update.
        self.added = 0
        #: The newest :class:`OffsetEstimate` (None before the first update with data).
        self.latest: Optional[OffsetEstimate] = None

    def add(self, observation: Observation) -> None:
        """
        Store one raw observation.

        Unknown cameras, non-finite pixels and a camera's duplicate or
        out-of-order stamps are ignored; stamps that jump back by more than the
        window (a replay looping, a restarted clock) start the window afresh.
        """
        samples = self._samples.get(observation.camera)
        if samples is None or not (math.isfinite(observation.u) and math.isfinite(observation.v)):
            return
        with self._lock:
            newest = max((s[-1][0] for s in self._samples.values() if s), default=None)
            if newest is not None and newest - observation.stamp_ns > self.window_ns:
                for old in self._samples.values():  # the clock jumped back (a replay looping)
                    old.clear()
            elif samples and observation.stamp_ns <= samples[-1][0]:
                return  # a duplicate or out-of-order point of this camera
            samples.append((int(observation.stamp_ns), float(observation.u),
                            float(observation.v)))
            self.added += 1

    def _prune(self) -> None:
        newest = max((s[-1][0] for s in self._samples.values() if s), default=None)
        if newest is None:
            return
        for samples in self._samples.values():
            while samples and newest - samples[0][0] > self.window_ns:
                samples.popleft()

    def update(self) -> Optional[OffsetEstimate]:
        """Estimate from the window; return it (also in :attr:`latest`), or None without data."""
        job = self.snapshot()
        if job is None:
            return None
        return self.accept(run_offset_job(job))

    def snapshot(self) -> Optional['OffsetJob']:
        """
        Take the window for an estimate that may run elsewhere (another process).

        :return: the job for :func:`run_offset_job` (pass its result to :meth:`accept`), or
            None without data
        """
        with self._lock:
            self._prune()
            rows = {name: list(samples) for name, samples in self._samples.items()}
            self.added = 0
        if not any(rows.values()):
            return None
        stamps = {name: np.array([row[0] for row in values], dtype=np.int64).reshape(-1)
                  for name, values in rows.items()}
        pixels = {name: np.array([row[1:] for row in values], dtype=float).reshape(-1, 2)
                  for name, values in rows.items()}
        # Once every camera has a usable estimate, search only near it (a drift is followed,
        # a jump of more than the half width is not: it needs a restart).  The jackknife is left
        # out to bound the work per update; the uncertainty is the noise value alone.
        narrow = self._settled and _ONLINE_HALF_WIDTH_S or None
        return OffsetJob(self.cameras, stamps, pixels, dict(self._center), self.max_gap_s,
                         self.max_uncertainty_s, narrow)

    def accept(self, estimate: OffsetEstimate) -> OffsetEstimate:
        """
        Make an estimate of a :meth:`snapshot` the latest; the next search centres on it.

        :param estimate: the result of :func:`run_offset_job`
        :return: the estimate
        """
        self.latest = estimate
        for name in self._center:
            if name != estimate.reference and self.usable(name):
                self._center[name] = estimate.offsets_s[name]
        self._settled = all(self.usable(camera.name) for camera in self.cameras[1:])
        return estimate

    def usable(self, name: str) -> bool:
        """Return True when the latest estimate of a camera may be applied."""
        estimate = self.latest
        return (estimate is not None and name != estimate.reference
                and not estimate.warnings.get(name)
                and estimate.uncertainty_s.get(name, math.inf) <= self.max_uncertainty_s)
