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
Refine a rig's extrinsics (optionally focal lengths) and time offsets from ball flights.

Bundle adjustment over recorded flights, robust (soft-L1) least squares with
:func:`scipy.optimize.least_squares`:

- **Unknowns.** The ball position [m] at every detection of the reference
  (first) camera, on the common clock ``stamp + o_ref``; each camera's
  rotation (a rotation vector applied to the given R) and optical centre
  [m]; with ``focal`` a relative change of its focal lengths (fx and fy
  together, so the aspect ratio stays); with ``estimate_offsets`` its time
  offset [s].  The reference camera's offset is the time gauge and stays,
  and so does its focal length: two cameras whose optical axes meet (a rig
  aimed at one volume) cannot tell both focal lengths from the epipolar
  geometry (the Bougnoux / Newsam degeneracy; freed, the default rig's came
  out with 1-sigma ~10, i.e. 1000%), while one focal length relative to a
  known one is determined.
- **Residuals.** Reprojection errors [raw px, with the lens distortion] of
  every detection: the reference camera's against its own ball positions,
  every other camera's against the ball interpolated to its common-clock
  time ``stamp + o`` by a cubic Lagrange polynomial through the four
  nearest reference detections of the same flight (a linear chord of a
  curved flight would bias offsets and poses).  A flight is a run of
  reference detections without a gap over ``max_gap_s``.  Loose smoothness
  rows (the third difference of four consecutive positions) remove the
  null modes of the interpolated positions; outliers (a cubic across a
  bounce) are left out round by round.
- **Solver.** Variable projection (:class:`_Solver`): least_squares over the
  camera parameters, the ball positions solved inside for each camera state
  by banded Gauss-Newton steps, the reduced Jacobian from the implicit
  function theorem (analytic throughout).
- **Gauge.** By default the reference camera's pose is fixed and the scale
  by the baseline between the first two cameras (the given one, or
  ``baseline_m``): the second camera's centre moves on a sphere about the
  first.  ``keep_world`` instead frees every pose and holds each near its
  given value by a prior (``prior_deg``, ``prior_m``, one sigma; quadratic,
  not robust), so that the world frame other consumers use does not move as
  a whole; the baseline's length is held as well (flights cannot give a
  scale).  With equal priors a correction is shared among the cameras.
- **Refusal.** The covariance of the camera parameters (the detection noise
  estimated from the tracks, over the reduced Jacobian's information) gives a
  1-sigma uncertainty of each (with ``keep_world``: of the rig's relative
  geometry); a rotation, centre, focal length or offset above its bound, too
  few flights (``min_flights``), a failed solve, or a result that reprojects
  worse than the given calibration puts a reason in
  :attr:`RefineResult.refusals` and nothing should be written.  Flights that
  leave a parameter ten times its bound undetermined are refused before any
  search.  A time offset strongly correlated with a pose (``|r| > 0.9``) is
  reported as confounded: the flights barely tell a time shift from a pose
  error.

Units: metres, radians inside (degrees in reports), seconds, raw pixels.
ROS-free.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
import math
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple

import cv2
import numpy as np
from scipy.linalg import solveh_banded
from scipy.optimize import least_squares

from .pair_check import epipolar_check
from ..calibration import CameraCalibration
from ..camera import Camera
from ..errors import UsageError
from ..evaluation.holdout import oracle_at
from ..offsets import apply_time_offsets, camera_time_offsets
from ..records import Observation
from ..stamps import NS_PER_S, seconds_to_ns

__all__ = [
    'CameraRefinement',
    'DEFAULT_MIN_FLIGHTS',
    'RefineResult',
    'epipolar_consistency',
    'refine_rig',
]

#: Fewest flights (runs of the reference camera's detections) for a result.
DEFAULT_MIN_FLIGHTS = 3
#: Default bounds of the 1-sigma uncertainty beyond which the data do not determine a value.
DEFAULT_MAX_SIGMA_DEG = 0.1
DEFAULT_MAX_SIGMA_M = 0.01
DEFAULT_MAX_SIGMA_S = 0.001
DEFAULT_MAX_SIGMA_FOCAL = 0.005
#: Default one-sigma priors of ``keep_world`` on every camera's rotation [deg] and centre [m].
DEFAULT_PRIOR_DEG = 1.0
DEFAULT_PRIOR_M = 0.05
#: |correlation| of a camera's offset with its pose above which they are confounded.
CONFOUNDED_CORRELATION = 0.9
# Fewest detections of the reference camera in a flight (the cubic needs four).
_MIN_FLIGHT_FRAMES = 4
# Smallest robust scale of the loss [px].
_MIN_SCALE_PX = 0.05
# Detections of the other cameras farther than this many robust scales are outliers.
_OUTLIER_SCALES = 4.0
# Most solve / re-assign / reject rounds.
_MAX_ROUNDS = 6
# Flights leaving a parameter this many times its bound undetermined are refused at once.
_EARLY_FACTOR = 10.0
# Most function evaluations of one solve.
_MAX_EVALUATIONS = 100
# Most Gauss-Newton steps of the ball positions for given camera parameters, and the
# relative decrease of the robust cost below which they stop.
_POINT_ITERATIONS = 20
_POINT_TOLERANCE = 1e-9
# Initial Marquardt damping of those steps.
_POINT_DAMPING = 1e-3
# One sigma of the baseline's length with keep_world [m]: held, as in the default gauge.
_BASELINE_SIGMA_M = 1e-4
# Jerk [m/s^3] that one sigma of the smoothness rows allows: loose (a 3 m/s spiral of radius
# 0.62 m has 70; drag and spin far less), so that the rows only remove the null modes; a
# bounce is an outlier the loss absorbs.  1e3 biased the simulated bounces at 168 fps.
_JERK_M_PER_S3 = 1e4


@dataclass(frozen=True)
class CameraRefinement:
    """
    What refinement changed for one camera, with 1-sigma uncertainties.

    ``rotation_deg`` is the angle of the rotation correction, ``centre_m``
    the distance the optical centre moved, ``focal`` the relative change of
    the focal lengths (0 without ``focal``), ``offset_s`` the new time
    offset (``offset_before_s`` the given one).  ``sigma_*`` are the largest
    1-sigma uncertainties of the components (0 for fixed values).  The
    reprojection medians [px] are before and after, over the camera's
    detections that entered; ``offset_correlation`` the largest |correlation|
    of the offset with the camera's pose (NaN without an offset).
    """

    name: str
    observations: int
    rotation_deg: float
    centre_m: float
    focal: float
    offset_before_s: float
    offset_s: float
    sigma_rotation_deg: float
    sigma_centre_m: float
    sigma_focal: float
    sigma_offset_s: float
    reprojection_before_px: float
    reprojection_after_px: float
    offset_correlation: float = math.nan


@dataclass(frozen=True)
class RefineResult:
    """
    The refined calibrations and what the data say about them.

    ``calibrations`` maps camera names (rig order) to refined calibrations
    (``time_offset_s`` included); ``cameras`` the per-camera report;
    ``refusals`` why the result must not be written (empty: it may);
    ``notes`` other findings (confounding); ``sigma_px`` the detection noise
    (per pixel coordinate) the uncertainties are scaled by; ``sigma_position_m``
    the rms 1-sigma displacement [m] of the flights' ball positions by the
    uncertainty of the refined camera parameters: the 3D error the refined
    calibration adds (with ``keep_world``: by the rig's relative geometry).
    """

    calibrations: Dict[str, CameraCalibration]
    cameras: List[CameraRefinement]
    flights: int
    points: int
    sigma_px: float
    refusals: List[str] = field(default_factory=list)
    notes: List[str] = field(default_factory=list)
    sigma_position_m: float = math.nan

    @property
    def ok(self) -> bool:
        """Return True when the data determine the result."""
        return not self.refusals


# -- data ---------------------------------------------------------------------------------------

@dataclass
class _Block:
    """One camera's detections in one recording."""

    camera: int
    recording: int
    raw_times: np.ndarray   # (M,) seconds from the recording's epoch, raw stamps
    pixels: np.ndarray      # (M, 2) raw pixels
    # (M', k) point indices (k = 1 for the reference; none before the first assignment)
    knots: np.ndarray = field(default_factory=lambda: np.zeros((0, 4), dtype=int))
    # (M,) bool: detections that entered (none before the first assignment)
    used: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    rejected: Optional[np.ndarray] = None    # (M,) bool: outliers left out


@dataclass
class _Flights:
    """The reference camera's flights of one recording: common-clock times and point indices."""

    times: np.ndarray       # (N,) seconds from the recording's epoch (stamp + o_ref)
    first: np.ndarray       # (F,) global index of each flight's first point
    last: np.ndarray        # (F,) global index of each flight's last point
    start_times: np.ndarray
    end_times: np.ndarray
    offset: int             # global index of this recording's first point


class _Linearization:
    """
    Residuals and Jacobian of a bundle adjustment, in the structure the solver uses.

    ``points`` holds per block ``(first row, point index (M, k), derivatives
    (M, k, r, 3))``: item m's r rows depend on k ball positions (a
    detection's two rows on one position for the reference camera, on the
    four knots of the cubic otherwise; a smoothness row's three on four);
    ``cameras`` is the dense (R, n_theta) Jacobian of the camera parameters
    (None when not computed).  The ball positions of a flight are numbered
    in time order and a row touches at most four consecutive ones, so
    ``J_p^T W J_p`` is banded (:meth:`normal`).
    """

    #: Lower bandwidth of the point normal matrix: four consecutive positions of 3 values.
    BANDWIDTH = 11

    def __init__(self, residuals: np.ndarray,
                 points: List[Tuple[int, np.ndarray, np.ndarray]],
                 cameras: Optional[np.ndarray], n_points: int):
        self.residuals = residuals
        self.points = points
        self.cameras = cameras
        self.n_points = n_points

    def normal(self, weights: np.ndarray, damping: float = 1e-9) -> np.ndarray:
        """
        Return ``J_p^T W J_p + damping * diag`` in lower banded storage (12, 3N).

        The (Marquardt) damping keeps a ball position that no other camera
        constrains along its ray (a gap in the other cameras' detections) from
        moving far on a tiny gradient.
        """
        size = 3 * self.n_points
        band = np.zeros((self.BANDWIDTH + 1, size))
        for row, index, derivative in self.points:
            per = derivative.shape[2]
            w = weights[row:row + per * len(index)].reshape(-1, per)
            # (M, k, l, 3, 3) blocks of J^T W J between knots k and l of each item.
            blocks = np.einsum('mkra,mlrb->mklab', derivative * w[:, None, :, None], derivative,
                               optimize=True)
            flat, lower = _band_plan(index, size)
            band += np.bincount(flat, weights=blocks.reshape(len(index), -1)[:, lower].ravel(),
                                minlength=band.size).reshape(band.shape)
        diagonal = band[0]
        floor = 1e-12 * max(float(diagonal.mean()) if size else 0.0, 1e-300)
        band[0] = diagonal * (1.0 + damping) + floor
        return band

    def points_transpose(self, weights: np.ndarray, matrix: np.ndarray) -> np.ndarray:
        """Return ``J_p^T W matrix`` (3N, q) for a (R, q) matrix (or (R,) vector)."""
        matrix = np.asarray(matrix, dtype=float)
        vector = matrix.ndim == 1
        matrix = matrix.reshape(len(matrix), -1)
        result = np.zeros((3 * self.n_points, matrix.shape[1]))
        for row, index, derivative in self.points:
            count = len(index)
            per = derivative.shape[2]
            w = weights[row:row + per * count].reshape(-1, per)
            values = matrix[row:row + per * count].reshape(count, per, -1) * w[:, :, None]
            contribution = np.einsum('mkra,mrq->mkaq', derivative, values)
            target = (3 * index[:, :, None] + np.arange(3)[None, None, :]).reshape(-1)
            contribution = contribution.reshape(-1, matrix.shape[1])
            for column in range(matrix.shape[1]):
                result[:, column] += np.bincount(target, weights=contribution[:, column],
                                                 minlength=len(result))
        return result[:, 0] if vector else result

    def points_times(self, moves: np.ndarray) -> np.ndarray:
        """Return ``J_p @ moves`` (R, q) for (3N, q) point moves."""
        rows = len(self.residuals)
        result = np.zeros((rows, moves.shape[1]))
        per_point = moves.reshape(self.n_points, 3, -1)
        for row, index, derivative in self.points:
            count = len(index)
            contribution = np.einsum('mkra,mkaq->mrq', derivative, per_point[index])
            per = derivative.shape[2]
            result[row:row + per * count] = contribution.reshape(per * count, -1)
        return result


_PLANS: Dict[Tuple[int, Tuple[int, ...], int], Tuple[np.ndarray, np.ndarray, np.ndarray]] = {}


def _band_plan(index: np.ndarray, size: int) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return where the (k, l, 3, 3) blocks of items with point indices (M, k) go in the band.

    :return: flat indices into the (12, size) band storage of the lower-triangle entries,
        item by item, and the mask of the lower-triangle entries among the k*k*9 per item
    """
    key = (index.__array_interface__['data'][0], index.shape, size)
    plan = _PLANS.get(key)
    if plan is not None and plan[0] is index:
        return plan[1], plan[2]
    k = index.shape[1]
    grid_k, grid_l, grid_a, grid_b = np.meshgrid(np.arange(k), np.arange(k), np.arange(3),
                                                 np.arange(3), indexing='ij')
    rows_i = 3 * index[:, grid_k.ravel()] + grid_a.ravel()[None, :]
    cols_j = 3 * index[:, grid_l.ravel()] + grid_b.ravel()[None, :]
    # The relative order within an item is the same for all items (knots are consecutive).
    lower = rows_i[0] >= cols_j[0] if len(index) else np.zeros(k * k * 9, dtype=bool)
    flat = ((rows_i - cols_j)[:, lower] * size + cols_j[:, lower]).ravel()
    if len(_PLANS) > 64:
        _PLANS.clear()
    _PLANS[key] = (index, flat, lower)
    return flat, lower


def _solve_band(band: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solve the banded symmetric system; raise the damping if it is not positive definite."""
    for _ in range(4):
        try:
            return solveh_banded(band, rhs, lower=True, check_finite=False)
        except np.linalg.LinAlgError:
            band = band.copy()
            band[0] = band[0] * (1.0 + 1e-6) + 1e-6 * max(float(band[0].mean()), 1e-300)
    return solveh_banded(band, rhs, lower=True, check_finite=False)


def _rows(observations: Sequence[Observation], name: str) -> Tuple[np.ndarray, np.ndarray]:
    rows = sorted({o.stamp_ns: (o.stamp_ns, o.u, o.v) for o in observations
                   if o.camera == name and math.isfinite(o.u) and math.isfinite(o.v)}.values())
    stamps = np.array([r[0] for r in rows], dtype=np.int64)
    return stamps, np.array([r[1:] for r in rows], dtype=float).reshape(-1, 2)


def _lagrange(s: np.ndarray, knots_t: np.ndarray) -> np.ndarray:
    """Return (M, 4) cubic Lagrange weights at times (M,) for knot times (M, 4)."""
    weights = np.ones_like(knots_t)
    for m in range(4):
        for n in range(4):
            if n != m:
                weights[:, m] *= (s - knots_t[:, n]) / (knots_t[:, m] - knots_t[:, n])
    return weights


def _lagrange_quadratic(s: np.ndarray, knots_t: np.ndarray) -> np.ndarray:
    """Return (M, 3) quadratic Lagrange weights at times (M,) for knot times (M, 3)."""
    weights = np.ones_like(knots_t)
    for m in range(3):
        for n in range(3):
            if n != m:
                weights[:, m] *= (s - knots_t[:, n]) / (knots_t[:, m] - knots_t[:, n])
    return weights


def _rotation(omega: np.ndarray, base: np.ndarray) -> np.ndarray:
    return cv2.Rodrigues(np.asarray(omega, dtype=float).reshape(3, 1))[0] @ base


# -- the problem --------------------------------------------------------------------------------

class _Problem:
    """Parameter layout, residuals and sparsity of one bundle adjustment."""

    def __init__(self, cameras: Sequence[Camera], recordings: Sequence[Sequence[Observation]],
                 offsets: Dict[str, float], *,
                 focal: bool, estimate_offsets: bool, keep_world: bool,
                 baseline_m: Optional[float], prior_rad: float, prior_m: float,
                 max_gap_s: float):
        self.cameras = list(cameras)
        self.offsets0 = offsets
        self.keep_world = keep_world
        self.prior_rad, self.prior_m = prior_rad, prior_m
        self.flights: List[_Flights] = []
        self.blocks: List[_Block] = []
        ref = self.cameras[0]
        points0, count = [], 0
        for number, observations in enumerate(recordings):
            observations = list(observations)
            if not observations:
                continue
            epoch = min(o.stamp_ns for o in observations)
            ref_stamps, ref_pixels = _rows(observations, ref.name)
            initial = self._initial_points(observations, ref_stamps)
            times = (ref_stamps - epoch).astype(float) / NS_PER_S + offsets[ref.name]
            cuts = np.nonzero(np.diff(times) > max_gap_s)[0] + 1
            keep: List[np.ndarray] = []
            first: List[int] = []
            last: List[int] = []
            starts: List[float] = []
            ends: List[float] = []
            for chunk in np.split(np.arange(len(times)), cuts):
                good = np.all(np.isfinite(initial[chunk]), axis=1)
                if len(chunk) < _MIN_FLIGHT_FRAMES or good.sum() < 2:
                    continue
                index = np.arange(len(chunk))
                for axis in range(3):  # fill detections no other camera saw, along the flight
                    initial[chunk, axis] = np.interp(index, index[good],
                                                     initial[chunk[good], axis])
                kept_so_far = count + sum(len(chunk_) for chunk_ in keep)
                first.append(kept_so_far)
                last.append(kept_so_far + len(chunk) - 1)
                keep.append(chunk)
                starts.append(times[chunk[0]])
                ends.append(times[chunk[-1]])
            if not keep:
                continue
            kept = np.concatenate(keep)
            self.flights.append(_Flights(times[kept], np.array(first), np.array(last),
                                         np.array(starts), np.array(ends), count))
            self.blocks.append(_Block(0, len(self.flights) - 1, times[kept] - offsets[ref.name],
                                      ref_pixels[kept], used=np.ones(len(kept), bool),
                                      knots=(count + np.arange(len(kept)))[:, None]))
            points0.append(initial[kept])
            count += len(kept)
            for k, camera in enumerate(self.cameras[1:], start=1):
                stamps, pixels = _rows(observations, camera.name)
                if len(stamps):
                    self.blocks.append(_Block(k, len(self.flights) - 1,
                                              (stamps - epoch).astype(float) / NS_PER_S,
                                              pixels))
        self.n_points = count
        self.points0 = np.vstack(points0) if points0 else np.zeros((0, 3))
        #: Rows of the keep_world priors at the end of the residuals (6 per camera and the
        #: baseline's length, or none).
        self.prior_rows = 6 * len(self.cameras) + 1 if keep_world else 0
        self._smoothness()
        self._layout(focal, estimate_offsets, keep_world, baseline_m)

    def _smoothness(self) -> None:
        """
        Prepare the smoothness rows: every four consecutive positions of a flight.

        Without them the positions have near-null "zig-zag" modes: a cubic
        interpolated half-way between knots does not see alternating depth
        changes of the knots (weights -1/16, 9/16, 9/16, -1/16).  The row is the
        fourth position minus the quadratic through the three before (the third
        difference, jerk * dt^3), over ``_JERK_M_PER_S3 * dt^3``: far weaker than
        the detections for smooth flights, strong against a zig-zag.
        """
        index, coefficients, sigma = [], [], []
        times = self._times()
        for flights in self.flights:
            for first, last in zip(flights.first, flights.last):
                if last - first < 3:
                    continue
                start = np.arange(first, last - 2)
                knots = start[:, None] + np.arange(4)[None, :]
                t = times[knots]
                quadratic = _lagrange_quadratic(t[:, 3], t[:, :3])
                index.append(knots)
                coefficients.append(np.column_stack((-quadratic, np.ones(len(start)))))
                sigma.append(_JERK_M_PER_S3 * ((t[:, 3] - t[:, 0]) / 3.0) ** 3)
        self.jerk_index = np.vstack(index) if index else np.zeros((0, 4), dtype=int)
        self.jerk_coefficients = np.vstack(coefficients) if coefficients else np.zeros((0, 4))
        self.jerk_sigma = np.maximum(np.concatenate(sigma), 1e-9) if sigma else np.zeros(0)

    def _initial_points(self, observations: Sequence[Observation],
                        ref_stamps: np.ndarray) -> np.ndarray:
        """Triangulate the reference camera with the first other camera that sees the ball."""
        shifted = apply_time_offsets(observations, self.offsets0)
        query = ref_stamps + seconds_to_ns(self.offsets0[self.cameras[0].name])
        points = np.full((len(ref_stamps), 3), np.nan)
        for camera in self.cameras[1:]:
            missing = ~np.all(np.isfinite(points), axis=1)
            if not missing.any():
                break
            found = oracle_at(self.cameras[0], camera, shifted, query[missing],
                              max_gap_ns=seconds_to_ns(0.1))
            points[missing] = found
        return points

    # -- parameters ---------------------------------------------------------------------------

    def _layout(self, focal: bool, estimate_offsets: bool, keep_world: bool,
                baseline_m: Optional[float]) -> None:
        self.slices: List[Dict[str, slice]] = []
        position = 3 * self.n_points
        ref_centre = self.cameras[0].center
        self.baseline = 0.0
        for k, camera in enumerate(self.cameras):
            parts = {}

            def take(name: str, size: int) -> None:
                nonlocal position
                parts[name] = slice(position, position + size)
                position += size

            if keep_world or k > 0:
                take('rotation', 3)
                if not keep_world and k == 1:
                    take('direction', 2)
                else:
                    take('centre', 3)
            if focal and k > 0:  # the reference focal length is held (see the docstring)
                take('focal', 1)
            if estimate_offsets and k > 0:
                take('offset', 1)
            self.slices.append(parts)
        axis = self.cameras[1].center - ref_centre
        length = float(np.linalg.norm(axis))
        if not length > 0:
            raise UsageError('the first two cameras share an optical centre: no baseline')
        self.baseline = float(baseline_m) if baseline_m is not None else length
        if not keep_world:
            self.axis = axis / length
            helper = np.eye(3)[int(np.argmin(np.abs(self.axis)))]
            self.e1 = np.cross(self.axis, helper)
            self.e1 /= np.linalg.norm(self.e1)
            self.e2 = np.cross(self.axis, self.e1)
        self.n_params = position
        x0 = np.zeros(self.n_params)
        x0[:3 * self.n_points] = self.points0.ravel()
        for k, camera in enumerate(self.cameras):
            parts = self.slices[k]
            if 'centre' in parts:
                x0[parts['centre']] = camera.center
            if 'offset' in parts:
                x0[parts['offset']] = self.offsets0[camera.name]
        self.x0 = x0

    def camera_state(self, x: np.ndarray, k: int) -> Tuple[np.ndarray, np.ndarray, np.ndarray,
                                                           float]:
        """Return (R, centre, K, offset) of camera k at parameters x."""
        camera, parts = self.cameras[k], self.slices[k]
        rotation = camera.R
        if 'rotation' in parts:
            rotation = _rotation(x[parts['rotation']], camera.R)
        if 'centre' in parts:
            centre = x[parts['centre']]
        elif 'direction' in parts:
            a, b = x[parts['direction']]
            direction = self.axis + a * self.e1 + b * self.e2
            centre = self.cameras[0].center + self.baseline * direction / np.linalg.norm(
                direction)
        else:
            centre = camera.center
        matrix = camera.K.copy()
        if 'focal' in parts:
            scale = 1.0 + x[parts['focal']][0]
            matrix[0, 0] *= scale
            matrix[0, 1] *= scale
            matrix[1, 1] *= scale
        offset = x[parts['offset']][0] if 'offset' in parts else self.offsets0[camera.name]
        return rotation, centre, matrix, float(offset)

    # -- residuals ----------------------------------------------------------------------------

    def assign(self, x: np.ndarray) -> int:
        """Assign every other camera's detections to reference knots; return how many entered."""
        total = 0
        for block in self.blocks:
            if block.camera == 0:
                total += len(block.raw_times)
                continue
            offset = self.camera_state(x, block.camera)[3]
            flights = self.flights[block.recording]
            s = block.raw_times + offset
            flight = np.searchsorted(flights.start_times, s, side='right') - 1
            inside = (flight >= 0) & (s <= flights.end_times[np.maximum(flight, 0)])
            if block.rejected is None:
                block.rejected = np.zeros(len(s), dtype=bool)
            inside &= ~block.rejected
            block.used = inside
            s, flight = s[inside], flight[inside]
            local = np.searchsorted(flights.times, s, side='right') - 1 + flights.offset
            lo = flights.first[flight]
            hi = flights.last[flight] - 3
            start = np.clip(local - 1, lo, np.maximum(hi, lo))
            block.knots = start[:, None] + np.arange(4)[None, :]
            total += int(inside.sum())
        return total

    def _times(self) -> np.ndarray:
        return np.concatenate([f.times for f in self.flights]) if self.flights else np.zeros(0)

    def evaluate(self, x: np.ndarray, *, scale_px: float = 1.0, priors: bool = True,
                 jacobian: bool = False, cameras: bool = True) -> Any:
        """
        Return the residuals, or their linearization when ``jacobian`` is true.

        Rows: two reprojection residuals [px] per detection that entered, block
        by block, then with ``keep_world`` the priors (in units of ``scale_px``
        per prior sigma, so a prior sigma weighs like a typical residual).
        With ``cameras=False`` the camera columns are not computed (the inner
        solve of the ball positions needs none).

        :return: the residuals (R,), or a :class:`_Linearization`
        """
        points = x[:3 * self.n_points].reshape(-1, 3)
        times = self._times()
        states = [self.camera_state(x, k) for k in range(len(self.cameras))]
        n_theta = self.n_params - 3 * self.n_points
        parts: List[np.ndarray] = []
        point_blocks: List[Tuple[int, np.ndarray, np.ndarray]] = []
        camera_rows: List[np.ndarray] = []
        row = 0
        for block in self.blocks:
            rotation, centre, matrix, offset = states[block.camera]
            camera = self.cameras[block.camera]
            if block.camera == 0:
                index = block.knots
                weights = np.ones((len(index), 1))
                world = points[index[:, 0]]
            else:
                index = block.knots
                s = block.raw_times[block.used] + offset
                weights = _lagrange(s, times[index])
                world = np.einsum('mk,mkj->mj', weights, points[index])
            projected, d_camera = _project(world, rotation, centre, matrix, camera,
                                           jacobian=jacobian)
            parts.append((projected - block.pixels[block.used]).ravel())
            count = len(world)
            if jacobian:
                d_world = d_camera @ rotation                       # (M, 2, 3)
                point_blocks.append((row, index, weights[:, :, None, None] * d_world[:, None]))
                if cameras:
                    derivative = np.zeros((count, 2, n_theta))
                    self._camera_jacobian(x, block, camera, states[block.camera], world,
                                          d_camera, d_world, index, times, derivative)
                    camera_rows.append(derivative.reshape(2 * count, n_theta))
            row += 2 * count
        if len(self.jerk_index):
            # Smoothness: the fourth position against the quadratic through the three before.
            moved = np.einsum('mk,mkj->mj', self.jerk_coefficients, points[self.jerk_index])
            parts.append((scale_px * moved / self.jerk_sigma[:, None]).ravel())
            count = len(self.jerk_index)
            if jacobian:
                gain = scale_px * self.jerk_coefficients / self.jerk_sigma[:, None]
                point_blocks.append((row, self.jerk_index,
                                     gain[:, :, None, None] * np.eye(3)[None, None]))
                if cameras:
                    camera_rows.append(np.zeros((3 * count, n_theta)))
            row += 3 * count
        if priors and self.keep_world:
            for k, camera in enumerate(self.cameras):
                for name, reference, sigma in (('rotation', 0.0, self.prior_rad),
                                               ('centre', camera.center, self.prior_m)):
                    part = self.slices[k][name]
                    parts.append(scale_px * (x[part] - reference) / sigma)
                    if jacobian and cameras:
                        derivative = np.zeros((3, n_theta))
                        columns = np.arange(part.start, part.stop) - 3 * self.n_points
                        derivative[np.arange(3), columns] = scale_px / sigma
                        camera_rows.append(derivative)
                    row += 3
            # The scale: flights cannot give it, and the smoothness rows would shrink the rig.
            first, second = self.slices[0]['centre'], self.slices[1]['centre']
            axis = x[second] - x[first]
            length = float(np.linalg.norm(axis))
            parts.append(np.array([scale_px * (length - self.baseline) / _BASELINE_SIGMA_M]))
            if jacobian and cameras:
                derivative = np.zeros((1, n_theta))
                unit = scale_px / _BASELINE_SIGMA_M * axis / length
                derivative[0, second.start - 3 * self.n_points:second.stop
                           - 3 * self.n_points] = unit
                derivative[0, first.start - 3 * self.n_points:first.stop
                           - 3 * self.n_points] = -unit
                camera_rows.append(derivative)
            row += 1
        residuals = np.concatenate(parts) if parts else np.zeros(0)
        if not jacobian:
            return residuals
        camera_jacobian = (np.vstack(camera_rows) if camera_rows and cameras
                           else None)
        return _Linearization(residuals, point_blocks, camera_jacobian, self.n_points)

    def _camera_jacobian(self, x: np.ndarray, block: _Block, camera: Camera,
                         state: Tuple[np.ndarray, np.ndarray, np.ndarray, float],
                         world: np.ndarray, d_camera: np.ndarray, d_world: np.ndarray,
                         index: np.ndarray, times: np.ndarray, derivative: np.ndarray) -> None:
        """Fill d residuals / d camera parameters (M, 2, n_theta) of one block."""
        rotation, centre, matrix, offset = state
        parts = self.slices[block.camera]
        first = 3 * self.n_points

        def add(part_slice: slice, value: np.ndarray) -> None:  # value (M, 2, n)
            derivative[:, :, part_slice.start - first:part_slice.stop - first] = value

        if 'rotation' in parts:
            omega = x[parts['rotation']]
            d_rodrigues = cv2.Rodrigues(omega.reshape(3, 1))[1].reshape(3, 3, 3)
            relative = world - centre
            columns = [relative @ (d_rodrigues[i] @ camera.R).T for i in range(3)]
            add(parts['rotation'], np.einsum('mij,kmj->mik', d_camera, np.array(columns)))
        if 'centre' in parts:
            add(parts['centre'], -d_world)
        elif 'direction' in parts:
            a, b = x[parts['direction']]
            v = self.axis + a * self.e1 + b * self.e2
            norm = float(np.linalg.norm(v))
            u = v / norm
            projector = (np.eye(3) - np.outer(u, u)) * self.baseline / norm
            d_centre = projector @ np.column_stack((self.e1, self.e2))  # (3, 2)
            add(parts['direction'], -d_world @ d_centre)
        if 'focal' in parts:
            # K = K0 (1 + phi): d/d phi is the derivative for a relative change of K / (1 + phi).
            d_focal = self._focal_derivative(world, state, camera) / (1.0 + x[parts['focal']][0])
            add(parts['focal'], d_focal[:, :, None])
        if 'offset' in parts and block.camera != 0:
            s = block.raw_times[block.used] + offset
            d_weights = _lagrange_derivative(s, times[index])
            velocity = np.einsum('mk,mkj->mj', d_weights, x[:3 * self.n_points].reshape(
                -1, 3)[index])
            add(parts['offset'], np.einsum('mij,mj->mi', d_world, velocity)[:, :, None])

    @staticmethod
    def _focal_derivative(world: np.ndarray,
                          state: Tuple[np.ndarray, np.ndarray, np.ndarray, float],
                          camera: Camera) -> np.ndarray:
        """Return d pixels / d (relative focal change), (M, 2), by a central difference."""
        rotation, centre, matrix, _ = state
        step = 1e-6
        moved = []
        for sign in (1.0, -1.0):
            scaled = matrix.copy()
            scaled[0, :2] *= 1.0 + sign * step
            scaled[1, 1] *= 1.0 + sign * step
            moved.append(_project(world, rotation, centre, scaled, camera)[0])
        return (moved[0] - moved[1]) / (2.0 * step)

    def residuals(self, x: np.ndarray, *, scale_px: float = 1.0,
                  priors: bool = True) -> np.ndarray:
        """Return the residuals alone (see :meth:`evaluate`)."""
        return self.evaluate(x, scale_px=scale_px, priors=priors)

    def reject(self, x: np.ndarray) -> int:
        """
        Leave out detections of the other cameras whose reprojection error is an outlier.

        Decided afresh from all detections inside flights (an outlier may come
        back), with the robust scale of all of them (the scale of the survivors
        would shrink round by round); the reference camera's detections always
        stay (each has its own ball position).  Return how many are left out.
        """
        for block in self.blocks:
            if block.camera:
                block.rejected = None
        self.assign(x)
        threshold = _OUTLIER_SCALES * self.scale(x)
        residuals = self.residuals(x, priors=False)
        position, total = 0, 0
        for block in self.blocks:
            count = int(block.used.sum())
            norms = np.hypot(*residuals[position:position + 2 * count].reshape(-1, 2).T)
            position += 2 * count
            if block.camera:
                rejected = np.zeros(len(block.used), dtype=bool)
                rejected[np.nonzero(block.used)[0][norms > threshold]] = True
                block.rejected = rejected
                total += int(rejected.sum())
        self.assign(x)
        return total

    def scale(self, x: np.ndarray) -> float:
        """
        Return the robust scale [px] of the other cameras' reprojection errors.

        1.4826 times the median error norm of their detections.  The reference
        camera is left out (each of its detections has its own ball position,
        which absorbs its error), and norms are used rather than components
        because the ball positions absorb the component along the epipolar
        lines too: half of the components are near zero.
        """
        tracks = [values for camera, values in self.per_camera(x).items() if camera]
        norms = np.concatenate(tracks) if tracks else np.zeros(0)
        return max(1.4826 * float(np.median(norms)), _MIN_SCALE_PX) if len(norms) \
            else _MIN_SCALE_PX

    def per_camera(self, x: np.ndarray) -> Dict[int, np.ndarray]:
        """Return camera index -> (M,) reprojection error norms [px] of its detections."""
        residuals = self.residuals(x, priors=False)
        result: Dict[int, np.ndarray] = {}
        position = 0
        for block in self.blocks:
            count = 2 * int(block.used.sum())
            norms = np.hypot(*residuals[position:position + count].reshape(-1, 2).T)
            result[block.camera] = np.concatenate((result.get(block.camera, np.zeros(0)),
                                                   norms))
            position += count
        return result


def _lagrange_derivative(s: np.ndarray, knots_t: np.ndarray) -> np.ndarray:
    """Return (M, 4) time derivatives [1/s] of the cubic Lagrange weights."""
    derivative = np.zeros_like(knots_t)
    for m in range(4):
        for n in range(4):
            if n == m:
                continue
            term = np.ones(len(s)) / (knots_t[:, m] - knots_t[:, n])
            for q in range(4):
                if q not in (m, n):
                    term = term * (s - knots_t[:, q]) / (knots_t[:, m] - knots_t[:, q])
            derivative[:, m] += term
    return derivative


def _project(world: np.ndarray, rotation: np.ndarray, centre: np.ndarray, matrix: np.ndarray,
             camera: Camera, *, jacobian: bool = False) -> Tuple[np.ndarray, Any]:
    """
    Project world points (M, 3) with a pose and camera matrix (the camera's distortion).

    :return: pixels (M, 2) and, with ``jacobian``, d pixels / d camera-frame point (M, 2, 3)
    """
    if len(world) == 0:
        return np.zeros((0, 2)), np.zeros((0, 2, 3))
    rvec = cv2.Rodrigues(rotation)[0]
    tvec = (-rotation @ centre).reshape(3, 1)
    object_points = np.ascontiguousarray(world, dtype=float).reshape(-1, 1, 3)
    if camera.fisheye:
        pixels, d = cv2.fisheye.projectPoints(object_points, rvec, tvec, matrix, camera.D)
        d_t = d[:, 11:14] if jacobian else None
    else:
        pixels, d = cv2.projectPoints(object_points, rvec, tvec, matrix, camera.D)
        d_t = d[:, 3:6] if jacobian else None
    pixels = pixels.reshape(-1, 2)
    if not jacobian:
        return pixels, None
    return pixels, np.asarray(d_t, dtype=float).reshape(-1, 2, 3)


def _soft_l1_weights(residuals: np.ndarray, scale_px: float) -> np.ndarray:
    """Return the IRLS weights rho'(z) of the soft-L1 loss, z = (r / scale)^2."""
    return 1.0 / np.sqrt(1.0 + (residuals / scale_px) ** 2)


class _Solver:
    """
    Variable projection: least squares over the camera parameters, ball positions inside.

    For given camera parameters the ball positions are solved by a few
    Gauss-Newton steps (iteratively reweighted for the soft-L1 loss); the
    positions couple only through the cubic interpolation, so each step is a
    banded Cholesky solve.  The outer problem has a handful of parameters and
    goes to :func:`scipy.optimize.least_squares` (soft-L1 loss) with the
    reduced Jacobian ``J_c + J_p dX/dc`` of the implicit function theorem.
    This converges in a few iterations where one large sparse problem (points
    and cameras together) crawls.
    """

    def __init__(self, problem: _Problem, x: np.ndarray, scale_px: float):
        self.problem = problem
        self.n_point = 3 * problem.n_points
        self.x = x.copy()
        self.scale_px = scale_px
        self._cache: Dict[bytes, Tuple[np.ndarray, _Linearization]] = {}
        self._damping = _POINT_DAMPING

    def solve_points(self, theta: np.ndarray) -> Tuple[np.ndarray, _Linearization]:
        """Return x with the positions optimal for theta, and its full linearization."""
        key = theta.tobytes()
        if key in self._cache:
            return self._cache[key]
        problem, n, scale = self.problem, self.n_point, self.scale_px
        x = self.x.copy()
        x[n:] = theta
        linear = problem.evaluate(x, scale_px=scale, jacobian=True, cameras=False)
        cost = float(np.sum(_soft_l1_cost(linear.residuals, scale)))
        damping = self._damping
        for _ in range(_POINT_ITERATIONS):
            # Levenberg-Marquardt on the reweighted problem (IRLS for the soft-L1 loss).
            weights = _soft_l1_weights(linear.residuals, scale)
            gradient = linear.points_transpose(weights, linear.residuals)
            for _ in range(8):
                step = -_solve_band(linear.normal(weights, damping), gradient)
                trial = x.copy()
                trial[:n] += step
                trial_linear = problem.evaluate(trial, scale_px=scale, jacobian=True,
                                                cameras=False)
                trial_cost = float(np.sum(_soft_l1_cost(trial_linear.residuals, scale)))
                if trial_cost <= cost:
                    damping = max(damping / 10.0, 1e-9)
                    break
                damping *= 10.0
            else:
                break
            improvement = cost - trial_cost
            x, linear, cost = trial, trial_linear, trial_cost
            if improvement <= _POINT_TOLERANCE * max(cost, 1e-300):
                break
        linear = problem.evaluate(x, scale_px=scale, jacobian=True)
        self.x = x
        self._damping = damping
        self._cache = {key: (x, linear)}
        return x, linear

    def _loss(self, z: np.ndarray) -> np.ndarray:
        """
        Return soft-L1 (rho, rho', rho'') of z = (r / scale)^2, quadratic for the priors.

        The priors of ``keep_world`` (the last rows) must hold whatever the
        residuals do: under a robust loss a large pull would switch them off.
        """
        root = np.sqrt(1.0 + z)
        rho = np.array((2.0 * (root - 1.0), 1.0 / root, -0.5 / root ** 3))
        priors = self.problem.prior_rows
        if priors:
            rho[0, -priors:] = z[-priors:]
            rho[1, -priors:] = 1.0
            rho[2, -priors:] = 0.0
        return rho

    def fun(self, theta: np.ndarray) -> np.ndarray:
        """Return the residuals at the best positions for theta."""
        return self.solve_points(theta)[1].residuals

    def point_moves(self, theta: np.ndarray) -> Tuple[_Linearization, np.ndarray]:
        """
        Return the linearization at theta and d ball positions / d theta (3N, parameters).

        The implicit function theorem: the positions stay optimal as theta moves.
        """
        linear = self.solve_points(theta)[1]
        assert linear.cameras is not None  # solve_points linearizes the cameras too
        weights = _soft_l1_weights(linear.residuals, self.scale_px)
        moves = -_solve_band(linear.normal(weights, 1e-9),
                             linear.points_transpose(weights, linear.cameras))
        return linear, moves

    def jac(self, theta: np.ndarray) -> np.ndarray:
        """Return the reduced Jacobian d residuals / d theta (dense, rows x parameters)."""
        linear, moves = self.point_moves(theta)
        assert linear.cameras is not None
        return linear.cameras + linear.points_times(moves)

    def run(self) -> Tuple[np.ndarray, Any]:
        """Solve; return the full parameter vector and scipy's result."""
        theta0 = self.x[self.n_point:]
        result = least_squares(self.fun, theta0, jac=self.jac, method='trf', loss=self._loss,
                               f_scale=self.scale_px, x_scale='jac', xtol=1e-8, ftol=1e-8,
                               gtol=1e-8, max_nfev=_MAX_EVALUATIONS)
        x = self.solve_points(result.x)[0]
        return x, result


def _soft_l1_cost(residuals: np.ndarray, scale_px: float) -> np.ndarray:
    return 2.0 * scale_px ** 2 * (np.sqrt(1.0 + (residuals / scale_px) ** 2) - 1.0)


def _detection_noise(problem: _Problem) -> float:
    """
    Return the detection noise [px per component] estimated from the image tracks.

    Model-free: the third differences of each camera's pixel track (within
    runs of detections at the camera's frame interval) are dominated by noise
    for a smoothly moving ball (their variance is 20 sigma^2); the median is
    robust to bounces.  The fit's own residuals would not do: the ball
    positions absorb an unknown share of them.
    """
    differences = []
    for block in problem.blocks:
        times, pixels = block.raw_times, block.pixels
        if len(times) < 4:
            continue
        steps = np.diff(times)
        regular = steps <= 1.5 * np.median(steps)
        ok = regular[:-2] & regular[1:-1] & regular[2:]
        third = pixels[3:] - 3.0 * pixels[2:-1] + 3.0 * pixels[1:-2] - pixels[:-3]
        differences.append(third[ok].ravel())
    values = np.concatenate(differences) if differences else np.zeros(0)
    if not len(values):
        return _MIN_SCALE_PX
    return max(1.4826 * float(np.median(np.abs(values))) / math.sqrt(20.0), _MIN_SCALE_PX)


def _relative_covariance(problem: _Problem, x: np.ndarray,
                         sigma_px: float) -> Tuple[np.ndarray, float]:
    """
    Return the covariance of the camera parameters that the flights must determine.

    In the default gauge that is all of them.  With ``keep_world`` the priors,
    not the flights, place the rig in the world (a rig moved as a whole
    explains the flights as well), so the uncertainty is judged for the rig's
    relative geometry: the first camera's pose and the baseline's length held,
    the priors left out.  The first camera's rotation and centre then get 0.

    Also return what it means in 3D: the rms over the ball positions of their
    1-sigma displacement [m] by the camera parameters' uncertainty (each
    position moving with the parameters as the implicit function theorem
    says): the error the calibration adds to later estimates at the flights'
    distances.
    """
    linear, moves = _Solver(problem, x, problem.scale(x)).point_moves(x[3 * problem.n_points:])
    assert linear.cameras is not None
    jacobian = linear.cameras + linear.points_times(moves)
    covariance = _relative_covariance_of(problem, x, jacobian, sigma_px)
    per_point = moves.reshape(problem.n_points, 3, -1)
    variance = np.einsum('pai,ij,paj->p', per_point, covariance, per_point)
    return covariance, math.sqrt(max(float(np.mean(variance)), 0.0))


def _relative_covariance_of(problem: _Problem, x: np.ndarray, jacobian: np.ndarray,
                            sigma_px: float) -> np.ndarray:
    """Return the covariance of :func:`_relative_covariance` from the reduced Jacobian."""
    if not problem.keep_world:
        return _camera_covariance(jacobian, sigma_px)
    first = 3 * problem.n_points
    data = jacobian[:len(jacobian) - problem.prior_rows]
    held = [c - first for name in ('rotation', 'centre')
            for c in range(problem.slices[0][name].start, problem.slices[0][name].stop)]
    free = [c for c in range(jacobian.shape[1]) if c not in held]
    centre = problem.slices[1]['centre']
    axis = problem.camera_state(x, 1)[1] - problem.camera_state(x, 0)[1]
    length_row = np.zeros((1, jacobian.shape[1]))
    length_row[0, centre.start - first:centre.stop - first] = axis / np.linalg.norm(axis)
    # The baseline's length held: a row far stronger than the data.
    weight = 1e6 * max(float(np.abs(data).max(initial=0.0)), 1.0)
    reduced = np.vstack((data, weight * length_row))[:, free]
    covariance = np.zeros((jacobian.shape[1], jacobian.shape[1]))
    covariance[np.ix_(free, free)] = _camera_covariance(reduced, sigma_px)
    return covariance


def _camera_covariance(jacobian: np.ndarray, sigma_px: float) -> np.ndarray:
    """Covariance of the camera parameters from the reduced Jacobian, times sigma^2."""
    normal = jacobian.T @ jacobian
    normal = 0.5 * (normal + normal.T)
    values, vectors = np.linalg.eigh(normal)
    floor = max(float(values.max(initial=0.0)), 1e-300) * 1e-14
    return sigma_px ** 2 * (vectors / np.maximum(values, floor)) @ vectors.T


# -- the entry point ----------------------------------------------------------------------------

def refine_rig(cameras: Mapping[str, Camera] | Sequence[Camera],
               recordings: Sequence[Sequence[Observation]], *,
               offsets_s: Optional[Mapping[str, float]] = None, estimate_offsets: bool = True,
               focal: bool = False, keep_world: bool = False,
               baseline_m: Optional[float] = None, prior_deg: float = DEFAULT_PRIOR_DEG,
               prior_m: float = DEFAULT_PRIOR_M, max_gap_s: float = 0.1,
               min_flights: int = DEFAULT_MIN_FLIGHTS,
               max_sigma_deg: float = DEFAULT_MAX_SIGMA_DEG,
               max_sigma_m: float = DEFAULT_MAX_SIGMA_M,
               max_sigma_s: float = DEFAULT_MAX_SIGMA_S,
               max_sigma_focal: float = DEFAULT_MAX_SIGMA_FOCAL) -> RefineResult:
    """
    Refine extrinsics (and focal lengths) and time offsets of a rig from recorded flights.

    :param cameras: the cameras in order (a Rig or a sequence); the first is the reference
    :param recordings: one or more recordings of observations with raw stamps
    :param offsets_s: the given offsets [s] (default: the calibrations')
    :param estimate_offsets: refine every offset but the reference's (else keep them)
    :param focal: refine the focal lengths (fx, fy by one factor) of every camera but the
        reference, whose focal length is held (with two converging cameras both are not
        determined)
    :param keep_world: free every pose, held near the given one by priors (else: the
        reference pose fixed, the scale by the baseline of the first two cameras)
    :param baseline_m: the baseline of the first two cameras [m] (default: the given one)
    :param prior_deg: 1-sigma prior on each rotation with ``keep_world`` [deg]
    :param prior_m: 1-sigma prior on each centre with ``keep_world`` [m]
    :param max_gap_s: longest gap inside a flight [s]
    :param min_flights: fewest flights for a result
    :param max_sigma_deg: largest allowed 1-sigma rotation uncertainty [deg]
    :param max_sigma_m: largest allowed 1-sigma centre uncertainty [m]
    :param max_sigma_s: largest allowed 1-sigma offset uncertainty [s]
    :param max_sigma_focal: largest allowed 1-sigma relative focal uncertainty
    :return: the result; check :attr:`RefineResult.refusals` before writing it
    :raises UsageError: fewer than two cameras, bad options, or no flight seen by two cameras
    """
    cameras = list(cameras.values()) if isinstance(cameras, Mapping) else list(cameras)
    if len(cameras) < 2:
        raise UsageError(f'refine needs at least two cameras, got {len(cameras)}')
    for label, value in (('prior_deg', prior_deg), ('prior_m', prior_m),
                         ('max_gap_s', max_gap_s)):
        if not (value > 0 and math.isfinite(value)):
            raise UsageError(f'{label}: expected a positive number, got {value}')
    if baseline_m is not None and not (baseline_m > 0 and math.isfinite(baseline_m)):
        raise UsageError(f'baseline: expected a positive number of metres, got {baseline_m}')
    offsets = camera_time_offsets(cameras, offsets_s)
    problem = _Problem(cameras, recordings, offsets, focal=focal,
                       estimate_offsets=estimate_offsets, keep_world=keep_world,
                       baseline_m=baseline_m, prior_rad=math.radians(prior_deg),
                       prior_m=prior_m, max_gap_s=max_gap_s)
    if problem.n_points == 0:
        raise UsageError(f'no flight of {cameras[0].name} seen by another camera '
                         f'(need runs of at least {_MIN_FLIGHT_FRAMES} detections)')
    x = problem.x0.copy()
    problem.assign(x)

    # Before: the given calibration, only the ball positions fitted.
    n_point = 3 * problem.n_points
    x = _Solver(problem, x, problem.scale(x)).solve_points(x[n_point:])[0]
    before = problem.per_camera(x)
    sigma_px = _detection_noise(problem)
    bounds: Dict[str, float] = {'min_flights': min_flights, 'max_sigma_deg': max_sigma_deg,
                                'max_sigma_m': max_sigma_m, 'max_sigma_s': max_sigma_s,
                                'max_sigma_focal': max_sigma_focal}

    # Flights that leave a parameter undetermined by far (ten times its bound, judged at the
    # given calibration: the geometry, not the error, decides) are refused without a search
    # through the flat directions of the cost.
    covariance, sigma_position = _relative_covariance(problem, x, sigma_px)
    early = _report(problem, x, before, before, covariance, sigma_px, sigma_position,
                    converged=True,
                    early=True, bounds={key: value * (_EARLY_FACTOR if key.startswith('max')
                                                      else 1)
                                        for key, value in bounds.items()})
    if any('not determined' in reason for reason in early.refusals):
        return early

    result = None
    for _ in range(_MAX_ROUNDS):
        # Each round: solve, then re-assign the knots (the offsets moved), re-scale the loss and
        # leave out outliers (a cubic across a bounce), until nothing changes.
        x, result = _Solver(problem, x, problem.scale(x)).run()
        previous = [(b.knots.copy(), b.used.copy()) for b in problem.blocks]
        problem.reject(x)
        if all(np.array_equal(used, b.used) and np.array_equal(knots, b.knots)
               for (knots, used), b in zip(previous, problem.blocks)):
            break
    else:
        x, result = _Solver(problem, x, problem.scale(x)).run()
    after = problem.per_camera(x)
    covariance, sigma_position = _relative_covariance(problem, x, sigma_px)
    return _report(problem, x, before, after, covariance, sigma_px, sigma_position,
                   converged=result.status > 0, message=result.message, bounds=bounds)


def _report(problem: _Problem, x: np.ndarray, before: Dict[int, np.ndarray],
            after: Dict[int, np.ndarray], covariance: np.ndarray, scale: float,
            sigma_position: float, *,
            converged: bool, bounds: Mapping[str, float], message: str = '',
            early: bool = False) -> RefineResult:
    """Judge a solution against ``bounds`` (min_flights, max_sigma_*); build the result."""
    min_flights = bounds['min_flights']
    max_sigma_deg, max_sigma_m = bounds['max_sigma_deg'], bounds['max_sigma_m']
    max_sigma_s, max_sigma_focal = bounds['max_sigma_s'], bounds['max_sigma_focal']
    n_point = 3 * problem.n_points
    flights = sum(len(f.first) for f in problem.flights)
    refusals, notes = [], []
    if flights < min_flights:
        refusals.append(f'too few flights: {flights} (need {min_flights}; a flight is a run '
                        f'of {problem.cameras[0].name} detections without a gap over max_gap)')
    if not converged:
        refusals.append(f'the solver did not converge: {message}')
    pooled_before = np.concatenate(list(before.values())) if before else np.zeros(0)
    pooled_after = np.concatenate(list(after.values())) if after else np.zeros(0)
    if len(pooled_after) and not np.median(pooled_after) <= np.median(pooled_before):
        refusals.append(f'the refined calibration reprojects worse than the given one (median '
                        f'{np.median(pooled_after):.3g} px > {np.median(pooled_before):.3g} px)')
    calibrations, reports = {}, []
    for k, camera in enumerate(problem.cameras):
        parts = problem.slices[k]
        rotation, centre, matrix, offset = problem.camera_state(x, k)
        sigma = {}
        for name, part in parts.items():
            block = covariance[part.start - n_point:part.stop - n_point,
                               part.start - n_point:part.stop - n_point]
            sigma[name] = block
        sigma_rotation = (math.degrees(math.sqrt(float(np.max(np.diag(sigma['rotation'])))))
                          if 'rotation' in sigma else 0.0)
        if 'centre' in sigma:
            sigma_centre = math.sqrt(float(np.max(np.diag(sigma['centre']))))
        elif 'direction' in sigma:
            sigma_centre = _direction_sigma(problem, x, k, sigma['direction'])
        else:
            sigma_centre = 0.0
        sigma_focal = math.sqrt(float(sigma['focal'][0, 0])) if 'focal' in sigma else 0.0
        sigma_offset = math.sqrt(float(sigma['offset'][0, 0])) if 'offset' in sigma else 0.0
        correlation = math.nan
        if 'offset' in parts:
            correlation = _offset_correlation(covariance, parts, n_point)
        change = rotation @ camera.R.T
        angle = math.degrees(float(np.linalg.norm(cv2.Rodrigues(change)[0])))
        focal_change = float(matrix[0, 0] / camera.K[0, 0] - 1.0)
        report = CameraRefinement(
            camera.name, int(len(after.get(k, []))), angle,
            float(np.linalg.norm(centre - camera.center)), focal_change,
            problem.offsets0[camera.name], offset, sigma_rotation, sigma_centre, sigma_focal,
            sigma_offset, _median(before.get(k)), _median(after.get(k)), correlation)
        reports.append(report)
        for label, value, bound, unit in (
                ('rotation', sigma_rotation, max_sigma_deg, 'deg'),
                ('optical centre', sigma_centre, max_sigma_m, 'm'),
                ('focal length', sigma_focal, max_sigma_focal, '(relative)'),
                ('time offset', sigma_offset, max_sigma_s, 's')):
            if not value <= bound:
                judged = (f'{_EARLY_FACTOR:g} x the bound, judged before refining: '
                          if early else '')
                refusals.append(f'{camera.name}: {label} not determined by these flights: '
                                f'1 sigma {value:.3g} {unit} > {judged}{bound:g} {unit} '
                                '(degenerate motion: add flights in other directions and '
                                'places)')
        if correlation > CONFOUNDED_CORRELATION:
            notes.append(f'{camera.name}: time offset and pose are confounded (correlation '
                         f'{correlation:.2f}): the flights barely tell a time shift from a '
                         'calibration error; flights in other directions separate them')
        calibrations[camera.name] = replace(
            camera.calibration, camera_matrix=_frozen(matrix), rotation=_frozen(rotation),
            translation=_frozen(-rotation @ centre), time_offset_s=float(offset))
    return RefineResult(calibrations, reports, flights, problem.n_points, scale, refusals,
                        notes, sigma_position)


def _frozen(array: np.ndarray) -> np.ndarray:
    array = np.array(array, dtype=float)
    array.setflags(write=False)
    return array


def _median(values: Optional[np.ndarray]) -> float:
    return float(np.median(values)) if values is not None and len(values) else math.nan


def _direction_sigma(problem: _Problem, x: np.ndarray, k: int, covariance: np.ndarray) -> float:
    """Propagate the 2-parameter direction's covariance to the centre's largest sigma [m]."""
    part = problem.slices[k]['direction']
    base = problem.camera_state(x, k)[1]
    jacobian = np.zeros((3, 2))
    for column in range(2):
        moved = x.copy()
        moved[part.start + column] += 1e-7
        jacobian[:, column] = (problem.camera_state(moved, k)[1] - base) / 1e-7
    centre = jacobian @ covariance @ jacobian.T
    return math.sqrt(float(np.max(np.diag(centre))))


def _offset_correlation(covariance: np.ndarray, parts: Dict[str, slice], n_point: int) -> float:
    """Return the largest |correlation| of a camera's offset with its pose parameters."""
    offset = parts['offset'].start - n_point
    others = [c - n_point for name in ('rotation', 'centre', 'direction') if name in parts
              for c in range(parts[name].start, parts[name].stop)]
    if not others:
        return math.nan
    variance = covariance[offset, offset]
    values = [abs(covariance[offset, c]) / math.sqrt(max(variance * covariance[c, c], 1e-300))
              for c in others]
    # A combination of pose parameters can correlate more than any one: the multiple correlation.
    block = covariance[np.ix_(others, others)]
    cross = covariance[offset, others]
    try:
        multiple = float(cross @ np.linalg.solve(block, cross)) / max(variance, 1e-300)
    except np.linalg.LinAlgError:
        multiple = max(values) ** 2
    return float(min(1.0, math.sqrt(max(multiple, max(values) ** 2))))


def epipolar_consistency(cameras: Sequence[Camera], recordings: Sequence[Sequence[Observation]],
                         offsets_s: Mapping[str, float], *,
                         max_gap_s: float = 0.1) -> Dict[Tuple[str, str], Tuple[float, int]]:
    """
    Median epipolar distance [px] of every camera pair over recordings (offsets applied).

    As ``pseudo_stereo check``: the second camera's track is interpolated to the
    first camera's stamps (after adding each camera's offset).

    :param cameras: the cameras, in order
    :param recordings: observations with raw stamps
    :param offsets_s: camera name -> offset [s]
    :param max_gap_s: longest interpolated gap [s]
    :return: (name a, name b) -> (median [px], compared detections); NaN median without any
    """
    cameras = list(cameras)
    distances: Dict[Tuple[str, str], List[np.ndarray]] = {}
    for observations in recordings:
        shifted = apply_time_offsets(observations, offsets_s)
        tracks = {}
        for camera in cameras:
            mine = [o for o in shifted if o.camera == camera.name]
            tracks[camera.name] = (np.array([o.stamp_ns for o in mine], dtype=np.int64),
                                   np.array([(o.u, o.v) for o in mine], dtype=float))
        for i, a in enumerate(cameras):
            for b in cameras[i + 1:]:
                result = epipolar_check(a, *tracks[a.name], b, *tracks[b.name],
                                        max_gap_ns=seconds_to_ns(max_gap_s))
                distances.setdefault((a.name, b.name), []).append(result.distances_px)
    return {pair: ((float(np.median(np.concatenate(values))),
                    int(sum(len(v) for v in values)))
                   if sum(len(v) for v in values) else (math.nan, 0))
            for pair, values in distances.items()}
