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

r"""
The ``trajectory`` method: a causal fit of the ball's path to the rays of all cameras.

At every shutter event of any camera the ball's path over a sliding window
is fitted to the viewing rays of *every* camera, each at its own stamp, and
evaluated at the event's stamp: an estimate per shutter event, immediately,
with no look-ahead.  Any number of cameras (two or more) enter the same fit.

**Model.**  Over the window the path is a polynomial per axis,
``X(t) = sum_k beta_k ((t - t_event) / 0.1 s)^k`` with ``k <= 2`` (constant
acceleration: gravity, drag and, locally, curves), plus, when an impact lies
inside the window, a velocity jump ``dV * max(0, t - t_impact)`` (position
continuous at the impact).  A detection ``(x, y)`` (undistorted, normalized)
of a camera with rotation rows ``r1, r2, r3`` and centre ``c`` gives two
equations linear in the coefficients, the pinhole projection multiplied out:
``(r1 - x r3) . (X(t) - c) = 0`` and ``(r2 - y r3) . (X(t) - c) = 0``.  Each is
weighted by ``f / depth`` (the depth predicted when the frame arrives), so
residuals are reprojection errors in pixels.  Each frame's normal matrix is
added once to prefix sums kept in the coefficients of a fixed reference
stamp; a window's system is a difference of two prefixes, moved to the
event's stamp by a linear change of the time origin: one frame's work per
event, whatever the window.

**Window.**  Fits over nested windows of the newest 6, 9, 13, 19, 28, 40
and 60 frames of a pair (a rig of C cameras: C / 2 times as many, so that
more cameras do not shorten the windows' time spans; at most
``max_window_s``) are solved together.  The window is
chosen at each event by Lepski's rule: the longest window whose estimate
agrees with that of every shorter one within a chi-square bound (below;
for nested fits the difference has the difference of their
covariances).  Longer windows average more noise until the model's bias (a
curve a parabola cannot follow, a missed impact) shows as disagreement, so
the window follows the frame rate, the noise and the motion by itself: long
on a straight line or a parabola, short on a tight circle.  Lepski's rule
needs the detection noise; it is measured online (:attr:`sigma_px`) from the
difference of consecutive standardized residuals of each camera in a fit of
fixed length (Rice's estimator: the systematic part of a residual, a
calibration bias or the curvature a parabola misses at the window's end, is
nearly the same at consecutive frames and cancels; the noise does not),
averaged in the log domain so that rare large samples do not inflate it, and
never below ``min_sigma_px``.

**Model order, then window.**  On the longest window (at least 13 frames:
the path is smooth at that scale), two lower-order fits compete with its
constant acceleration: a constant velocity and a free fall (gravity
:data:`GRAVITY_MPS2` along -z, known); both have the variance of a velocity
fit, much smaller than a parabola's at the window's end.  Each is the
acceleration fit under a linear constraint (its acceleration fixed), so it
follows from that fit's solution; the one whose fixed acceleration the fitted
one differs from less (Wald's chi-square) is taken if that is within 12.  A
straight line keeps the velocity fit, a ball in flight the free fall, a curve
the acceleration fit.  Lepski's rule then runs among that model's fits of the
windows: with a lower-order model with the bound ``_LOWER_CONSISTENCY`` (the
longest window accepted the model: a disagreement is more likely noise, and a
noisy short velocity fit costs little), among acceleration fits with
``consistency`` (they run only where the path curves at the longest window's
scale, so a long window's bias is caught early).

**Jerk.**  Where the acceleration fit is taken and no impact lies in the
window, constant-jerk fits (a cubic per axis, from prefix sums of their own)
of the windows of 13 to 40 frames of a pair that span at least 0.15 s join
Lepski's rule, if the longest one's jerk is significant (Wald's chi-square
above 30): acceleration and jerk fits in one sequence by decreasing variance,
the least variable one consistent with every more variable one.  A turning
path (the spiral's acceleration turns 0.6-0.9 rad over such a span) is
followed by a cubic over windows where a parabola's bias already shows, so the
noise is averaged over more frames.  Where that sequence still takes an
acceleration fit (no parabola's bias shows yet) and three or more cubic
windows reach back 0.15 s (camera rates up to about 60 fps), the estimate is
the mean of the parabolas' own choice by Lepski's rule and the cubics': their
errors (a parabola's bias, a short cubic's noise) are partly independent, so
on the noisy spirals the mean is closer on average than either, and a path a
cubic fits exactly keeps the cubic.  Only the estimate comes from them: the path that
judges the next detection stays the acceleration fit's.

**A flight's first frames.**  Until the window holds six frames (a flight's
start, or a restart after the path was lost) the paper's method
(:class:`pseudo_stereo_ros.fusion.Fuser`, on the same admitted detections)
gives the estimate: a fit of so few frames extrapolates more roughly than the
paper's anchors (the real sessions' flight starts), and no detection is gated
by it.  Where the paper has none yet either, a constant-velocity fit of all
frames serves.  Where the window is long enough for acceleration but no window
determines it (one camera carried the path for a while: its depth is known only
from the other cameras' older rays), the better of a constant velocity and a
free fall over all frames (the smaller residuals) serves, and only where its
residuals are noise (``_fixed_fallback``): over 0.9 s of a bounce a constant
velocity missed gravity by 0.98 m.  One frame whose removal alone explains such
a fit's misfit is dropped as an outlier there, and in a window that just
reached six frames (``_check_young_window``): a flight's or a restart's first
frames are fitted ungated, and a restart often starts from a wrong blob.

**Impacts and outliers.**  A new detection is compared with the path predicted
from the previous event: its innovation less that camera's last residual (slow
biases cancel again), over its expected spread (noise, prediction covariance,
and the running spread of innovations accepted without the prediction's own
variance, each counted at most 20 times the spread so far).  Until the noise is known
(ten samples: a wrongly low noise makes false impacts) the gate uses a
provisional noise, twice the estimate and at least 1 px, from three samples on
(a flight's first 0.4 s at 30 fps: a stray detection there, fitted, bent the
short windows 0.2 m).  Beyond ``gate`` (chi-square, 2 d.o.f.) the detection is
*pending*: not fitted, and its event's estimate (kind ``'predicted'``) is the
predicted position, or, when the detection moved off it along the image of the
vertical by no more than an impact could carry the ball since the last frame,
where the path descends and the point lies above it, the point of its ray
nearest to the prediction with vertical offsets preferred (the first frame
after a bounce on a table or floor, which lifts the ball off the path it
would have followed).  If the next detection of any camera
agrees with the path, the pending one was an outlier (``outlier``).  If it
disagrees too and a path with a velocity jump explains both (their residuals
within the gate, or ten times smaller than without the jump), the impact is
confirmed (``breaks``): both are fitted with the jump, placed in time by a jump
in the flight's vertical plane (a bounce: the vertical and the horizontal
direction of the velocity) where that explains both within the noise, else
halfway into one of the last two intervals before the pending frame, and its
time is refined on a grid, then finer grids around the best, over the next six
frames; once three frames of two cameras follow the pending one, detections are
gated there too (a stray one, fitted while the jump was known from so few
frames, was 1.1-1.4 m off).  A detection within the gate but unlikely as noise (``_DOUBT``) against
a path known well there gets its estimate from the fit with it and then waits,
pending, for the next detection: judged against the path before it, both
disagreeing and explained by a jump make an impact (the first detection after
one is only a few pixels off); otherwise it is fitted as it would have been at
once.  Windows that reach back past the impact carry the jump; frames before an
earlier impact are dropped.  Two disagreeing detections that no jump explains
(of two cameras: three or more in a row of one camera alone are outliers, the
newest pending, until another camera's detection agrees or disagrees too; an
impact undone because one of the detections confirming it was stray, where the
two left are not explained either, still restarts from them, of one camera or
two) mean the path is lost: the fit restarts from them (``restarts``), and the lost
path's estimates no longer bound the plausible speed (a new ball served before
the rig paused); but until the new window has six frames, a fitted position out
of an impact's reach of the lost path is no estimate (``implausible``: the
ball's position is continuous at an impact, and a fit of a few frames, one of
them a wrong blob, can be anywhere).  A camera's first detection after a
silence longer than its max gap is fitted without gating: meanwhile the path
drifted along the other cameras' rays, where they cannot see, and they would
judge the returning camera's detections stray; unless another camera's
detection is pending and the two confirm an impact, or (one other camera having
carried the path) it lies off the path across the image of that camera's rays,
where no drift moves it: then it is judged as any detection (a camera silent
across a bounce).  A camera the path lost while its detections arrived is taken
as fresh too: none fitted over its max gap, the last two taken as outliers off
the path the same way and growing, one other camera alone carrying the path
(its depth drifted along that camera's rays; see ``_unheard``).  A shorter
drift is allowed for as well: a camera back from one or more missed frames
while one other camera alone carried the path is fitted when it is off the path
only along the image of that camera's ray (within 45 degrees), by no more than
half the acceleration a constant velocity or a free fall leaves
unexplained (at most 2 g) times the squared time since its last frame
(``_drifted``: on spirals at the rounding floor such detections were judged
stray and the drift grew, up to 79 mm off).

A late detection (older than the newest frame fitted: streamed cameras with
different latencies) is fitted without gating too, estimated at its own stamp,
unless it lies off the path there across the image of the one other camera's
rays: then it is an outlier (``outlier``), its estimate the prediction.

**Conditioning.**  A fit whose estimate has a standard deviation above
``max_uncertainty`` pixels of the newest camera per pixel of noise is not
used (when one camera stops seeing the ball, its last rays would be
extrapolated); with no usable fit there is no estimate (``degenerate``).
Estimates need two cameras with a detection within their max gap (the input
gate's), as for the paper's method.

**Input and plausibility.**  Every observation first passes the shared input
and timing rules of :class:`~pseudo_stereo_ros.timing.InputGate` (validation,
image margin, measured frame periods and max gaps, stamp outliers, sessions:
:attr:`TrajectoryFuser.gate`), and every estimate the physical plausibility
gate of :mod:`pseudo_stereo_ros.plausibility` (``max_speed_mps``, the
optional workspace box), exactly as for :class:`pseudo_stereo_ros.fusion.Fuser`;
and off a path faster than ``max_speed_mps`` (a fit of too few frames that
diverged) no impact is confirmed, nor a free jump's position taken (which must
also lie within an impact's reach of the path before it).
A new session (the cameras agree on a jump of their stamps, or the rig
resumes after a pause) starts a new flight: the window, the path and the
impacts are forgotten, the measured noise is kept.  A camera that comes back
after more than its max gap (``fresh`` for the gate) keeps its older frames in
the window: they are rays at their own stamps, which the path fit uses
without interpolating between them (the window is bounded by
``max_window_s``); only its residual history, compared over its max gap, is
too old to use.

Counts: ``observations`` = ``estimates`` + drops (:data:`DROP_REASONS`, the
paper fuser's plus ``pending``) + ``gate.held`` at all times.  The other keys
are informational: ``late``, ``breaks``, ``restarts``, ``predicted`` (estimates
at pending detections, among ``estimates``) and ``outlier`` (detections judged
stray, not fitted, or fitted and dropped again afterwards (``_remove_misfit``); their
event already counted as an estimate or a drop).
"""

from __future__ import annotations

import bisect
from collections import deque
from collections.abc import Iterator, Mapping, Sequence
import contextlib
import itertools
import math
from typing import TypeAlias

import numpy as np
from scipy.special import chdtri, fdtri

from .camera import Camera
from .errors import FuserConfigError
from .estimator import GatedEstimator
from .fusion import Fuser
from .plausibility import DEFAULT_MAX_SPEED_MPS
from .records import Estimate
from .timing import Admitted, INPUT_DROP_REASONS

__all__ = [
    'DEFAULT_CONSISTENCY',
    'DEFAULT_GATE',
    'DEFAULT_MAX_UNCERTAINTY',
    'DEFAULT_MAX_WINDOW_S',
    'DEFAULT_MIN_SIGMA_PX',
    'DROP_REASONS',
    'TrajectoryFuser',
]

#: Longest window considered [s].
DEFAULT_MAX_WINDOW_S = 1.0
#: Lepski's bound: chi-square (3 degrees of freedom) of two windows' disagreement (p ~ 0.05),
#: among constant-acceleration fits (used where the path curves at the longest window's scale).
DEFAULT_CONSISTENCY = 8.0
#: Impact/outlier gate: chi-square (2 degrees of freedom) of a detection's innovation.
DEFAULT_GATE = 60.0
#: Floor of the measured detection noise [px]: above the 0.05 px rounding floor's 0.014 px,
#: where a fit's bias dominates its residuals and Lepski's rule would stop at a biased
#: shortest window on bias alone (0.02 px: three cameras lost to a pair on the spiral).
DEFAULT_MIN_SIGMA_PX = 0.03
#: Largest estimate standard deviation, in pixels of the newest camera per pixel of noise.
DEFAULT_MAX_UNCERTAINTY = 8.0

#: Why an observation gave no estimate (keys of :attr:`TrajectoryFuser.stats`): the input
#: gate's reasons, then the method's.
DROP_REASONS = {
    **INPUT_DROP_REASONS,
    'no_partner': 'fewer than two cameras have a detection within their max gap',
    'warming_up': 'too few frames in the flight for a fit yet',
    'degenerate': 'no fit (or prediction) determined well enough (max_uncertainty), or '
                  'only a velocity or free-fall fit whose residuals are beyond the noise',
    'pending': 'the detection is off the path and pending_estimate is none, or it waits in '
               'the place of one judged stray (where the ball is depends on which was)',
    'implausible': 'the estimate moved faster than max_speed_mps from the previous one, or '
                   'lies outside the workspace box, or the fit restarted from a few frames '
                   "put it out of an impact's reach of the path it lost",
}

# Time unit of the polynomial [ns]: keeps the normal matrices well scaled.
_SCALE_NS = 100_000_000
# Window sizes [frames] of two cameras, nested, newest first; the largest bounds the work
# per event.  A rig of C cameras uses C / 2 times as many frames (the same time spans).
_WINDOWS = np.array((6, 9, 13, 19, 28, 40, 60))
# Where the 12 coefficients and then the right-hand side are in the prefix sums' augmented
# rows: x0 .. z2, the right-hand side, the jump (so that the first 10 serve fits without it).
_AUGMENTED = np.array((0, 1, 2, 3, 4, 5, 6, 7, 8, 10, 11, 12, 9))
# Frames kept at least (room for late observations); a rig of many cameras keeps twice its
# longest window (the store is compacted when full and must hold that window and more).
_CAPACITY = 256
# Coefficients (12): x0 x1 x2 y0 y1 y2 z0 z1 z2 (powers of tau per axis) and the velocity
# jump jx jy jz at an impact.  Subsets: constant acceleration, constant velocity.
_CV = np.array((0, 1, 3, 4, 6, 7))
# Constant-jerk fits (see _jerk_fits): the shortest time span of their windows [ns] and the
# chi-square (3 d.o.f.) above which the longest one's jerk is significant.  Without both, the
# real sessions' medians were 1.67 / 1.33 / 1.76 px instead of 1.58 / 1.21 / 1.70 (measured
# before the running spread's change below: a short window's jerk is poorly determined, and
# the 168 fps detections' noise is not white).
_JERK_MIN_SPAN_NS = 150_000_000
_JERK_SIGNIFICANCE = 30.0
# Fewest such windows for which the cubics' own choice and the parabolas' may be averaged
# (see _with_jerk): three reach back 0.15 s at camera rates up to about 60 fps, none at the
# real sessions' 168 fps unless detections are missing (with two, n1_n1's p90 was 1.094x the
# oracle's instead of 1.059x; with one, n3_p1_v14's 1.22x instead of 1.075x).
_JERK_AVERAGE_MIN = 3
# Two innovations of a camera's detections taken as outliers point the same way within this
# cosine (30 degrees) where the path drifts off its rays (see _unheard).
_DRIFT_COSINE = math.cos(math.pi / 6.0)
# A camera's innovation lies along the image of the one other camera's ray through the
# prediction (the epipolar line, where that camera alone cannot see the path drift) within
# this cosine (45 degrees) for a detection off the path the same way as this camera's
# previous, rejected one to be fitted (see _check).
_ALONG_COSINE = math.cos(math.pi / 4.0)
# A camera missed frames where its newest frame in the window is older than this many of its
# measured frame periods (see _drifted; the measure is the intervals' lower quartile, so
# intervals jittered by +-15 % reach about 1.45 of it, one missed frame at least 1.85).
_MISSED_PERIODS = 1.5
# The entries of the jerk fits' change of time origin that depend on delta (see _jerk_fits),
# per axis (p, q) of tau^q = sum_p C(q, p) (-delta)^(q - p) tau_reference^p, p < q.
_JERK_PAIRS = ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3))
_JERK_SHIFT = (np.array([4 * axis + p for axis in range(3) for p, _ in _JERK_PAIRS]),
               np.array([4 * axis + q for axis in range(3) for _, q in _JERK_PAIRS]))
# Their values are C(q, p) (-1)^(q - p) times delta^(q - p): (factor, power) per pair.
_JERK_TERMS = tuple((math.comb(q, p) * (-1) ** (q - p), q - p) for p, q in _JERK_PAIRS)
# The jerk fits' shortest and longest windows [frames of a pair; C cameras: C / 2 times as many].
_JERK_WINDOWS = (13, 40)
#: Gravity [m/s^2] of the free-fall model, along -z of the world frame (9.8 as in the paper
#: and the simulation; the standard 9.80665 differs by 0.07 %).
GRAVITY_MPS2 = 9.8
# The largest acceleration [m/s^2] a drift bound takes from the path (see _drifted): the
# spiral's 1.5 g passes; a fit gone wrong (hundreds of m/s^2) does not widen the bound.
_DRIFT_MAX_ACCELERATION = 2.0 * GRAVITY_MPS2
# The acceleration's coefficients (tau^2 per axis) and their fixed values in the
# lower-order models: a constant velocity, a free fall [m per (0.1 s)^2].
_ACCELERATION = np.array((2, 5, 8))
_FIXED_ACCELERATIONS = np.array(((0.0, 0.0), (0.0, 0.0),
                                 (0.0, -0.5 * GRAVITY_MPS2 * (_SCALE_NS * 1e-9) ** 2)))
_FIXED_LIST = _FIXED_ACCELERATIONS.T.tolist()  # per model: (x, y, z)
# Fewest frames of a window whose velocity fit may replace the acceleration fit. Like the
# support counts below it is a count of equations, not a time span, so it does not grow with
# the number of cameras as the windows do (more cameras reach it sooner, which is the point:
# it guards the statistics of the order test, not the window's length in time).
_CV_SELECT_MIN = 13
# Chi-square bound (3 d.o.f.) of a velocity fit's disagreement with the acceleration fit.
_ORDER_CONSISTENCY = 12.0
# Lepski's bound (chi-square, 3 d.o.f., p ~ 0.001) among the windows' lower-order fits: the
# longest window accepted that model, so a disagreement is more likely noise than bias.
_LOWER_CONSISTENCY = 16.0
# Frames after an impact during which its time is refined, and candidate times.
_REFINE_FRAMES = 6
_REFINE_MIN = 2  # frames after the pending one before the time is refined
# Frames after the pending one, of two cameras at least, before detections are gated while
# an impact's time is refined (with two, synchronized cameras' right after an impact
# confirmed a false second one: 2.3 m off; with four, more strays were fitted).
_GATE_AFTER_IMPACT = 3
# The prefix sums' reference stamp moves when the newest frame is this much farther from it
# than the longest window [ns].
_REANCHOR_NS = 400_000_000
_BREAK_GRID = 9
# Finer grids around the best impact time, each a fifth of the last step, down to 10 us.
_BREAK_ZOOM = 3
_BREAK_RESOLUTION_NS = 10_000
# Below this horizontal speed [m/s] a bounce's jump is taken as vertical only.
_BOUNCE_MIN_SPEED = 0.1
# Smoothing of the running innovation spread and of Rice's noise estimate; the clip of one
# noise sample (in variances) once warmed up.
_SPREAD_ALPHA = 0.05
# The largest innovation sample the running spread learns from, in times the spread so far.
_SPREAD_CLIP = 20.0
_SIGMA_ALPHA = 0.02
_EULER_GAMMA = 0.5772156649015329
# Residuals of frames with a larger leverage (short fits) do not enter the noise estimate.
_MAX_LEVERAGE = 0.5
# Noise samples needed before detections are gated at the measured noise (a wrongly low noise
# makes false impacts).  From _SIGMA_PROVISIONAL samples on they are gated at a provisional
# noise, _PROVISIONAL_FACTOR times the estimate and at least _PROVISIONAL_SIGMA_PX: wide
# enough not to judge a good detection stray, narrow enough to keep a wrong blob out of a
# flight's first fits (there the window is short and one stray detection bends it most).
_SIGMA_MATURE = 10
_SIGMA_PROVISIONAL = 3
_PROVISIONAL_FACTOR = 2.0
_PROVISIONAL_SIGMA_PX = 1.0
# Frames in the window before detections are gated: a flight's first velocity fits
# extrapolate too roughly to tell an outlier or an impact (the real data's flight starts).
_GATE_SUPPORT = 6
# Frames the fit needs before its estimates replace the paper method's.
_PAPER_SUPPORT = 6
# Admitted detections the paper's method is given again at a restart.
_RECENT = 6
# Drop reasons of the fit itself (undone where the paper's estimate stands in).
_FIT_DROPS = ('no_partner', 'warming_up', 'degenerate', 'pending', 'implausible')
# Length of the fit whose residuals measure the noise [frames].
_NOISE_WINDOW = 10
# Fewest frames of a velocity fit at a flight's start (3 determine it exactly).
_CV_MIN = 3
# A velocity or free-fall fit of a window's frames misfits where its residual sum of squares
# is beyond the chi-square bound of this p-value at _MISFIT_NOISE_FACTOR times the measured
# noise (see _fixed_fallback, _check_young_window); one frame is taken as an outlier where
# removing it explains the misfit (an F test at this p-value over the frames, Bonferroni).
# (Factors 1.4, 2, 2.8, 4 and 8 over sweep --messy, measured before _check_young_window:
# 170 / 170 / 169 / 168 / 169 runs over 0.5 m, 175 before; but at 8, or without the bound, a
# camera's silence at a spiral's start let a fallback's estimate 0.47 m off through.  2: the
# noise a provisional gate allows.)
_MISFIT_P = 0.001
_MISFIT_NOISE_FACTOR = 2.0
# An impact estimate needs the detection off the prediction within this sine of vertical.
_VERTICAL_SINE = 0.5
_IMPACT_REACH = 5.0
# A detection within the gate but beyond this chi-square (2 d.o.f., p ~ 5e-5) waits for the
# next detection before it is fitted (see _check).
_DOUBT = 20.0
# A velocity jump at an impact is taken as one only up to twice the ball's speed (a bounce or
# a hit reverses it at most) plus this [m/s] (see _jump_plausible): a stray detection next
# to an impact moved the path by 19-51 m/s times the time since the last fitted frame (the
# stray runs); the real sessions' bounces and hits by at most 20 m/s, twice their speed plus
# 7 m/s, the simulated bounces by 9-13 m/s.
_JUMP_MARGIN_MPS = 15.0


# A detection to fit: (stamp [ns], camera index, rows (2, 3), right-hand sides (2,), weight).
_Frame: TypeAlias = tuple[int, int, np.ndarray, np.ndarray, float]
# A path: (reference stamp [ns], beta (m,), covariance (m, m) per px^2 (m = 9 without the
# jump's coefficients, or 12), impact stamp or None, beta as 12 floats).
_Path: TypeAlias = tuple[int, np.ndarray, np.ndarray, int | None, list[float]]
# A camera's residual: (stamp [ns], segment, standardized residual (two floats) [px]).
_Residual: TypeAlias = tuple[int, int, tuple[float, float]]
# A path with an impact: (residual sum of squares, impact stamp [ns], beta (12,) at the
# newest frame, normal matrix (m, m) of its free coefficients).
_Break: TypeAlias = tuple[float, int, np.ndarray, np.ndarray]
# The fuser's state before an impact was confirmed (see _snapshot): attribute -> value.
_Snapshot: TypeAlias = dict[str, object]
# The attributes a snapshot keeps as they are (replaced, never changed in place).
_SNAPSHOT_ATTRIBUTES = ('_start', '_end', '_reference', '_weights_guessed', '_path', '_pending',
                        '_pending_innovation', '_pending_doubtful', '_replaced',
                        '_doubtful_path',
                        '_bounce_point', '_break', '_break_range', '_segment', '_spread',
                        '_lost')
# One window's solution: (columns: a count or indices, beta (m,), inverse (m, m)).
_Solution: TypeAlias = tuple[int | np.ndarray, np.ndarray, np.ndarray]


class _Solutions:
    """Solutions of windows sharing their columns: ``[k]`` is window k's :data:`_Solution`."""

    __slots__ = ('columns', 'betas', 'inverses')

    def __init__(self, columns: int | np.ndarray, betas: np.ndarray,
                 inverses: np.ndarray) -> None:
        self.columns, self.betas, self.inverses = columns, betas, inverses

    def __getitem__(self, k: int) -> _Solution:
        return self.columns, self.betas[k], self.inverses[k]


# Solved windows: (sizes, points (3 floats each), covariances (3 x 3 nested lists), solutions).
_Fits: TypeAlias = tuple[list, list, list, _Solutions | list[_Solution]]

_SIZES: dict[tuple[int, int], np.ndarray] = {}


# The position map: the position at a time is ``P @ beta`` with, per axis, the powers
# tau^0, tau^1, tau^2 of the time from the path's reference (in _SCALE_NS) at that axis's
# coefficients, and the time since the impact (zero before it) at the axis's velocity jump.
# _map_terms is its float form (the per-event paths), _position_map its array form; both
# write the same entries (tested), _position_row is the array form at one time.

def _map_terms(offset_ns: int, jump_offset_ns: int | None) -> tuple[float, float, float]:
    """
    Return the position map's entries at one time: ``tau``, ``tau^2`` and the jump's factor.

    :param offset_ns: time from the path's reference [ns]
    :param jump_offset_ns: time from the impact [ns], or None without one
    :return: ``(tau, tau^2, jump)`` with ``tau`` in units of _SCALE_NS and ``jump`` the time
        since the impact in the same units, 0.0 before it or without one
    """
    tau = offset_ns / _SCALE_NS
    jump = 0.0 if jump_offset_ns is None or jump_offset_ns <= 0 else jump_offset_ns / _SCALE_NS
    return tau, tau * tau, jump


def _position_map(offsets_ns: np.ndarray, jump_offsets_ns: np.ndarray | None) -> np.ndarray:
    """
    Return (N, 3, 12) maps from the coefficients to positions (the array form of _map_terms).

    :param offsets_ns: (N,) times from the path's reference [ns]
    :param jump_offsets_ns: (N,) times from the impact [ns], or None without one
    """
    tau = np.asarray(offsets_ns, dtype=float) / _SCALE_NS
    maps = np.zeros((len(tau), 3, 12))
    jump = None if jump_offsets_ns is None else \
        np.maximum(0.0, np.asarray(jump_offsets_ns, dtype=float) / _SCALE_NS)
    for axis in range(3):
        maps[:, axis, 3 * axis] = 1.0
        maps[:, axis, 3 * axis + 1] = tau
        maps[:, axis, 3 * axis + 2] = tau * tau
        if jump is not None:
            maps[:, axis, 9 + axis] = jump
    return maps


def _position_row(offset_ns: int, jump_offset_ns: int | None) -> np.ndarray:
    """Return the (3, 12) position map at one time (:func:`_position_map` of one time)."""
    tau, tau2, jump = _map_terms(offset_ns, jump_offset_ns)
    row = np.zeros((3, 12))
    row[0, 0] = row[1, 3] = row[2, 6] = 1.0
    row[0, 1] = row[1, 4] = row[2, 7] = tau
    row[0, 2] = row[1, 5] = row[2, 8] = tau2
    if jump:
        row[0, 9] = row[1, 10] = row[2, 11] = jump
    return row


# The map from the coefficients to the position at the reference time (no impact before it).
_POSITION = _position_row(0, None)
_POSITION.flags.writeable = False


def _trace(fit: tuple) -> float:
    """Return the trace of a fit's position covariance (a (point, covariance, ...) tuple)."""
    covariance = fit[1]
    return covariance[0][0] + covariance[1][1] + covariance[2][2]


def _drifting(older: tuple[float, float] | None, newer: tuple[float, float] | None) -> bool:
    """Return True if two innovations [px] point the same way (30 degrees), not shrinking."""
    if older is None or newer is None:
        return False
    (o0, o1), (n0, n1) = older, newer
    size_older, size_newer = math.hypot(o0, o1), math.hypot(n0, n1)
    return size_older <= size_newer and \
        o0 * n0 + o1 * n1 >= _DRIFT_COSINE * size_older * size_newer


def _raise_singular(error: str, flag: int) -> None:
    """Raise numpy's error for a singular matrix (the call of :func:`_inverses`' errstate)."""
    raise np.linalg.LinAlgError('Singular matrix')


# The LAPACK routine np.linalg.inv calls, without its per-call Python layer.
_GUFUNC_INV: np.ufunc | None
try:
    from numpy.linalg import _umath_linalg
    _GUFUNC_INV = _umath_linalg.inv
except (ImportError, AttributeError):  # pragma: no cover (numpy 1.26 to 2.4 have it)
    _GUFUNC_INV = None
# numpy 1.x: that error state as the ufunc's ``extobj``, as numpy 1.26's own ``inv`` passes it
# (its ``np.errstate`` costs ~5 us); numpy 2 has no ``extobj`` and a cheap ``np.errstate``.
_EXTOBJ: list | None = None
if _GUFUNC_INV is not None and hasattr(np, 'geterrobj'):  # pragma: no cover (numpy 1.x)
    with np.errstate(invalid='call', over='ignore', divide='ignore', under='ignore'):
        _EXTOBJ = np.geterrobj()[:2] + [_raise_singular]


def _inverses(matrices: np.ndarray) -> np.ndarray:
    """
    Return ``np.linalg.inv(matrices)`` for a stack of float64 matrices, the same floats.

    The routine numpy's own ``inv`` calls, under the same error state (a singular matrix
    raises ``LinAlgError``; overflow, division and underflow are ignored), without the
    wrapper's type and shape checks (a few microseconds per event).

    :param matrices: (K, m, m) float64
    :raises np.linalg.LinAlgError: a matrix is singular
    """
    if _GUFUNC_INV is None:  # pragma: no cover
        return np.linalg.inv(matrices)
    if _EXTOBJ is not None:  # pragma: no cover (numpy 1.x)
        return _GUFUNC_INV(matrices, signature='d->d', extobj=_EXTOBJ)
    with np.errstate(call=_raise_singular, invalid='call', over='ignore', divide='ignore',
                     under='ignore'):
        return _GUFUNC_INV(matrices, signature='d->d')


def _sizes(count: int, windows: np.ndarray) -> np.ndarray:
    """Return the window sizes (ascending) for ``count`` frames: the nested ones and all."""
    key = (count, int(windows[-1]))
    sizes = _SIZES.get(key)
    if sizes is None:
        sizes = _SIZES[key] = np.append(windows[windows < count], count)
    return sizes


def _inverse_form(x: float, y: float, z: float, a: float, b: float, c: float, e: float,
                  f: float, i: float) -> float:
    """
    Return ``d^T S^-1 d`` for ``d = (x, y, z)`` and a symmetric ``S`` (zero if singular).

    ``S`` has the rows (a b c), (b e f), (c f i).
    """
    # The adjugate's entries (S^-1 = adjugate / determinant).
    adj_a, adj_b, adj_c = e * i - f * f, c * f - b * i, b * f - c * e
    adj_e, adj_f, adj_i = a * i - c * c, b * c - a * f, a * e - b * b
    determinant = a * adj_a + b * adj_b + c * adj_c
    if determinant == 0.0:
        return 0.0
    return (x * x * adj_a + y * y * adj_e + z * z * adj_i
            + 2.0 * (x * y * adj_b + x * z * adj_c + y * z * adj_f)) / determinant


def _standardized(rows: list, rhs: list, weight: float, point: list,
                  covariance: list) -> tuple[float, float]:
    """
    Return a frame's residual (two floats) [px] over sqrt(1 - leverage) in a fit.

    The frame's design rows are ``weight * rows @ position`` (position: the map from the
    fit's coefficients to the position at the frame's stamp), so its residual and leverage
    need only the fitted position there and its covariance.

    :param rows: the frame's rows (2 x 3), ``rhs`` their right-hand sides (2)
    :param weight: the frame's weight [px/m]
    :param point: the fitted position (3) [m] at the frame's stamp
    :param covariance: its covariance per px^2 (3 x 3)
    """
    x, y, z = point
    (c00, c01, c02), (c10, c11, c12), (c20, c21, c22) = covariance
    (a0, a1, a2), (b0, b1, b2) = rows
    quadratic = (a0 * (c00 * a0 + c01 * a1 + c02 * a2) + a1 * (c10 * a0 + c11 * a1 + c12 * a2)
                 + a2 * (c20 * a0 + c21 * a1 + c22 * a2)
                 + b0 * (c00 * b0 + c01 * b1 + c02 * b2) + b1 * (c10 * b0 + c11 * b1 + c12 * b2)
                 + b2 * (c20 * b0 + c21 * b1 + c22 * b2))
    leverage = min(0.95, weight * weight * quadratic / 2.0)
    scale = math.sqrt(1.0 - leverage)
    return (weight * (a0 * x + a1 * y + a2 * z - rhs[0]) / scale,
            weight * (b0 * x + b1 * y + b2 * z - rhs[1]) / scale)


class TrajectoryFuser(GatedEstimator):
    """
    Causal multi-camera trajectory fit: one observation in, at most one estimate out.

    Same interface as :class:`pseudo_stereo_ros.fusion.Fuser` (``update``, ``process``,
    ``reset``, ``stats``, ``gate``, ``session``, ``off_timeline``, ``camera_names``,
    ``max_gap_ns``, ``sync_tolerance_ns``).

    :param cameras: the calibrated cameras (two or more; a sequence or a mapping name -> camera)
    :param sync_tolerance_ns: observations of two cameras closer than this are one instant
        for the input gate and the paper method's stand-in (a flight's first frames) [ns]
        (default 1 ms; never more than a quarter of the measured frame period: the input
        gate's).  The fit itself estimates at every stamp: :meth:`process` keeps one
        estimate per distinct stamp (the later, which saw both, at an equal stamp), as the
        node publishes one per shutter event
    :param max_gap_ns: upper bound of every camera's max gap (each uses at most 4.5 of its
        measured frame periods): an estimate needs two cameras with a detection within
        their max gap, and a pause of the rig longer than that starts a new flight [ns]
        (default 0.1 s)
    :param image_margin: see :class:`pseudo_stereo_ros.fusion.Fuser` (the shared input rules)
    :param max_speed_mps: see :class:`pseudo_stereo_ros.fusion.Fuser` (the shared
        plausibility gate) [m/s]
    :param workspace_min_m: see :class:`pseudo_stereo_ros.fusion.Fuser` [m]
    :param workspace_max_m: see :class:`pseudo_stereo_ros.fusion.Fuser` [m]
    :param max_window_s: longest window of the fit [s]
    :param consistency: Lepski's chi-square bound (3 d.o.f.) between windows' estimates
        among constant-acceleration fits
    :param innovation_gate: chi-square bound (2 d.o.f.) beyond which a detection is pending
    :param min_sigma_px: floor of the measured detection noise [px]
    :param max_uncertainty: largest estimate standard deviation in pixels of the newest
        camera per pixel of detection noise
    :param order: 2 (constant acceleration, default) or 1 (constant velocity)
    :raises FuserConfigError: an invalid option, naming it
    """

    method = 'trajectory'
    methods = ('trajectory',)
    drop_reasons = DROP_REASONS

    def __init__(self, cameras: Sequence[Camera] | Mapping[str, Camera], *,
                 sync_tolerance_ns: int | None = None, max_gap_ns: int | None = None,
                 image_margin: float | None = None,
                 max_speed_mps: float | None = DEFAULT_MAX_SPEED_MPS,
                 workspace_min_m: Sequence[float] | None = None,
                 workspace_max_m: Sequence[float] | None = None,
                 max_window_s: float = DEFAULT_MAX_WINDOW_S,
                 consistency: float = DEFAULT_CONSISTENCY,
                 innovation_gate: float = DEFAULT_GATE,
                 min_sigma_px: float = DEFAULT_MIN_SIGMA_PX,
                 max_uncertainty: float = DEFAULT_MAX_UNCERTAINTY, order: int = 2,
                 pending_estimate: str = 'impact') -> None:
        super().__init__(cameras, sync_tolerance_ns=sync_tolerance_ns, max_gap_ns=max_gap_ns,
                         image_margin=image_margin, max_speed_mps=max_speed_mps,
                         workspace_min_m=workspace_min_m, workspace_max_m=workspace_max_m)
        cameras = self.cameras
        names = self.camera_names
        # Counts beyond the shared ones (:attr:`stats`): ``resets``, ``late``, ``breaks``
        # (impacts), ``outlier`` (detections judged stray), ``predicted`` (estimates at
        # pending detections), ``restarts`` (path lost, fitted afresh); see DROP_REASONS.
        for name, value in (('max_window_s', max_window_s), ('consistency', consistency),
                            ('innovation_gate', innovation_gate), ('min_sigma_px', min_sigma_px),
                            ('max_uncertainty', max_uncertainty)):
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise FuserConfigError(f'{name} must be a finite number > 0, got {value!r}')
        if order not in (1, 2):
            raise FuserConfigError(f'order must be 1 (constant velocity) or 2 (constant '
                                   f'acceleration), got {order!r}')
        if pending_estimate not in ('predicted', 'impact', 'none'):
            raise FuserConfigError(f'unknown pending_estimate {pending_estimate!r}')
        self.max_window_ns = int(round(max_window_s * 1e9))
        self.consistency = float(consistency)
        self.innovation_gate = float(innovation_gate)
        self.min_sigma_px = float(min_sigma_px)
        self.max_uncertainty = float(max_uncertainty)
        self.order = int(order)
        self.pending_estimate = pending_estimate
        self._names = names
        # Window sizes [frames]: each camera contributes as many frames as in a pair's windows
        # (more cameras must not shorten the windows' time spans).
        self._windows = np.unique(np.round(_WINDOWS * max(len(names), 2) / 2.0).astype(int))
        self._shortest, self._longest = int(self._windows[0]), int(self._windows[-1])
        # The constant-jerk fits' windows (see _jerk_fits): 13 to 40 frames of a pair.
        self._jerk_windows = tuple(int(round(size * max(len(names), 2) / 2.0))
                                   for size in _JERK_WINDOWS)
        self._cameras = {camera.name: camera for camera in cameras}
        self._index = {name: index for index, name in enumerate(names)}
        self._rotation = np.array([camera.R for camera in cameras], dtype=float)  # (C, 3, 3)
        self._center = np.array([camera.center for camera in cameras], dtype=float)  # (C, 3)
        # R @ centre per camera (plain floats): a detection's right-hand sides without numpy.
        self._rotated_center = [tuple(float(v) for v in rotation @ center)
                                for rotation, center in zip(self._rotation, self._center)]
        self._center_rows = [tuple(float(v) for v in center) for center in self._center]
        self._focal = np.array([math.sqrt(abs(camera.K[0, 0] * camera.K[1, 1]))
                                for camera in cameras])
        self._focal_list = self._focal.tolist()
        baseline = max(float(np.linalg.norm(a - b)) for a in self._center for b in self._center)
        #: Per camera, a recent depth of the ball [m]: weights of frames before any fit.
        self._depth = [max(baseline, 1e-3)] * len(cameras)
        # Frame store, time-ordered in [_start, _end).
        self._capacity = capacity = max(_CAPACITY, 2 * int(self._windows[-1]))
        self._stamp = np.zeros(capacity, dtype=np.int64)
        self._camera = np.zeros(capacity, dtype=np.int64)
        self._rows = np.zeros((capacity, 2, 3))
        self._rhs = np.zeros((capacity, 2))
        self._weight = np.ones(capacity)
        # Prefix sums of each frame's augmented normal matrix (the normal matrix and the
        # moment together: the design's rows extended by the right-hand side, see _AUGMENTED)
        # in the coefficients of a fixed reference stamp (_reference): a window's system is a
        # difference of two prefixes, moved to the event's time by a linear map (see _fit).
        # [i] sums frames [_start, i).
        self._prefix = np.zeros((capacity + 1, 13, 13))
        # Their leading 10 x 10 blocks (the fits without an impact), contiguous: a window's
        # system is then one subtraction of contiguous blocks, ready to multiply.
        self._prefix10 = np.zeros((capacity + 1, 10, 10))
        # The same for the constant-jerk fits (see _jerk_fits): the coefficients x0 .. x3,
        # y0 .. y3, z0 .. z3 (powers of tau per axis), then the right-hand side; no jump.
        self._prefix_jerk = np.zeros((capacity + 1, 13, 13))
        self._shift_jerk = np.eye(13)  # its change of time origin; _jerk_fits sets delta's
        # The change of time origin (tau -> tau - delta) in the augmented coefficients, per
        # number of unknowns (9 without an impact, 12 with one); _fit sets its delta entries.
        self._shift = {9: np.eye(10), 12: np.eye(13)}
        self._shift_t = {9: np.eye(10), 12: np.eye(13)}  # their transposes, contiguous
        # Per camera: rotation rows and the third row, as plain floats (a detection's rows).
        self._rotation_rows = [tuple(tuple(float(v) for v in row) for row in rotation)
                               for rotation in self._rotation]
        # The paper's method on the same admitted detections (sharing the input gate, none
        # of its own plausibility test: this fuser's applies): its estimate stands in while
        # the fit has fewer than _PAPER_SUPPORT frames (a flight's first frames, a path
        # lost), where the fit extrapolates from too little.  It sees only those frames.
        self._paper = Fuser(cameras, sync_tolerance_ns=sync_tolerance_ns, max_gap_ns=max_gap_ns,
                            image_margin=image_margin, max_speed_mps=None)
        self._paper.gate = self.gate
        #: The measured detection noise [px] (Rice's estimator), kept across flights.
        self.sigma_px: float | None = None
        self._sigma_count = 0
        # The noise detections are gated at [px]: None (not gated yet), provisional, then
        # sigma_px (see _SIGMA_MATURE).
        self._gate_sigma: float | None = None
        self._log_variance: float | None = None
        self._forget()

    def _forget(self) -> None:
        """Forget the flight (a new session): window, path, impacts (the noise is kept)."""
        super()._forget()
        self._paper._forget()
        # The newest admitted detections, given to the paper's method again at a restart.
        self._recent: deque[Admitted] = deque(maxlen=_RECENT)
        self._start = self._end = 0
        self._removed = False  # a fitted frame was removed at this event (_remove_misfit)
        self._reference: int | None = None  # stamp of the prefix sums' coefficients [ns]
        self._weights_guessed = True  # weights of a new flight's frames, before its first fit
        self._last: dict[str, int] = {}  # camera name -> its newest stamp
        self._path: _Path | None = None  # the path of the newest estimate
        self._pending: _Frame | None = None  # a detection not fitted yet
        # Its innovation (two floats) [px] against the path (None when its depth was not
        # positive).
        self._pending_innovation: tuple[float, float] | None = None
        # Whether it was within the gate (a doubtful one, fitted if the next one agrees).
        self._pending_doubtful = False
        # The detection it took the place of, judged stray (see _check), or None.
        self._replaced: _Frame | None = None
        self._doubtful_path: _Path | None = None  # the path fitted with it
        # After a restart: the lost path and the stamp of its newest frame, which bound the
        # new path's first estimates (see _restart_from); None otherwise.
        self._lost: tuple[_Path, int] | None = None
        # A bounce's position at the frame that confirmed it, or None (_bounce_estimate).
        self._bounce_point: np.ndarray | None = None
        self._break: int | None = None  # stamp of the impact inside the window [ns], or None
        # (low, high) [ns] while the impact's time is being refined.
        self._break_range: tuple[int, int] | None = None
        # The bounce that explained the first three detections after an impact, which judges
        # the next ones until they are gated or one is stray (see _check): the frames before
        # it, the lower end of its time's range, its directions, the frames after it so far;
        # or None.
        self._bounce_check: tuple[tuple[np.ndarray, ...], int, np.ndarray,
                                  list[_Frame]] | None = None
        self._segment = 0  # counts impacts: residuals are compared within a segment only
        # An impact confirmed from two detections, until a third (or fourth) one after it
        # decides which of them was stray, if any (see _recheck_impact): the state before
        # it, the frames before it (stamps, cameras, rows, rhs, weights), the lower end of
        # its time's range, a bounce's directions there, and the frames after it so far.
        self._tentative: tuple[_Snapshot, tuple[np.ndarray, ...], int, np.ndarray,
                               list[_Frame]] | None = None
        # Running spread of accepted innovations (within the gate without the prediction's
        # own variance), per axis [px^2].
        self._spread: float | None = None
        # Camera index -> its newest residual in the fit.
        self._residual: dict[int, _Residual] = {}
        # Camera index -> (stamp, innovation or None) of its last detection taken as an outlier.
        self._rejected: dict[int, tuple[int, tuple[float, float] | None]] = {}
        # Camera index -> innovations of its detections taken as outliers since its newest
        # fitted frame (see _unheard).
        self._strays: dict[int, list[tuple[float, float] | None]] = {}
        # Camera index -> stamp of its detection before the newest (None: it had none).
        self._previous: dict[int, int | None] = {}
        # Camera index -> the same as _residual from the noise estimate's fixed-length fit.
        self._noise_residual: dict[int, _Residual] = {}

    # -- the method -----------------------------------------------------------------------------

    def _fuse(self, item: Admitted) -> Estimate | None:
        """Fit one admitted observation; return its plausible estimate, or None (counted)."""
        camera, stamp, _, _ = item.observation
        index = self._index[camera]
        self._previous[index] = self._last.get(camera)
        self._last[camera] = stamp
        # The fit's first frames (a flight's start, a restart): the paper's estimate (if any)
        # stands in for the fit's.  The paper's method sees the frames since the flight's
        # start; at a restart it is given again those the fit restarts from.
        recent = self._recent
        recent.append(item)
        supported = self._end - self._start + 1 >= _PAPER_SUPPORT
        paper = None if supported else self._paper._fuse(item)
        stats = self.stats
        dropped = [stats[reason] for reason in _FIT_DROPS]
        self._removed = False
        estimate = self._fit_frame(index, stamp, item.x, item.y, item.late, item.fresh)
        if self._end - self._start < _PAPER_SUPPORT:
            if supported and not self._removed:
                # The path was lost at this frame: the fit restarts from its frames.  (A
                # frame removed as an outlier shrinks the window too: not a lost path.)
                self._paper._forget()
                first = int(self._stamp[self._start])
                for earlier in recent:
                    if earlier.observation.stamp_ns >= first:
                        paper = self._paper._fuse(earlier)
            if paper is not None:
                if estimate is None:  # not dropped after all: uncount the fit's reason
                    for reason, count in zip(_FIT_DROPS, dropped):
                        if stats[reason] > count:
                            stats[reason] -= 1
                estimate = paper
        if estimate is None:
            return None
        plausibility = self.plausibility
        plausibility.window_ns = self.gate.rig_gap_ns  # "recent": a few frame periods
        if not plausibility.accept(stamp, estimate[2:5]):
            return None
        self.stats['estimates'] += 1
        if estimate.kind == 'predicted':
            self.stats['predicted'] += 1
        return estimate

    def _supersedes(self, estimate: Estimate, previous: Estimate) -> bool:
        """
        Replace only an estimate at the same stamp: the fit evaluates at each event's stamp.

        Two cameras' shutters a fraction of a millisecond apart are two shutter events
        with two estimates (keeping only the later lost up to 13 % of the events in
        jittered cases, where the node published both).
        """
        return estimate.stamp_ns == previous.stamp_ns

    def _fit_frame(self, index: int, stamp: int, x: float, y: float, late: bool,
                   fresh: bool = False) -> Estimate | None:
        """
        Add a detection (normalized x, y) to the fit; return the estimate or None.

        A ``late`` detection (older than the newest frame fitted) is fitted without gating
        unless it is off the path across what a drift explains (:meth:`_seen_off_path`;
        then it is an outlier, its estimate the prediction at its stamp).  A ``fresh`` one
        (its camera was silent for longer than its max gap) is fitted without gating:
        while the other cameras saw the ball alone
        the path drifted where they cannot see (along their rays), and they would judge
        the returning camera's detections stray; unless another camera's detection is
        pending and the two confirm an impact (a camera silent across a bounce), or it is
        off the path across what such a drift explains (:meth:`_seen_off_path`).  A camera
        the path lost although its detections arrived counts as fresh (:meth:`_unheard`).
        """
        if not (fresh or late):
            fresh = self._unheard(index, stamp)
        (a0, a1, a2), (b0, b1, b2), (c0, c1, c2) = self._rotation_rows[index]
        r0, r1, r2 = self._rotated_center[index]
        equations = ((a0 - x * c0, a1 - x * c1, a2 - x * c2),
                     (b0 - y * c0, b1 - y * c1, b2 - y * c2), (r0 - x * r2, r1 - y * r2))
        rows = np.array(equations[:2])
        rhs = np.array(equations[2])
        if fresh and not late and self._path is not None and \
                self._seen_off_path(index, stamp, equations):
            fresh = False  # off the path where the drift cannot explain it: judged
        if self._tentative is not None:
            held = self._recheck_impact(index, stamp, rows, rhs, late or fresh)
            if held is not None:
                return held[0]
        pending = self._pending
        if pending is not None and self._pending_doubtful and not late:
            # A doubtful detection waits for this one (see _doubtful_estimate): an impact if
            # both disagree with the path before it and a jump explains them (this one judged
            # without gating if its camera was silent); otherwise it is fitted as it would
            # have been at once, and this one judged against the path with it.
            if stamp - pending[0] <= self.gate.rig_gap_ns and self._break_range is None:
                before = self._predict_point(stamp)  # the path before the doubtful one
                depth = c0 * before[0] + c1 * before[1] + c2 * before[2] - r2
                frame: _Frame = (stamp, index, rows, rhs, self._focal_list[index] / (
                    depth if depth > 0.0 else self._depth[index]))
                if fresh or not self._statistic(stamp, index, before,
                                                equations)[0] <= self.innovation_gate:
                    if self._confirm_break(frame):
                        return self._estimate_at_break(stamp, index)
            self._insert(pending)
            self._pending = None
            self._path = self._doubtful_path
        depth = self._depth[index]
        prediction = None
        if self._path is not None:
            prediction = self._predict_point(stamp)
            predicted = c0 * prediction[0] + c1 * prediction[1] + c2 * prediction[2] - r2
            if predicted > 0.0:
                depth = predicted
        frame = (stamp, index, rows, rhs, self._focal_list[index] / depth)
        if late:
            self.stats['late'] += 1  # fitted without gating, estimated at its own stamp
            if not fresh and prediction is not None and self._pending is None and \
                    self._tentative is None and self._break_range is None and \
                    self._seen_off_path(index, stamp, equations):
                # Off the path at its own stamp where no drift explains it (a wrong blob
                # arriving after a newer detection: streamed near-synchronized cameras with
                # different latencies deliver many of one camera's detections late).
                self.stats['outlier'] += 1
                x, y, z = prediction
                return Estimate(stamp, self._names[index], x, y, z, 'predicted')
        elif fresh:
            # The path is corrected by this detection, not judged; but if another camera's
            # detection is pending, the two may show an impact while this camera was silent.
            if self._pending is not None and self._break_range is None and \
                    stamp - self._pending[0] <= self.gate.rig_gap_ns and \
                    self._confirm_break(frame):
                return self._estimate_at_break(stamp, index)
            self._pending = None
        else:
            verdict = self._check(frame, prediction, equations)
            if verdict in ('pending', 'stray'):
                return self._pending_estimate(frame)
            if verdict == 'replaced':
                # Where the ball is depends on which of the two was stray: no estimate.
                self.stats['pending'] += 1
                return None
            if verdict == 'inserted':
                return self._estimate_at_break(stamp, index)
            if verdict == 'doubtful':
                return self._doubtful_estimate(frame)
        self._insert(frame)
        if self._end - self._start == _GATE_SUPPORT:
            self._check_young_window(stamp)
        return self._estimate(stamp, index)

    def _check_young_window(self, stamp: int) -> None:
        """
        Drop a wrong blob from a window that just reached the frames detections are gated by.

        A flight's or a restart's first frames are fitted without gating, and a restart
        starts from detections off the path, often one a wrong blob: fitted, it bent the
        restarted path (under bursts of wrong blobs 4 of 240 runs over 0.5 m more).  Where a
        velocity or free fall misfits the window and one frame's removal alone explains it
        (:meth:`_remove_misfit`), that frame is an outlier.  Not across an impact.
        """
        if self._break is None:
            first = self._start
            squares, without = self._fixed_squares(stamp, first, self._end)
            self._remove_misfit(first, min(squares), without)

    def _seen_off_path(self, index: int, stamp: int,
                       equations: tuple[tuple[float, ...], ...]) -> bool:
        """
        Return True if a detection is off the path across what a drift could explain.

        A fresh detection is fitted without gating because, while one other camera alone
        carried the path, the path drifted along that camera's rays, where it cannot see
        (and a late one, because newer detections of the other camera moved the path).
        Such a drift moves the prediction, in this camera's image, along the image of the
        carrier's ray through it (the epipolar line); across that line the path is still
        known.  Beyond the gate there, the detection is judged as any other (a camera
        silent across a bounce: its first detection after the impact, fitted without
        gating into the falling ball's path, put the path 1.7 m off; judged, it confirms
        the impact with the next detection).  With two or more other cameras carrying the
        path, or before detections are gated, a fresh detection stays unjudged.  A late
        detection off the path there is taken as an outlier (see :meth:`_fit_frame`).
        """
        if self._gate_sigma is None or self._end - self._start < _GATE_SUPPORT:
            return False
        carriers = self._carried_since(index)[1]
        if len(carriers) != 1:
            return False
        prediction = self._predict_point(stamp)
        statistic, found, _, _ = self._statistic(stamp, index, prediction, equations)
        if found is None or not statistic > self.innovation_gate:
            return False
        along = self._carrier_direction(index, int(carriers[0]), prediction, equations)
        if along is None:
            return False
        norm2 = float(along @ along)
        offset = np.array(found)
        size2 = float(offset @ offset)
        if not norm2 > 0.0 or not size2 > 0.0:
            return False
        across = offset - along * float(offset @ along) / norm2
        # The statistic's share across the line (the spread taken as the same both ways).
        return statistic * float(across @ across) / size2 > self.innovation_gate

    def _carrier_direction(self, index: int, carrier: int,
                           prediction: tuple[float, float, float],
                           equations: tuple[tuple[float, ...], ...]) -> np.ndarray | None:
        """
        Return the image direction (2,) of a carrier camera's ray through a point.

        In camera ``index``'s image (the Jacobian of the detection's innovation at the
        point, its rows from ``equations``, times the point's offset from the carrier's
        centre; only its direction means anything): where the path drifts while the
        carrier alone sees the ball (along the epipolar line).  None behind the camera.
        """
        point = np.array(prediction)
        innovation = self._innovation(index, np.array(equations[:2]), np.array(equations[2]),
                                      point)
        if innovation is None:
            return None
        return innovation[1] @ (point - self._center[carrier])

    def _along_carrier(self, index: int, prediction: tuple[float, float, float],
                       equations: tuple[tuple[float, ...], ...],
                       found: tuple[float, float]) -> bool:
        """
        Return whether an innovation [px] lies where a drift of the path can explain it.

        True unless one other camera alone carried the path since this camera's newest
        frame in the window and the innovation is off the image of its ray through the
        prediction by more than 45 degrees (``_ALONG_COSINE``).  (With two or more, the
        rule it serves in :meth:`_check` stays as it was.)
        """
        carriers = self._carried_since(index)[1]
        if len(carriers) != 1:
            return True
        along = self._carrier_direction(index, int(carriers[0]), prediction, equations)
        if along is None:
            return True
        size = math.hypot(*found) * math.hypot(float(along[0]), float(along[1]))
        return abs(found[0] * float(along[0]) + found[1] * float(along[1])) >= \
            _ALONG_COSINE * size

    def _judged_stray(self, index: int, stamp: int,
                      innovation: tuple[float, float] | None) -> None:
        """Record a camera's detection taken as an outlier (not fitted)."""
        self._rejected[index] = (stamp, innovation)
        self._strays.setdefault(index, []).append(innovation)

    def _unheard(self, index: int, stamp: int) -> bool:
        """
        Return True if the path has lost this camera: it drifted off that camera's rays.

        The gate's ``fresh`` measures a camera's silence by the detections that arrived; the
        path knows only those it fitted.  Where this camera's detections were taken as
        outliers over its max gap while one other camera alone carried the path, the depth
        along that camera's rays drifted, and each detection of this camera was further off
        than the one before, the same way, and taken as an outlier too (near-synchronized
        cameras with jitter and drops at 60 fps: 0.22 m off before a restart).  Then its
        next detection corrects the path, as a returning camera's does.  Stray detections
        scatter: the last two taken as outliers must point the same way (within 30
        degrees), the newer not the smaller; and with two other cameras the depth is known.
        """
        previous = self._previous.get(index)
        gap = self.gate.max_gaps[self._names[index]]
        rejected = self._rejected.get(index)
        if previous is None or stamp - previous > gap or rejected is None or \
                rejected[0] != previous:
            # Silent by the gate's measure too, a first detection, or a previous one not
            # taken as an outlier (fitted, or still pending).
            return False
        strays = self._strays.get(index, [])
        if len(strays) < 2 or not _drifting(strays[-2], strays[-1]):
            return False
        last, carriers = self._carried_since(index)
        return last is not None and stamp - last > gap and len(carriers) <= 1

    def _drifted(self, index: int, stamp: int, prediction: tuple[float, float, float],
                 equations: tuple[tuple[float, ...], ...], found: tuple[float, float]) -> bool:
        """
        Return True if a camera back from missed frames is off the path only by its drift.

        While a camera misses frames (its previous detection fitted, more than
        ``_MISSED_PERIODS`` of its periods ago) and one other camera alone carries the
        path, the path's depth along that camera's rays is extrapolated from this camera's
        older frames.  Where the path turns more than a constant velocity or a free fall
        explains (the spiral's 1.5 g), it drifts there by about half that acceleration
        times the time squared: 23-31 mm in 67 ms at 30 fps, 20-40 times the innovations'
        spread at 0.05 px rounding.  The gate judged such a detection stray, the carrier's
        next detection (blind along its own rays) agreed with the drifted path, and the
        drift grew until a restart (up to 79 mm off, 0.75-1.19x paper).  Such a detection
        is fitted where its innovation lies along the image of the carrier's ray (within
        45 degrees, :meth:`_along_carrier`; a valid one was 26 degrees off it, 7 px, so
        the gate across that line is too strict) and within that drift, ``a * t**2 / 2``:
        ``a`` the smaller of the path's acceleration and its difference from gravity (a
        straight line or a free fall does not drift: with the whole acceleration, wrong
        blobs 2-6 px off after a missed frame of a falling ball were fitted, 43-164 mm
        off, and after a silence beyond the max gap 0.35 m; at most
        ``_DRIFT_MAX_ACCELERATION``), ``t`` the time since this camera's newest frame, in
        pixels at the predicted depth.  (A camera silent beyond its max gap is fresh and
        comes here only off the path across the line, :meth:`_seen_off_path`; capping
        ``t`` at the max gap rejected a valid one, 7 px and 134 ms, on a spiral.)  A wrong
        blob (5-60 px, or a burst's 4 px and growing) rarely lies there.
        """
        period = self.gate.period_ns(self._names[index])
        last, carriers = self._carried_since(index)
        if period is None or last is None or last != self._previous.get(index) or \
                stamp - last <= _MISSED_PERIODS * period or len(carriers) != 1 or \
                not self._along_carrier(index, prediction, equations, found):
            return False
        assert self._path is not None, 'detections are judged against a path'
        # What the lower-order models (a constant velocity, a free fall) leave unexplained of
        # the path's acceleration [m per (0.1 s)^2, then m/s^2].
        x2, y2, z2 = (self._path[4][k] for k in _ACCELERATION)
        unexplained = min(math.hypot(x2 - fx, y2 - fy, z2 - fz) for fx, fy, fz in _FIXED_LIST)
        acceleration = min(_DRIFT_MAX_ACCELERATION,
                           2.0 * unexplained / (_SCALE_NS * 1e-9) ** 2)
        depth = float(self._rotation[index, 2] @ (np.array(prediction) - self._center[index]))
        since = (stamp - last) * 1e-9
        return depth > 0.0 and math.hypot(*found) * depth <= \
            0.5 * acceleration * since * since * self._focal_list[index]

    def _carried_since(self, index: int) -> tuple[int | None, np.ndarray]:
        """
        Return the stamp of a camera's newest frame in the window and who carried the path since.

        :return: ``(stamp [ns] or None without one, the other cameras' indices fitted after
            it, or in the whole window without one)``
        """
        start, end = self._start, self._end
        cameras = self._camera[start:end]
        mine = np.flatnonzero(cameras == index)
        if not len(mine):
            return None, np.unique(cameras[cameras != index])
        return int(self._stamp[start + mine[-1]]), np.unique(cameras[mine[-1] + 1:])

    # -- frames ---------------------------------------------------------------------------------

    def _arrays(self) -> tuple[np.ndarray, ...]:
        return self._stamp, self._camera, self._rows, self._rhs, self._weight

    def _insert(self, frame: _Frame) -> None:
        """Insert a frame in time order and forget frames beyond the longest window."""
        stamp, index, rows, rhs, weight = frame
        rebuild = None
        if self._end == self._capacity:
            count = self._end - self._start
            for array in self._arrays():
                array[:count] = array[self._start:self._end].copy()
            self._start, self._end = 0, count
            rebuild = 0
        end = self._end
        position = end
        if end > self._start and stamp < self._stamp[end - 1]:
            position = self._start + int(np.searchsorted(self._stamp[self._start:end], stamp))
            for array in self._arrays():
                array[position + 1:end + 1] = array[position:end].copy()
            rebuild = position if rebuild is None else rebuild
        self._strays.pop(index, None)  # fitted again
        self._stamp[position] = stamp
        self._camera[position] = index
        self._rows[position] = rows
        self._rhs[position] = rhs
        self._weight[position] = weight
        self._end = end = end + 1
        start = max(self._start, end - self._longest)
        newest = stamp if position == end - 1 else int(self._stamp[end - 1])
        oldest = newest - self.max_window_ns
        stamps = self._stamp
        while start < end and stamps[start] < oldest:  # usually one step at most
            start += 1
        self._start = min(start, end - 1)
        if self._reference is None or newest - self._reference > self.max_window_ns + _REANCHOR_NS:
            self._reference = int(self._stamp[self._start])
            rebuild = self._start
        if rebuild is None:
            rebuild = position
        self._rebuild(max(rebuild, self._start))

    def _remove(self, position: int) -> None:
        """Remove the frame at ``position`` of the store (an outlier found afterwards)."""
        end = self._end
        for array in self._arrays():
            array[position:end - 1] = array[position + 1:end].copy()
        self._end = end - 1
        if position < self._end:
            self._rebuild(max(position, self._start))

    def _rebuild(self, first: int) -> None:
        """Recompute the prefix sums from frame ``first`` on (``first == _start``: from 0)."""
        end = self._end
        reference = self._reference
        assert reference is not None, 'the window holds frames, so _insert set the reference'
        prefix = self._prefix
        if first == end - 1 and first > self._start:  # the common case: one frame appended
            stamp = int(self._stamp[first])
            tau, tau2, jump = _map_terms(stamp - reference,
                                         None if self._break is None else stamp - self._break)
            w = float(self._weight[first])
            (a0, a1, a2), (b0, b1, b2) = self._rows[first].tolist()
            q0, q1 = self._rhs[first].tolist()
            # rows (2, 3) times the (3, 12) position map: per axis the powers of tau, then
            # the right-hand side and the jump's columns (the order of _AUGMENTED).
            design = np.array((
                (a0 * w, a0 * tau * w, a0 * tau2 * w, a1 * w, a1 * tau * w, a1 * tau2 * w,
                 a2 * w, a2 * tau * w, a2 * tau2 * w, q0 * w,
                 a0 * jump * w if jump else 0.0, a1 * jump * w if jump else 0.0,
                 a2 * jump * w if jump else 0.0),
                (b0 * w, b0 * tau * w, b0 * tau2 * w, b1 * w, b1 * tau * w, b1 * tau2 * w,
                 b2 * w, b2 * tau * w, b2 * tau2 * w, q1 * w,
                 b0 * jump * w if jump else 0.0, b1 * jump * w if jump else 0.0,
                 b2 * jump * w if jump else 0.0)))
            np.add(prefix[first], design.T @ design, out=prefix[end])
            self._prefix10[end] = prefix[end, :10, :10]
            if self.order == 2:  # the jerk fits' (see _jerk_fits)
                tau3 = tau2 * tau
                design = np.array((
                    (a0 * w, a0 * tau * w, a0 * tau2 * w, a0 * tau3 * w, a1 * w, a1 * tau * w,
                     a1 * tau2 * w, a1 * tau3 * w, a2 * w, a2 * tau * w, a2 * tau2 * w,
                     a2 * tau3 * w, q0 * w),
                    (b0 * w, b0 * tau * w, b0 * tau2 * w, b0 * tau3 * w, b1 * w, b1 * tau * w,
                     b1 * tau2 * w, b1 * tau3 * w, b2 * w, b2 * tau * w, b2 * tau2 * w,
                     b2 * tau3 * w, q1 * w)))
                np.add(self._prefix_jerk[first], design.T @ design,
                       out=self._prefix_jerk[end])
            return
        if first == self._start:
            prefix[first] = 0.0
        stamps = self._stamp[first:end]
        jumps = None if self._break is None else stamps - self._break
        maps = _position_map(stamps - reference, jumps)
        weight = self._weight[first:end, None, None]
        design = np.empty((end - first, 2, 13))
        design[:, :, _AUGMENTED[:12]] = np.einsum('nra,nam->nrm', self._rows[first:end], maps)
        design[:, :, 9] = self._rhs[first:end]
        design *= weight
        np.cumsum(design.transpose(0, 2, 1) @ design, axis=0, out=prefix[first + 1:end + 1])
        prefix[first + 1:end + 1] += prefix[first]
        self._prefix10[first:end + 1] = prefix[first:end + 1, :10, :10]
        if self.order != 2:
            return
        # The constant-jerk fits' prefix sums: the rows times the powers of tau per axis.
        prefix = self._prefix_jerk
        if first == self._start:
            prefix[first] = 0.0
        taus = ((stamps - reference) / _SCALE_NS)[:, None, None]
        rows = self._rows[first:end] * weight
        design = np.empty((end - first, 2, 13))
        design[:, :, 0:12:4] = rows
        for power in range(1, 4):
            rows = rows * taus
            design[:, :, power:12:4] = rows
        design[:, :, 12] = self._rhs[first:end] * weight[:, :, 0]
        np.cumsum(design.transpose(0, 2, 1) @ design, axis=0, out=prefix[first + 1:end + 1])
        prefix[first + 1:end + 1] += prefix[first]

    # -- the path -------------------------------------------------------------------------------

    def _predict(self, stamp: int) -> tuple[np.ndarray, np.ndarray]:
        """Return the predicted position (3,) [m] and its covariance (3, 3) per px^2."""
        assert self._path is not None, 'predictions are made only once a path was fitted'
        t_ref, beta, covariance, t_break, _ = self._path
        row = _position_row(stamp - t_ref, None if t_break is None else stamp - t_break)
        row = row[:, :len(beta)]
        return row @ beta, row @ covariance @ row.T

    def _predict_point(self, stamp: int) -> tuple[float, float, float]:
        """Return the predicted position [m] as floats (the fast path of :meth:`_predict`)."""
        assert self._path is not None, 'predictions are made only once a path was fitted'
        t_ref, _, _, t_break, coefficients = self._path
        tau, tau2, jump = _map_terms(stamp - t_ref, None if t_break is None else stamp - t_break)
        x0, x1, x2, y0, y1, y2, z0, z1, z2, jx, jy, jz = coefficients
        x, y, z = x0 + x1 * tau + x2 * tau2, y0 + y1 * tau + y2 * tau2, z0 + z1 * tau + z2 * tau2
        if jump:
            x, y, z = x + jx * jump, y + jy * jump, z + jz * jump
        return x, y, z

    def _innovation(self, index: int, rows: np.ndarray, rhs: np.ndarray,
                    point: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """Return (innovation (2,) px, Jacobian (2, 3) px/m) of a detection, or None."""
        depth = float(self._rotation[index, 2] @ (point - self._center[index]))
        if not depth > 0.0:
            return None
        scale = self._focal[index] / depth
        return (rows @ point - rhs) * scale, rows * scale

    # -- impacts and outliers -------------------------------------------------------------------

    def _statistic(self, stamp: int, index: int, prediction: tuple[float, float, float],
                   equations: tuple[tuple[float, ...], ...]
                   ) -> tuple[float, tuple[float, float] | None, float, bool]:
        """
        Return a detection's innovation statistic (chi-square, 2 d.o.f.) against the path.

        :return: ``(statistic, innovation (two floats) [px] or None, its mean square
            [px^2], whether the prediction's own variance entered)``; the statistic is
            infinite (and the innovation None) where the prediction is not in front of
            the camera
        """
        x, y, z = prediction
        (c0, c1, c2), (d0, d1, d2) = self._center_rows[index], self._rotation_rows[index][2]
        depth = (x - c0) * d0 + (y - c1) * d1 + (z - c2) * d2
        found = None  # the innovation [px] (two floats)
        statistic = squared = math.inf
        uncertain = False
        if depth > 0.0:
            # The innovation and its Jacobian (rows * scale) [px/m].
            scale = self._focal_list[index] / depth
            (g0, g1, g2), (h0, h1, h2), (q0, q1) = equations
            found = ((g0 * x + g1 * y + g2 * z - q0) * scale,
                     (h0 * x + h1 * y + h2 * z - q1) * scale)
            assert self._gate_sigma is not None, 'detections are gated with a noise level'
            sigma2 = self._gate_sigma ** 2
            noise = sigma2  # the detection's variance per axis [px^2]
            innovation_x, innovation_y = found
            last = self._residual.get(index)
            if last is not None and last[1] == self._segment and \
                    stamp - last[0] <= self.gate.max_gaps[self._names[index]]:
                # Against this camera's last residual: slowly varying biases (calibration)
                # cancel.
                innovation_x -= last[2][0]
                innovation_y -= last[2][1]
                noise += sigma2
            squared = (innovation_x * innovation_x + innovation_y * innovation_y) / 2.0
            # The expected spread: the noise, the prediction's own variance (in the image) and
            # at least the running spread of accepted innovations.  The prediction's variance
            # only raises it: it is needed only where the detection fails the gate without it.
            spread = noise if self._spread is None else max(noise, self._spread)
            statistic = 2.0 * squared / spread
            if not statistic <= self.innovation_gate:
                uncertain = True
                spread = noise + sigma2 * scale * scale * \
                    self._predicted_spread(stamp, equations) / 2.0
                if self._spread is not None:
                    spread = max(spread, self._spread)
                statistic = 2.0 * squared / spread
        return statistic, found, squared, uncertain

    def _check(self, frame: _Frame, prediction: tuple[float, float, float] | None,
               equations: tuple[tuple[float, ...], ...]) -> str:
        """
        Classify a new detection: 'ok', 'doubtful', 'pending', 'replaced', 'stray', 'inserted'.

        'doubtful': within the gate but beyond :data:`_DOUBT` (see :meth:`_doubtful_estimate`).
        'replaced': pending in the place of the pending one, judged stray.  'stray': an
        outlier, not pending.  'inserted': an impact confirmed, or the path restarted.

        :param frame: the detection's frame
        :param prediction: the position predicted at its stamp (:meth:`_predict_point`)
        :param equations: the frame's rows and right-hand sides as floats (2 x 3, 2)
        """
        stamp, index = frame[0], frame[1]
        if prediction is None or self._gate_sigma is None or \
                self._end - self._start < _GATE_SUPPORT:
            # No path yet, the noise not known yet, or a path from too few frames to judge a
            # detection by (a flight's first frames).
            return 'ok'
        refining = self._break_range is not None
        if self._break_range is not None:
            after = self._camera[self._start:self._end][
                self._stamp[self._start:self._end] > self._break_range[1]]
            if len(after) < _GATE_AFTER_IMPACT or np.all(after == after[0]):
                # An impact just confirmed: the jump is known from too few frames, or from
                # one camera only (along its rays the path is not known yet).
                # Once a bounce explained the first three (_recheck_impact), it must explain
                # this one with them: a wrong blob right after an impact, fitted, bent the
                # jump's path by up to 1.1 m (synchronized cameras, sweep --strays).
                # It stops at the first one it judges stray: that one is not fitted, so no
                # more frames follow the impact, and a wrong bounce (a blob among its three)
                # would judge every later detection stray.
                check, self._bounce_check = self._bounce_check, None
                if check is not None:
                    before, low, directions, frames = check
                    if self._jump_chi2(before, low, frames + [frame], directions) is None:
                        self.stats['outlier'] += 1
                        return 'stray'
                    self._bounce_check = (before, low, directions, frames + [frame])
                return 'ok'
        statistic, found, squared, uncertain = self._statistic(stamp, index, prediction,
                                                               equations)
        # The running spread learns only from detections within the gate without the path's
        # own uncertainty: a bounce the path missed let a 28 px innovation in that way, the
        # spread grew to 46 px^2, and 200 ms later a wrong blob passed (0.53 m off).  And a
        # sample counts at most _SPREAD_CLIP times the spread so far: a wrong blob within the
        # gate (9 px, while the noise was provisional) raised it 27-fold at once, and later
        # blobs of 11 and 25 px passed (three cameras: 0.93 m off); a bias that grows (a
        # curve the fit misses) still nearly doubles it at every sample.
        if statistic <= self.innovation_gate and not refining and not uncertain:
            # (A spread of zero, from a first sample of zero, would stay zero: restarted.)
            self._spread = squared if not self._spread else self._spread + \
                _SPREAD_ALPHA * (min(squared, _SPREAD_CLIP * self._spread) - self._spread)
        pending = self._pending
        # Two off the path in a row: this one agreeing only thanks to the path's own
        # uncertainty does not make both stray (the path may be the one off).
        agrees = statistic <= self.innovation_gate and not (
            uncertain and pending is not None and self._replaced is not None)
        if agrees:
            if pending is not None:
                self.stats['outlier'] += 1  # the path goes on: the pending one was stray
                self._judged_stray(pending[1], pending[0], self._pending_innovation)
                self._pending = None
                self._replaced = None
                return 'ok'
            # Within the gate but unlikely as noise (p ~ 5e-5) against a path known well
            # there: see _doubtful_estimate.  (Let in by the path's own uncertainty, or
            # while an impact's time is refined, the detection tells more than the path:
            # fitted.)
            return 'ok' if statistic <= _DOUBT or uncertain or refining or \
                self._sigma_count < _SIGMA_MATURE else 'doubtful'
        if found is not None and pending is None and \
                self._drifted(index, stamp, prediction, equations, found):
            # Back from a missed frame, off only by the drift of the path along the one
            # carrier's rays meanwhile: fitted, it corrects the path (judged stray, the
            # carrier agreed with the drifted path and the drift grew).
            return 'ok'
        rejected = self._rejected.get(index)
        if found is not None and rejected is not None and \
                rejected[0] == self._previous.get(index) and rejected[1] is not None and \
                math.hypot(found[0] - rejected[1][0], found[1] - rejected[1][1]) < \
                0.5 * math.hypot(*found) and \
                self._along_carrier(index, prediction, equations, found):
            # This camera's previous detection was rejected, off the path the same way: not
            # stray detections (they scatter) but a path the other cameras' rays have pulled
            # off this camera's (one camera alone does not fix the depth). Fitted, it
            # corrects the path.  With one other camera carrying the path, only along the
            # image of that camera's rays (a burst of wrong blobs of one camera, growing in
            # random directions, met this by chance: fitted, 2.7 m off).
            return 'ok'
        if pending is not None and stamp - pending[0] <= self.gate.rig_gap_ns:
            if self._confirm_break(frame):
                return 'inserted'
            replaced = self._replaced
            if replaced is None or (pending[1] == index and replaced[1] == index):
                # No impact explains the two (or only a jump no bounce or hit gives): one of
                # them is stray (a wrong blob next to an impact, or two in a row), or the path
                # is lost (a new ball).  The pending one is taken as stray and this one waits
                # in its place: the next detection agrees with the path (this one stray too),
                # or confirms an impact with it or with the replaced one, or else the path
                # restarts from all three.  Three or more of one camera alone do not restart
                # it: along the other cameras' rays only that camera sees the ball, so its
                # wrong blobs in a row (a reflection, a second ball) look like a path that
                # turned; they wait for another camera's detection to agree with the path
                # (all stray) or to disagree too (with a rig dropping frames, three wrong blobs
                # in a row of one camera's burst restarted the fit from them: 2.3 m off).
                self.stats['outlier'] += 1
                self._judged_stray(pending[1], pending[0], self._pending_innovation)
                self._pending = frame
                self._pending_innovation = found
                self._pending_doubtful = False
                self._replaced = pending
                return 'replaced'
            # Detections in a row off the path, of two cameras, not explained by an impact:
            # the path is lost (or was wrong). Start it afresh from them, as at a new flight;
            # the estimates of the lost path no longer bound where the ball can be (a new
            # ball served before the rig paused).
            if replaced is not None and frame[0] - replaced[0] <= self.gate.rig_gap_ns:
                # The pending one was the stray one, and the one it replaced the first after
                # an impact: the two left confirm it (the outlier counted stays one).
                middle = self._pending_innovation
                self._pending, self._pending_innovation = replaced, None
                if self._confirm_break(frame):
                    self._judged_stray(pending[1], pending[0], middle)
                    self._replaced = None
                    return 'inserted'
                # The one judged stray before was not (a new ball): fitted after all.
                self.stats['outlier'] -= 1
                rejected = self._rejected.get(replaced[1])
                if rejected is not None and rejected[0] == replaced[0]:
                    del self._rejected[replaced[1]]
                self._restart_from(replaced, pending, frame)
            else:
                self._restart_from(pending, frame)
            return 'inserted'
        self._pending = frame
        self._pending_innovation = found
        self._pending_doubtful = False
        self._replaced = None
        return 'pending'

    def _doubtful_estimate(self, frame: _Frame) -> Estimate | None:
        """
        Return the estimate at a doubtful detection (within the gate, unlikely as noise).

        The estimate is the fit with it, but the detection is then taken out again and
        pending (the path as before it): the first detection after an impact, a few
        milliseconds in, is only a few pixels off, and fitted it bends the short windows,
        so that the next detection would be judged against a bent path (after a gap of
        dropped frames, 0.1-0.2 m off, and let in by that path's own uncertainty).  The next
        detection decides: it agrees with the path, and the doubtful one is fitted back;
        or it disagrees too, an impact or a lost path (:meth:`_check`).
        """
        stamp, index = frame[0], frame[1]
        impact = None
        if self.pending_estimate == 'impact':
            impact = self._impact_point(frame, self._predict(stamp)[0])
        path = self._path
        dropped = [self.stats[reason] for reason in _FIT_DROPS]
        self._insert(frame)
        estimate = self._estimate(stamp, index)
        if self._end - self._start > _GATE_SUPPORT and self._stamp[self._end - 1] == stamp and \
                self._camera[self._end - 1] == index:
            # The newest frame of the store: dropping it leaves the prefix sums of the others.
            self._end -= 1
            self._doubtful_path, self._path = self._path, path
            self._pending = frame
            self._pending_doubtful = True
            if impact is not None and np.all(np.isfinite(impact)):
                # Left the path along the image of the vertical: the first frame after a
                # bounce, where the fit with it is bent most.
                for reason, count in zip(_FIT_DROPS, dropped):
                    self.stats[reason] = count  # not dropped after all: uncount the fit's
                estimate = Estimate(stamp, self._names[index], float(impact[0]),
                                    float(impact[1]), float(impact[2]), 'predicted')
        return estimate

    def _predicted_spread(self, stamp: int, equations: tuple[tuple[float, ...], ...]) -> float:
        """
        Return the predicted position's variance along a frame's two rows, summed (per px^2).

        ``sum_r g_r^T P C P^T g_r`` for the rows ``g_r`` (m^-1 scaled), the position map
        ``P`` at ``stamp`` and the path's covariance ``C``: each row mapped to the
        coefficients (``P^T g_r``) first.
        """
        assert self._path is not None, 'predictions are made only once a path was fitted'
        t_ref, _, covariance, t_break, _ = self._path
        tau, tau2, jump = _map_terms(stamp - t_ref, None if t_break is None else stamp - t_break)
        powers = (1.0, tau, tau2)
        rows = np.array([[value * power for value in row for power in powers]
                         + ([] if len(covariance) == 9 else [value * jump for value in row]
                            if jump else [0.0] * 3)
                         for row in equations[:2]])
        return float(np.vdot(rows @ covariance, rows))

    def _restart(self) -> None:
        """Drop the window and the path; keep the flight's timing and the measured noise."""
        self._start = self._end
        self._reference = None
        self._weights_guessed = True
        self._path = None
        self._pending = None
        self._replaced = None
        self._break = None
        self._break_range = None
        self._bounce_check = None
        self._segment += 1
        self._tentative = None
        self._lost = None

    def _restart_from(self, *frames: _Frame) -> None:
        """
        Start the path afresh from two (or three) detections (``restarts``): the old one is lost.

        The lost path's estimates no longer bound the plausible speed (a new ball served
        before the rig paused), but the lost path bounds the new fit's first positions
        (:meth:`_lost_reaches`).
        """
        lost = None
        if self._path is not None and self._end > self._start:
            lost = (self._path, int(self._stamp[self._end - 1]))
        self._restart()
        self._lost = lost
        self.plausibility.reset()
        for frame in frames:
            self._insert(frame)
        self.stats['restarts'] += 1

    def _lost_reaches(self, point: Sequence[float], stamp: int) -> bool:
        """
        Return whether a restarted fit's position is within an impact's reach of the lost path.

        Until the new window holds :data:`_GATE_SUPPORT` frames, the fit's positions must be
        reachable from the lost path (:meth:`_reachable`): the ball's position is continuous
        at an impact, and a fit of a few frames, one of them a wrong blob, can be anywhere
        (a restart from three detections that disagreed with the path: 5.93 m off).  A new
        ball elsewhere loses the fit's first estimates (the paper's stand in for them).
        """
        assert self._lost is not None, 'called only after a restart'
        if self._end - self._start >= _GATE_SUPPORT:
            self._lost = None
            return True
        lost, last = self._lost
        with self._judged_by(lost):
            return self._reachable(point, stamp, last)

    def _pending_estimate(self, frame: _Frame) -> Estimate | None:
        """Return the estimate at a pending detection's event: the predicted position."""
        stamp, index = frame[0], frame[1]
        if self.pending_estimate == 'none':
            self.stats['pending'] += 1
            return None
        point, covariance = self._predict(stamp)
        depth = float(self._rotation[index, 2] @ (point - self._center[index]))
        if not (depth > 0.0 and math.sqrt(max(float(np.trace(covariance)), 0.0))
                * self._focal[index] / depth <= self.max_uncertainty):
            self.stats['degenerate'] += 1  # the path is not known well enough to predict
            return None
        if self.pending_estimate == 'impact':
            on_ray = self._impact_point(frame, point)
            if on_ray is not None:
                point = on_ray
        if not np.all(np.isfinite(point)):
            self.stats['degenerate'] += 1
            return None
        return Estimate(stamp, self._names[index], float(point[0]), float(point[1]),
                        float(point[2]), 'predicted')

    def _impact_point(self, frame: _Frame, point: np.ndarray) -> np.ndarray | None:
        """
        Return where a detection off the predicted ``point`` puts the ball after an impact.

        If the detection is the first after an impact on a horizontal surface (a table, the
        floor), the ball left the path vertically: the point of its ray nearest to the
        prediction, vertical offsets costing a ninth of horizontal ones; taken only if the
        detection moved off the prediction along the image of the vertical (within 30
        degrees) and by no more than reversing the ball's velocity since the last fitted
        frame could carry it.  Otherwise (a stray detection) None.
        """
        stamp, index = frame[0], frame[1]
        assert self._path is not None, 'an impact point needs a path'
        t_ref, _, _, t_break, coefficients = self._path
        tau, _, jump = _map_terms(stamp - t_ref, None if t_break is None else stamp - t_break)
        if coefficients[7] + 2.0 * coefficients[8] * tau + (coefficients[11] if jump else 0.0) \
                >= 0.0:
            return None  # the path does not descend: no bounce on a horizontal surface
        found = self._innovation(index, frame[2], frame[3], point)
        if found is None:
            return None
        vertical = found[1][:, 2]
        if abs(found[0][0] * vertical[1] - found[0][1] * vertical[0]) > _VERTICAL_SINE \
                * float(np.linalg.norm(found[0]) * np.linalg.norm(vertical)):
            return None
        direction = np.cross(frame[2][0], frame[2][1])
        weights = np.array((9.0, 9.0, 1.0))
        offset = point - self._center[index]
        on_ray = self._center[index] + direction * float((offset * weights) @ direction) / \
            float((direction * weights) @ direction)
        if on_ray[2] <= point[2]:
            return None  # a bounce lifts the ball above the path it would have followed
        last = self._predict(int(self._stamp[self._end - 1]))[0]
        reach = _IMPACT_REACH * float(np.linalg.norm(point - last))
        return on_ray if float(np.linalg.norm(on_ray - point)) <= reach else None

    def _confirm_break(self, frame: _Frame) -> bool:
        """Test an impact between the last consistent frames and the pending one."""
        pending = self._pending
        assert pending is not None, 'an impact is confirmed only with a pending detection'
        start, end = self._start, self._end
        first = start  # frames after an earlier impact only: one jump per window
        if self._break is not None:
            first += int(np.searchsorted(self._stamp[start:end], self._break))
        if end - first < 4:
            return False
        stamps = np.append(self._stamp[first:end], (pending[0], frame[0]))
        cameras = np.append(self._camera[first:end], (pending[1], frame[1]))
        rows = np.concatenate((self._rows[first:end], (pending[2], frame[2])))
        rhs = np.concatenate((self._rhs[first:end], (pending[3], frame[3])))
        weights = np.append(self._weight[first:end], (pending[4], frame[4]))
        low, high = int(self._stamp[max(first, end - 3)]), int(pending[0])
        frames = (stamps, rows, rhs, weights)
        # Two frames after the impact do not place it with a free jump (four equations, four
        # unknowns: the time chosen by the residual would fit the noise).  A bounce on a
        # horizontal surface (a table, the floor) changes the velocity in the vertical plane
        # of the flight: a jump in that plane (at most three unknowns with the time) places
        # it where it explains both frames within the noise; the free jump is then fitted at
        # that time.  Otherwise (a hit) halfway before the pending frame, until later frames
        # refine it.  (A time halfway into an interval was 20-35 mm off at the next event
        # with three cameras at 60 fps.)
        best = None
        directions = self._bounce_directions(high)
        bounce = self._refine_break(frames, int(frame[0]), int(self._stamp[max(first, end - 2)]),
                                    high, directions)
        if bounce is not None and self._explains(bounce, stamps, cameras, rows, rhs):
            best = self._refine_break(frames, int(frame[0]), bounce[1], bounce[1])
        else:
            bounce = None
        if best is None:
            for earlier, later in ((end - 1, None), (end - 2, end - 1)):
                if earlier < first:
                    continue
                later = high if later is None else int(self._stamp[later])
                middle = (int(self._stamp[earlier]) + later) // 2
                found = self._refine_break(frames, int(frame[0]), middle, middle)
                if found is not None and (best is None or found[0] < best[0]):
                    best = found
        if best is None:
            return False
        if not self._jump_plausible(best, int(frame[0]), int(self._stamp[end - 1])):
            return False
        # The jump must explain both new frames: their residuals within the gate, or at
        # least ten times smaller (squared) than without it (the impact time is only known
        # to a grid step until later frames refine it).
        if not self._explains(best, stamps, cameras, rows, rhs, loose=True):
            return False
        t_break = best[1]
        self._tentative = (self._snapshot(), (stamps[:-2], cameras[:-2], rows[:-2], rhs[:-2],
                                              weights[:-2]), low, directions, [pending, frame])
        self._start = first
        self._insert(pending)
        self._insert(frame)
        self._break = t_break
        self._rebuild(self._start)
        self._break_range = (low, high)
        self._bounce_check = None
        self._segment += 1
        self._pending = None
        self.stats['breaks'] += 1
        self._bounce_point = None if bounce is None else \
            self._bounce_estimate(bounce, directions, int(frame[0]), int(frame[1]))
        return True

    def _jump_plausible(self, found: _Break, stamp: int, last: int) -> bool:
        """
        Return whether an impact's path is one a bounce or a hit can give.

        A free jump explains any two detections, and next to an impact a stray one needs a
        velocity jump of tens of m/s.  The jump's size itself depends on its time, which two
        detections do not fix; the path's distance at ``stamp`` from the path before the
        impact does not.  Over the time since the ``last`` fitted frame, where the path
        before the impact still held (an impact placed a little before it moved the path
        there by no more than the noise), it must not exceed twice the ball's speed (a
        bounce or hit reverses it at most) plus :data:`_JUMP_MARGIN_MPS`.  (Measured since
        the impact's own time instead, two wrong blobs in a row confirmed one 0.86 m off.)
        A detection not newer than ``last`` confirms no impact.

        :param found: the path with the jump (:meth:`_refine_break` at ``stamp``)
        :param stamp: the newest frame's stamp [ns]
        :param last: the stamp of the newest frame fitted [ns]
        """
        _, t_break, beta, _ = found
        return self._reachable((_position_row(0, stamp - t_break) @ beta).tolist(), stamp, last)

    def _reachable(self, point: Sequence[float], stamp: int, last: int) -> bool:
        """
        Return whether an impact after ``last`` can carry the ball to ``point`` by ``stamp``.

        Its distance from the path's prediction must not exceed twice the ball's speed at
        ``last`` plus :data:`_JUMP_MARGIN_MPS`, times the time since ``last`` (see
        :meth:`_jump_plausible`); and a path faster than ``max_speed_mps`` is no ball's
        (bursts of wrong blobs across a bounce: impacts confirmed from them until a path at
        2,900 m/s put an estimate 339 m off; at 168 fps a false second impact 18 ms after
        a bounce, off a path at 71 m/s).
        """
        speed = math.hypot(*self._velocity(last))
        fastest = self.plausibility.max_speed_mps
        if fastest and not speed <= fastest:
            return False
        away = math.dist(point, self._predict_point(stamp))
        return away <= (2.0 * speed + _JUMP_MARGIN_MPS) * (stamp - last) * 1e-9

    def _reachable_before(self, state: _Snapshot, point: Sequence[float], stamp: int,
                          last: int) -> bool:
        """Return :meth:`_reachable` by the path before a tentative impact (its snapshot)."""
        with self._judged_by(state['_path']):  # type: ignore[arg-type]
            return self._reachable(point, stamp, last)

    @contextlib.contextmanager
    def _judged_by(self, path: _Path) -> Iterator[None]:
        """Make another path the one that predicts (:meth:`_predict_point`), for a while."""
        current, self._path = self._path, path
        try:
            yield
        finally:
            self._path = current

    def _snapshot(self) -> _Snapshot:
        """Return the state an impact's confirmation changes (see :meth:`_restore`)."""
        state: _Snapshot = {name: getattr(self, name) for name in _SNAPSHOT_ATTRIBUTES}
        start, end = self._start, self._end
        state['frames'] = tuple(array[start:end].copy() for array in self._arrays())
        state['residual'] = dict(self._residual)
        state['rejected'] = dict(self._rejected)
        state['strays'] = {index: list(strays) for index, strays in self._strays.items()}
        state['depth'] = list(self._depth)
        return state

    def _restore(self, state: _Snapshot) -> None:
        """
        Return to a :meth:`_snapshot`'s state: the window, the path, the pending frame.

        Deliberately kept: the noise estimate (samples from the undone frames are a few
        among many) and the plausibility gate's history (the estimates were published).
        """
        for name in _SNAPSHOT_ATTRIBUTES:
            setattr(self, name, state[name])
        start, end = self._start, self._end
        frames: tuple[np.ndarray, ...] = state['frames']  # type: ignore[assignment]
        for array, saved in zip(self._arrays(), frames):
            array[start:end] = saved
        self._residual = dict(state['residual'])  # type: ignore[call-overload]
        self._rejected = dict(state['rejected'])  # type: ignore[call-overload]
        strays: dict[int, list] = state['strays']  # type: ignore[assignment]
        self._strays = {index: list(innovations) for index, innovations in strays.items()}
        self._depth = list(state['depth'])  # type: ignore[call-overload]
        # Residuals of the undone segments are not this segment's (the noise estimate).
        self._noise_residual = {camera: residual for camera, residual
                                in self._noise_residual.items()
                                if residual[1] <= self._segment}
        self._tentative = None
        self._rebuild(start)

    def _recheck_impact(self, index: int, stamp: int, rows: np.ndarray, rhs: np.ndarray,
                        unjudged: bool) -> tuple[Estimate | None] | None:
        """
        Decide, at the detections after an impact confirmed from two, which one was stray.

        A free velocity jump explains any two detections (four equations, four unknowns):
        a stray one next to an impact confirms it with the wrong jump (the first detection
        after an impact pending, the next a wrong blob), 0.4-0.8 m off until the path is
        lost.  The third detection after the pending one tests the jump: a jump (its time
        refined) in the flight's vertical plane (a bounce) explaining all three settles it.
        A free jump explaining them does not: with two cameras, two frames of one camera
        fix the jump only poorly along its rays, where a stray frame of the other camera
        hides.  If the third agrees with the path before the impact both were stray (no
        impact); else it is held (not fitted, its estimate the prediction, or where that is
        too uncertain the free jump's position) and the fourth decides.  A free jump
        explaining all four settles it; else, of the four triples, the one a bounce explains
        best, or else a free jump (within the gate), is kept and the detection left out
        counted an outlier (the fourth: judged against the path as usual); none: the impact
        stands, the held one fitted as it would have been.

        :param unjudged: a late or fresh detection (fitted without gating): the impact stands
        :return: ``(estimate,)`` if this detection is held, else None (fit it as usual)
        """
        assert self._tentative is not None, 'called only while an impact is tentative'
        state, before, low, directions, after = self._tentative
        if unjudged or not 0 <= stamp - after[-1][0] <= self.gate.rig_gap_ns:
            self._settle()
            return None
        depth = self._depth[index]
        if self._path is not None:
            point = self._predict_point(stamp)
            (c0, c1, c2), (d0, d1, d2) = self._center_rows[index], self._rotation_rows[index][2]
            predicted = (point[0] - c0) * d0 + (point[1] - c1) * d1 + (point[2] - c2) * d2
            if predicted > 0.0:
                depth = predicted
        frame: _Frame = (stamp, index, rows, rhs, self._focal_list[index] / depth)
        if len(after) == 2:
            if self._jump_chi2(before, low, after + [frame], directions) is not None:
                self._tentative = None  # the usual case: a bounce explains all three
                # Until detections are gated again, the bounce judges them (_check).
                self._bounce_check = (before, low, directions, after + [frame])
                return None
            if self._agrees(state['_path'], frame):  # type: ignore[arg-type]
                # Back on the path before the impact: both detections were stray.
                self._restore(state)
                self._pending = None
                self.stats['outlier'] += 2
                self.stats['breaks'] -= 1
                return None
            after.append(frame)
            estimate = self._pending_estimate(frame)
            free = self._jump_chi2(before, low, after)
            if estimate is None and self.pending_estimate != 'none' and free is not None and \
                    np.all(np.isfinite(free[1])) and self._reachable_before(
                        state, free[1].tolist(), stamp, int(before[0][-1])):
                # The prediction is not known well enough (right after the impact), but a
                # free jump explains the three (a hit, a bounce with side spin): its position.
                self.stats['degenerate'] -= 1  # not dropped after all
                estimate = Estimate(stamp, self._names[index], float(free[1][0]),
                                    float(free[1][1]), float(free[1][2]), 'trajectory')
            return (estimate,)
        first, second, third = after
        if self._jump_chi2(before, low, after + [frame]) is not None:
            self._settle()  # all four explained (a hit, not a bounce): the impact stands
            return None
        # One of the four is stray.  Two frames of one camera fix the jump only poorly along
        # its rays (a rig of two cameras: a stray frame of the other camera is absorbed
        # there), so a jump in the flight's vertical plane (a bounce), with fewer unknowns,
        # is preferred to a free one.
        best: tuple[tuple[int, float], _Frame] | None = None
        for dropped, triple in ((frame, (first, second, third)), (third, (first, second, frame)),
                                (second, (first, third, frame)), (first, (second, third, frame))):
            for rank, plane in enumerate((directions, None)):
                found = self._jump_chi2(before, low, list(triple), plane)
                if found is not None:
                    if best is None or (rank, found[0]) < best[0]:
                        best = ((rank, found[0]), dropped)
                    break
        if best is None or best[1] is frame:
            self._settle()  # this one is judged against the impact's path as usual
            return None
        self._tentative = None
        self.stats['outlier'] += 1
        if best[1] is third:
            return None  # the held one was stray: the impact stands
        # One of the two that confirmed it was stray: confirm it again without it.
        kept = [candidate for candidate in after if candidate is not best[1]]
        self._restore(state)
        self.stats['breaks'] -= 1
        self._pending, self._pending_innovation, self._pending_doubtful = kept[0], None, False
        if self._confirm_break(kept[1]):
            self._tentative = None
        else:
            self._restart_from(kept[0], kept[1])  # no impact explains the two left either
        return None

    def _settle(self) -> None:
        """Keep a tentative impact as confirmed; fit its held detection, if any."""
        assert self._tentative is not None, 'called only while an impact is tentative'
        after = self._tentative[4]
        self._tentative = None
        if len(after) == 3:
            self._insert(after[2])

    def _jump_chi2(self, before: tuple[np.ndarray, ...], low: int, after: list[_Frame],
                   directions: np.ndarray | None = None) -> tuple[float, np.ndarray] | None:
        """
        Return the chi-square of frames after an impact under a jump fitted to them.

        :param before: the frames before the impact (stamps, cameras, rows, rhs, weights)
        :param low: the earliest time of the impact [ns]; the latest is the first frame's
        :param directions: (3, k) a bounce's (see :meth:`_bounce_directions`), or None (free)
        :return: (chi-square, position at the newest frame [m]), or None if any frame's
            residual is beyond the gate (or no jump was found)
        """
        stamps = np.append(before[0], [frame[0] for frame in after])
        rows = np.concatenate((before[2], [frame[2] for frame in after]))
        rhs = np.concatenate((before[3], [frame[3] for frame in after]))
        weights = np.append(before[4], [frame[4] for frame in after])
        newest = int(after[-1][0])
        found = self._refine_break((stamps, rows, rhs, weights), newest, low, int(after[0][0]),
                                   directions)
        if found is None:
            return None
        _, t_break, beta, _ = found
        offsets = np.array([frame[0] for frame in after], dtype=np.int64)
        maps = _position_map(offsets - newest, offsets - t_break)
        assert self._gate_sigma is not None, 'impacts are confirmed only with a noise level'
        spread = max(self._gate_sigma ** 2, self._spread or 0.0)
        total = 0.0
        for frame, row in zip(after, maps):
            found_innovation = self._innovation(frame[1], frame[2], frame[3], row @ beta)
            if found_innovation is None:
                return None
            chi2 = float(found_innovation[0] @ found_innovation[0]) / spread
            if chi2 > self.innovation_gate:
                return None
            total += chi2
        return total, maps[-1] @ beta

    def _agrees(self, path: _Path, frame: _Frame) -> bool:
        """Return whether a detection is within the gate of a path's prediction."""
        with self._judged_by(path):
            point = np.array(self._predict_point(frame[0]))
        found = self._innovation(frame[1], frame[2], frame[3], point)
        if found is None:
            return False
        assert self._gate_sigma is not None, 'detections are gated only with a noise level'
        spread = max(self._gate_sigma ** 2, self._spread or 0.0)
        return float(found[0] @ found[0]) <= self.innovation_gate * spread

    def _velocity(self, stamp: int) -> tuple[float, float, float]:
        """Return the path's velocity at ``stamp`` [m/s] (its positions 1 ms either side)."""
        before = self._predict_point(stamp - 1_000_000)
        after = self._predict_point(stamp + 1_000_000)
        return ((after[0] - before[0]) / 0.002, (after[1] - before[1]) / 0.002,
                (after[2] - before[2]) / 0.002)

    def _bounce_directions(self, stamp: int) -> np.ndarray:
        """
        Return (3, k) directions that span a bounce's velocity jump at ``stamp``.

        A ball bouncing off a horizontal surface (a table, the floor) without side spin
        changes its velocity in the vertical plane of its flight: the vertical (the
        restitution) and the horizontal direction of its velocity (friction, top or back
        spin); the vertical alone when it has hardly any horizontal speed.
        """
        vx, vy, _ = self._velocity(stamp)
        speed = math.hypot(vx, vy)
        if speed > _BOUNCE_MIN_SPEED:
            return np.array(((0.0, vx / speed), (0.0, vy / speed), (1.0, 0.0)))
        return np.array(((0.0,), (0.0,), (1.0,)))

    def _bounce_estimate(self, bounce: _Break, directions: np.ndarray, stamp: int,
                         index: int) -> np.ndarray | None:
        """
        Return a bounce's position at its newest frame if it is determined well.

        With the free jump fitted to two frames after an impact, the position along the
        newest camera's ray can be too uncertain to give (``max_uncertainty``); the
        bounce's jump that placed the impact explained both frames with fewer unknowns.

        :param bounce: the bounce's path (:meth:`_refine_break` with ``directions``)
        :param directions: (3, k) the directions of its jump
        """
        _, t_break, beta, normal = bounce
        row = _position_row(0, stamp - t_break)
        free = np.concatenate((row[:, :9], row[:, 9:] @ directions), axis=1)
        try:
            covariance = free @ np.linalg.solve(normal, free.T)
        except np.linalg.LinAlgError:
            return None
        point = row @ beta
        depth = float(self._rotation[index, 2] @ (point - self._center[index]))
        limit = self.max_uncertainty * depth / self._focal[index]
        if depth > 0.0 and np.all(np.isfinite(point)) and \
                0.0 < float(np.trace(covariance)) <= limit * limit:
            return point
        return None

    def _estimate_at_break(self, stamp: int, index: int) -> Estimate | None:
        """Return the estimate at the frame that confirmed an impact (see _bounce_estimate)."""
        degenerate = self.stats['degenerate']
        estimate = self._estimate(stamp, index)
        point, self._bounce_point = self._bounce_point, None
        if estimate is None and point is not None and self.stats['degenerate'] > degenerate:
            self.stats['degenerate'] -= 1  # not dropped after all
            estimate = Estimate(stamp, self._names[index], float(point[0]), float(point[1]),
                                float(point[2]), 'trajectory')
        return estimate

    def _explains(self, found: _Break, stamps: np.ndarray,
                  cameras: np.ndarray, rows: np.ndarray, rhs: np.ndarray,
                  loose: bool = False) -> bool:
        """
        Return whether a path with a jump explains the last two frames.

        :param found: (residual sum of squares, impact stamp, beta at the newest frame)
        :param loose: also accept residuals ten times smaller (squared) than the path's
            without the jump; otherwise they must be within the gate
        """
        _, t_break, beta, _ = found
        maps = _position_map(stamps[-2:] - int(stamps[-1]), stamps[-2:] - t_break)
        assert self._gate_sigma is not None, '_check gates detections only with a noise level'
        spread = max(self._gate_sigma ** 2, self._spread or 0.0)
        for k in (-2, -1):
            after = self._innovation(int(cameras[k]), rows[k], rhs[k], maps[k] @ beta)
            before = self._innovation(int(cameras[k]), rows[k], rhs[k],
                                      self._predict(int(stamps[k]))[0])
            if after is None or before is None:
                return False
            bound = self.innovation_gate * spread
            if loose:
                bound = max(bound, 0.1 * float(before[0] @ before[0]))
            if float(after[0] @ after[0]) > bound:
                return False
        return True

    def _refine_break(self, frames: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
                      stamp: int, low: int, high: int,
                      directions: np.ndarray | None = None) -> _Break | None:
        """
        Return (residual sum of squares, impact stamp, beta, normal matrix) minimizing it.

        The impact time is searched on a grid over (low, high), then on finer grids around
        the best time (the residual is smooth between frames; the time, not the grid,
        decides how far the jump's path is off right after the impact).

        :param directions: (3, k) the jump restricted to these directions' span (a bounce:
            see :meth:`_bounce_directions`), or None (free); beta still has 12
            coefficients, the normal matrix 9 + k
        :return: None if no candidate time gave a solution
        """
        stamps, rows, rhs, weights = frames
        offsets = stamps - stamp
        base = _position_map(offsets, None)  # (n, 3, 12) without the jump
        design = np.einsum('nra,nam->nrm', rows, base) * weights[:, None, None]
        vector = (rhs * weights[:, None]).reshape(-1)
        if directions is None:
            directions = np.eye(3)
        best: _Break | None = None

        fixed = design[:, :, :9].reshape(len(stamps) * 2, 9)
        along = (rows @ directions) * weights[:, None, None]  # (n, 2, k)

        def search(candidates: np.ndarray) -> None:
            # All candidate times at once: (K, 2n, 9 + k) designs, stacked solves.
            nonlocal best
            jumps = np.maximum(0.0, (stamps[None, :] - candidates[:, None]).astype(float)
                               / _SCALE_NS)  # (K, n)
            candidates = candidates[np.any(jumps > 0.0, axis=1)]
            jumps = jumps[np.any(jumps > 0.0, axis=1)]
            if not len(candidates):
                return
            flats = np.concatenate((np.broadcast_to(fixed, (len(candidates),) + fixed.shape),
                                    (jumps[:, :, None, None] * along).reshape(
                                        len(candidates), len(stamps) * 2, -1)), axis=2)
            normals = flats.transpose(0, 2, 1) @ flats
            try:
                betas = np.linalg.solve(normals, (flats.transpose(0, 2, 1) @ vector)[:, :, None])
            except np.linalg.LinAlgError:  # one singular candidate: each on its own
                betas = np.full(normals.shape[:2] + (1,), np.nan)
                for k, normal in enumerate(normals):
                    try:
                        betas[k] = np.linalg.solve(normal, flats[k].T @ vector)[:, None]
                    except np.linalg.LinAlgError:
                        continue
            residuals = (flats @ betas)[:, :, 0] - vector
            rss = np.einsum('kr,kr->k', residuals, residuals)
            if not np.any(np.isfinite(rss)):
                return
            k = int(np.nanargmin(rss))
            if best is None or rss[k] < best[0]:
                beta = np.concatenate((betas[k, :9, 0], directions @ betas[k, 9:, 0]))
                best = (float(rss[k]), int(candidates[k]), beta, normals[k])

        if low == high:
            search(np.array((low,), dtype=np.int64))
            return best
        step = (high - low) / (_BREAK_GRID + 1)
        search(np.linspace(low, high, _BREAK_GRID + 2)[1:-1].astype(np.int64))
        for _ in range(_BREAK_ZOOM):
            if best is None or step < _BREAK_RESOLUTION_NS:
                break
            around = best[1]
            search(np.linspace(max(low, around - step), min(high, around + step),
                               _BREAK_GRID + 2)[1:-1].astype(np.int64))
            step = 2.0 * step / (_BREAK_GRID + 1)
        return best

    # -- the fit --------------------------------------------------------------------------------

    def _estimate(self, stamp: int, index: int) -> Estimate | None:
        """Fit the windows at ``stamp`` and return the estimate (or None, counted)."""
        stats = self.stats
        start, end = self._start, self._end
        stamps = self._stamp[start:end]
        gaps = self.gate.max_gaps
        partners = 0
        for name, last in self._last.items():
            if stamp - last <= gaps[name]:
                partners += 1
                if partners == 2:
                    break
        else:
            stats['no_partner'] += 1
            return None
        if self._break_range is not None and \
                np.count_nonzero(stamps > self._break_range[1]) >= _REFINE_MIN:
            low, high = self._break_range
            best = self._refine_break((stamps, self._rows[start:end], self._rhs[start:end],
                                       self._weight[start:end]), stamp, low, high)
            if best is not None and best[1] != self._break:
                self._break = best[1]
                self._rebuild(start)
            if np.count_nonzero(stamps > high) >= _REFINE_FRAMES:
                self._break_range = None
        point = self._fit(stamp, index)
        if point is None:
            return None
        if self._lost is not None and not self._lost_reaches(point, stamp):
            stats['implausible'] += 1
            return None
        return Estimate(stamp, self._names[index], float(point[0]), float(point[1]),
                        float(point[2]), 'trajectory')

    def _fit(self, stamp: int, index: int) -> Sequence[float] | None:
        """Fit the nested windows, choose one (Lepski) and return the position at ``stamp``."""
        start, end = self._start, self._end
        count = end - start
        stamps = self._stamp[start:end]
        t_break = self._break
        if t_break is not None and not stamps[0] < t_break:
            t_break = None  # the impact has left the window: plain fits
        # Window k holds the newest sizes[k] frames: a difference of prefix sums, moved from
        # the reference stamp's coefficients to the event's (tau -> tau - delta per axis).
        quadratic = self.order == 2 and count >= self._shortest
        sizes = _sizes(count, self._windows) if quadratic else np.array((count,))
        assert self._reference is not None, 'the window holds frames, so _insert set the reference'
        delta = (stamp - self._reference) / _SCALE_NS
        unknowns = 9 if t_break is None else 12  # the jump's columns only with an impact
        shift, shift_t = self._shift[unknowns], self._shift_t[unknowns]
        shift[0, 1] = shift[3, 4] = shift[6, 7] = shift_t[1, 0] = shift_t[4, 3] = \
            shift_t[7, 6] = -delta
        shift[0, 2] = shift[3, 5] = shift[6, 8] = shift_t[2, 0] = shift_t[5, 3] = \
            shift_t[8, 6] = delta * delta
        shift[1, 2] = shift[4, 5] = shift[7, 8] = shift_t[2, 1] = shift_t[5, 4] = \
            shift_t[8, 7] = -2.0 * delta
        previous = end - sizes
        # The unknowns first, the right-hand side last.  (A contiguous stack: numpy 1.26 and
        # 2.x then multiply it the same way, bit for bit.)
        if t_break is None:
            prefix = self._prefix10
            systems = prefix[end] - prefix.take(previous, axis=0)
        else:
            prefix = self._prefix
            systems = np.ascontiguousarray((prefix[end] - prefix.take(previous, axis=0))[
                :, _AUGMENTED[:, None], _AUGMENTED])
        systems = np.matmul(np.matmul(shift_t, systems), shift)
        matrices, moments = systems[:, :unknowns, :unknowns], systems[:, :unknowns, unknowns]
        position = _POSITION if t_break is None else _position_row(0, stamp - t_break)
        kept: _Fits | None = None
        fixed, biased = 0, False  # a velocity or free-fall fallback (see _fixed_fallback)
        if quadratic:
            if t_break is None:
                kept = self._fits(matrices, moments, sizes, 9, position, index)
            else:
                spans = stamps[::-1][sizes - 1] < t_break
                kept = self._merge(
                    self._fits(matrices[~spans], moments[~spans], sizes[~spans], 9, position,
                               index),
                    self._fits(matrices[spans], moments[spans], sizes[spans], 12, position,
                               index))
        after = count if t_break is None else int(np.count_nonzero(stamps > t_break))
        if kept is None and after >= _CV_MIN:
            # Too few frames for constant acceleration (a flight's first frames): velocity,
            # never across an impact.
            if after == count:
                system = (matrices[-1:], moments[-1:])
            else:
                system = self._window_system(stamp, end - after, end)
            kept = self._fits(system[0][:, _CV][:, :, _CV], system[1][:, _CV],
                              np.array((after,)), _CV, position, index)
            if quadratic and kept is not None:
                # Frames enough for acceleration, but no window determined it.
                fallback = self._fixed_fallback(kept, system, stamp, end - after, position,
                                                index)
                if fallback is None:  # a frame was taken as an outlier: fit without it
                    return self._fit(stamp, index)
                kept, fixed, biased = fallback
        if kept is None:
            self.stats['warming_up' if count < self._windows[0] else 'degenerate'] += 1
            return None
        kept_sizes, points, covariances, solutions = kept
        sigma2 = 1.0 if self.sigma_px is None else self.sigma_px ** 2
        longest = len(kept_sizes) - 1
        model = None
        if quadratic and kept_sizes[longest] >= _CV_SELECT_MIN:
            # The model's order, from the longest window: a constant velocity or a free fall
            # where its acceleration does not differ significantly from theirs.
            model = self._lower_model(*self._full(*solutions[longest]), sigma2)
        lower = None
        if model is not None:
            try:
                lower = self._lower_choice(solutions, longest, model, position, sigma2)
            except np.linalg.LinAlgError:  # a shorter window's acceleration block is singular
                lower = None
        estimate = None
        if lower is None:
            chosen = self._lepski(points, covariances, sigma2, self.consistency)
            beta, inverse = self._full(*solutions[chosen])
            point, covariance = points[chosen], covariances[chosen]
            if quadratic and t_break is None:
                jerk = self._jerk_fits(stamp, index, count, sigma2)
                if jerk is not None:
                    estimate = self._with_jerk(points, covariances, chosen, *jerk, sigma2)
        else:  # the noise estimate below uses the lower-order fits too
            beta, inverse, point, covariance, points, covariances = lower
        if fixed:  # the free fall's acceleration is known, not fitted
            beta = beta.copy()
            beta[_ACCELERATION] = _FIXED_ACCELERATIONS[:, fixed]
        coefficients = beta.tolist()
        self._path = (stamp, beta, inverse, t_break,
                      coefficients + [0.0] * (12 - len(coefficients)))
        if self._weights_guessed:
            self._refresh_weights(stamp, beta, t_break)
        if self._stamp[end - 1] == stamp:
            # This frame's residual in the chosen fit (for the impact gate) and in the noise
            # estimate's fixed-length fit; the frame's row maps the coefficients to the
            # position at the event, so its residual and leverage need only that position
            # and its covariance.
            weight = float(self._weight[end - 1])
            rows = self._rows[end - 1].tolist()
            rhs = self._rhs[end - 1].tolist()
            self._residual[index] = (stamp, self._segment,
                                     _standardized(rows, rhs, weight, point, covariance))
            (c0, c1, c2), (d0, d1, d2) = self._center_rows[index], self._rotation_rows[index][2]
            self._depth[index] = (point[0] - c0) * d0 + (point[1] - c1) * d1 + \
                (point[2] - c2) * d2
            reference = bisect.bisect_left(kept_sizes, _NOISE_WINDOW)
            if reference < len(kept_sizes):
                self._measure_noise(stamp, index, _standardized(
                    rows, rhs, weight, points[reference], covariances[reference]))
        if biased:  # the path predicts as before (the gate judges by it), but no estimate
            self.stats['degenerate'] += 1
            return None
        return point if estimate is None else estimate

    def _jerk_fits(self, stamp: int, index: int, count: int,
                   sigma2: float) -> tuple[list, list] | None:
        """
        Return constant-jerk fits' positions at ``stamp`` and covariances, or None.

        Windows of the nested sizes from 13 to 40 frames of a pair (``_JERK_WINDOWS``)
        reaching back at least ``_JERK_MIN_SPAN_NS`` from the event's stamp, from prefix
        sums of their own (see :meth:`_rebuild`); None without one, or unless the jerk of
        the longest window kept is significant (Wald's chi-square, 3 d.o.f., above
        ``_JERK_SIGNIFICANCE``).

        :return: ``(points, covariances)`` as :meth:`_fits` gives them, shortest window first
            (the solutions are cubic coefficients, x0 .. x3 y0 .. z3: not for :meth:`_full`)
        """
        end = self._end
        sizes = _sizes(count, self._windows)
        shortest, longest = self._jerk_windows
        sizes = sizes[(sizes >= shortest) & (sizes <= longest)]
        if len(sizes):
            sizes = sizes[stamp - self._stamp[end - sizes] >= _JERK_MIN_SPAN_NS]
        if not len(sizes):
            return None
        # A difference of prefix sums, moved from the reference stamp's coefficients to the
        # event's: tau^q -> (tau - delta)^q, binomially, per axis.
        assert self._reference is not None, 'the window holds frames, so _insert set the reference'
        delta = (stamp - self._reference) / _SCALE_NS
        shift = self._shift_jerk
        shift[_JERK_SHIFT] = [factor * delta ** power for factor, power in _JERK_TERMS] * 3
        prefix = self._prefix_jerk
        systems = np.matmul(np.matmul(shift.T, prefix[end] - prefix.take(end - sizes, axis=0)),
                            shift)
        kept = self._fits(np.ascontiguousarray(systems[:, :12, :12]),
                          np.ascontiguousarray(systems[:, :12, 12]), sizes, 12, _POSITION,
                          index, picks=4)
        if kept is None:
            return None
        solutions = kept[3]
        assert isinstance(solutions, _Solutions)
        (a, b, c), (_, e, f), (_, _, i) = solutions.inverses[-1][3::4, 3::4].tolist()
        x, y, z = solutions.betas[-1][3::4].tolist()
        if _inverse_form(x, y, z, a, b, c, e, f, i) <= _JERK_SIGNIFICANCE * sigma2:
            return None
        return kept[1], kept[2]

    def _with_jerk(self, points: list, covariances: list, chosen: int, jerk_points: list,
                   jerk_covariances: list, sigma2: float) -> list[float]:
        """
        Return the position from the acceleration fits (``chosen``: theirs) and jerk fits.

        Both families' fits form one sequence by decreasing variance (the trace of the
        covariance), and Lepski's rule takes the least variable fit consistent with every
        more variable one.  If that is an acceleration fit (no parabola's bias shows yet)
        and ``_JERK_AVERAGE_MIN`` jerk fits or more are at hand, the position is instead
        the mean of the acceleration fits' choice and the jerk fits' own (Lepski's rule
        among them): the two errors, a parabola's bias and a short cubic's noise, are
        partly independent.
        """
        consistency = self.consistency
        fits = sorted(zip(points + jerk_points, covariances + jerk_covariances,
                          [False] * len(points) + [True] * len(jerk_points)),
                      key=_trace, reverse=True)
        best = self._lepski([point for point, _, _ in fits],
                            [covariance for _, covariance, _ in fits], sigma2, consistency)
        point, _, cubic = fits[best]
        if cubic or len(jerk_points) < _JERK_AVERAGE_MIN:
            return point
        jerk = self._lepski(jerk_points, jerk_covariances, sigma2, consistency)
        (x0, y0, z0), (x1, y1, z1) = points[chosen], jerk_points[jerk]
        return [0.5 * (x0 + x1), 0.5 * (y0 + y1), 0.5 * (z0 + z1)]

    @staticmethod
    def _lower_model(beta: np.ndarray, inverse: np.ndarray, sigma2: float) -> int | None:
        """
        Return the lower-order model a window's acceleration fit does not reject, or None.

        The candidates fix the acceleration: zero (0, a constant velocity) or the known
        gravity :data:`GRAVITY_MPS2` along -z (1, a free fall).  The test is Wald's
        chi-square (3 d.o.f.) of the fitted acceleration against the fixed one; the
        candidate with the smaller statistic is taken if that is within
        ``_ORDER_CONSISTENCY``.

        :param beta: (m,) the acceleration fit's coefficients at the event (m = 9 or 12)
        :param inverse: (m, m) their covariance per px^2
        :param sigma2: the detection noise's variance [px^2]
        :return: the model's column in ``_FIXED_ACCELERATIONS``, or None
        """
        # (Plain floats: a 3 x 3 form per candidate, the cost of every event.)
        (a, b, c), (_, e, f), (_, _, i) = inverse[2:9:3, 2:9:3].tolist()
        x, y, z = beta[2:9:3].tolist()
        statistics = [_inverse_form(x - fixed_x, y - fixed_y, z - fixed_z, a, b, c, e, f, i)
                      for fixed_x, fixed_y, fixed_z in _FIXED_LIST]
        best = 0 if statistics[0] <= statistics[1] else 1
        if not 0.0 < statistics[best] <= _ORDER_CONSISTENCY * sigma2:
            return None  # (zero: a singular covariance)
        return best

    def _lower_choice(self, solutions: _Solutions | list[_Solution], longest: int, model: int,
                      position: np.ndarray, sigma2: float) -> tuple:
        """
        Return the lower-order model's chosen fit (beta, inverse, point, covariance) and all fits.

        The model's variance is far smaller than a parabola's at a short window's end, so a
        noisy short fit stops Lepski's rule less often and costs less when it does.

        :raises np.linalg.LinAlgError: a window's acceleration block is singular
        """
        if isinstance(solutions, _Solutions):  # one stack: all windows at once
            stacks = [(solutions.betas, solutions.inverses)]
        else:  # windows without and with an impact's jump (9, then 12 unknowns): two stacks
            stacks = []
            fits = [self._full(*solutions[k]) for k in range(longest + 1)]
            for _, group in itertools.groupby(fits, key=lambda fit: len(fit[0])):
                betas, inverses = zip(*group)
                stacks.append((np.stack(betas), np.stack(inverses)))
        lowers: list[tuple[np.ndarray, np.ndarray]] = []
        points: list = []
        covariances: list = []
        for betas, inverses in stacks:
            betas, inverses = self._lower_order(betas, inverses, model)
            selector = position[:, :betas.shape[1]]
            points += (betas @ selector.T).tolist()
            covariances += (selector @ inverses @ selector.T).tolist()
            lowers += zip(betas, inverses)
        chosen = self._lepski(points, covariances, sigma2, _LOWER_CONSISTENCY)
        beta, inverse = lowers[chosen]
        return beta, inverse, points[chosen], covariances[chosen], points, covariances

    @staticmethod
    def _lower_order(betas: np.ndarray, inverses: np.ndarray,
                     model: int) -> tuple[np.ndarray, np.ndarray]:
        """
        Return windows' fits with their acceleration fixed (a lower-order model).

        Each is the acceleration fit under a linear constraint, so its coefficients and
        their covariance follow from the acceleration fit's solution alone; a velocity jump
        at an impact stays free.

        :param betas: (K, m) the acceleration fits' coefficients at the event (m = 9 or 12)
        :param inverses: (K, m, m) their covariances per px^2
        :param model: the column of ``_FIXED_ACCELERATIONS`` (:meth:`_lower_model`)
        :return: the lower-order fits' coefficients (K, m) and covariances (K, m, m)
        """
        gains = inverses[:, :, _ACCELERATION]  # (K, m, 3)
        offsets = betas[:, _ACCELERATION] - _FIXED_ACCELERATIONS[:, model]  # (K, 3)
        solved = np.linalg.solve(gains[:, _ACCELERATION], np.concatenate(
            (offsets[:, :, None], gains.transpose(0, 2, 1)), axis=2))  # (K, 3, 1 + m)
        lower_betas = betas - np.matmul(gains, solved[:, :, :1])[:, :, 0]
        lower_betas[:, _ACCELERATION] = _FIXED_ACCELERATIONS[:, model]
        return lower_betas, inverses - np.matmul(gains, solved[:, :, 1:])

    def _fixed_fallback(self, velocity: _Fits, system: tuple[np.ndarray, np.ndarray],
                        stamp: int, first: int, position: np.ndarray,
                        index: int) -> tuple[_Fits, int, bool] | None:
        """
        Choose a velocity or free-fall fit of frames [first, _end) where no acceleration fit is.

        There the window is long enough for acceleration, but no window determined it: one
        camera carried the path for a while, and its depth rests on the other cameras'
        older rays (a burst of one camera's wrong blobs, all rejected; a camera silent).
        The velocity fit over the whole window missed gravity there (0.98 m off 0.9 s after
        a bounce); the free fall does not.  The one with the smaller residuals serves.
        Its residuals beyond the noise (:meth:`_misfits`) show it biased: no estimate,
        though the path still predicts from it (the gate judges by it, as before).  But
        first, where one frame's removal alone explains the misfit, that frame is an outlier
        and is dropped (:meth:`_remove_misfit`): a restart's first frames are not gated, and
        a wrong blob among them kept every such fit biased.

        :param velocity: the velocity fit (:meth:`_fits`) of the frames
        :param system: their normal system at ``stamp`` (1, m, m), (1, m), m >= 9
        :return: ``(fit, model, biased)``, the model a column of ``_FIXED_ACCELERATIONS``;
            or None when a frame was dropped (fit again)
        """
        end = self._end
        squares, without = self._fixed_squares(stamp, first, end)
        model = int(np.argmin(squares))
        fit: _Fits | None = velocity
        if model:
            matrix = system[0][:, _CV][:, :, _CV]
            offset = system[0][:, _CV][:, :, _ACCELERATION] @ _FIXED_ACCELERATIONS[:, model]
            fit = self._fits(matrix, system[1][:, _CV] - offset, np.array((end - first,)),
                             _CV, position, index)
            if fit is None:
                fit, model = velocity, 0
        if self._remove_misfit(first, float(squares[model]), without):
            return None
        assert fit is not None, 'the velocity fit was kept'
        return fit, model, self._misfits(float(squares[model]), end - first)

    def _misfits(self, squares: float, frames: int) -> bool:
        """
        Return whether a velocity or free-fall fit's residuals [px^2] are beyond the noise.

        The chi-square bound (``_MISFIT_P``) of its degrees of freedom at
        ``_MISFIT_NOISE_FACTOR`` times the measured noise (1 px before it is measured).
        """
        freedom = 2 * frames - len(_CV)
        sigma = self.sigma_px if self.sigma_px is not None and \
            self._sigma_count >= _SIGMA_PROVISIONAL else _PROVISIONAL_SIGMA_PX
        return freedom > 0 and squares > chdtri(freedom, _MISFIT_P) * \
            (_MISFIT_NOISE_FACTOR * sigma) ** 2

    def _remove_misfit(self, first: int, squares: float, without: np.ndarray) -> bool:
        """
        Remove the one frame whose removal alone explains a misfit; return whether one was.

        Where the fit of frames [first, _end) misfits (:meth:`_misfits`), the frame whose
        removal lowers the residuals most is an outlier if the F test (2 and the remaining
        degrees of freedom, ``_MISFIT_P`` over the frames) finds that drop beyond the
        remaining residuals' spread; it is removed (``outlier``).  Not while an impact is
        being decided (the frames after it are held elsewhere).

        :param squares: the fit's residual sum of squares [px^2]
        :param without: (N,) the same without each frame (:meth:`_fixed_squares`)
        """
        frames = self._end - first
        freedom = 2 * frames - len(_CV) - 2
        if freedom <= 0 or self._tentative is not None or self._bounce_check is not None or \
                not self._misfits(squares, frames):
            return False
        skip = int(np.argmin(without))
        rest = float(without[skip])
        if not (squares - rest) / 2.0 > fdtri(2, freedom, 1.0 - _MISFIT_P / frames) * \
                rest / freedom:
            return False
        # (Not recorded as its camera's rejected detection: it was fitted, and may be older
        # than that camera's newest frame.)  Nor given to the paper's method again.
        name, stamp = self._names[int(self._camera[first + skip])], int(self._stamp[first + skip])
        for item in self._recent:
            if item.observation.camera == name and item.observation.stamp_ns == stamp:
                self._recent.remove(item)
                break
        self._remove(first + skip)
        self._removed = True
        self.stats['outlier'] += 1
        return True

    def _fixed_squares(self, stamp: int, first: int,
                       end: int) -> tuple[np.ndarray, np.ndarray]:
        """
        Return the residual sums of squares [px^2] of frames [first, end) per fixed acceleration.

        Least squares of the position and velocity with each of ``_FIXED_ACCELERATIONS``'
        accelerations (the frames' weights make the residuals pixels).

        :return: ``(squares (M,), without (N,))``: the sums per model, and the smallest sum
            over the models with each frame left out (inf where the rest do not determine
            the fit), by the leave-one-out identity ``S - e^T (I - H)^-1 e`` of the frame's
            residuals ``e`` and its block ``H`` of the hat matrix
        """
        design, rhs = self._weighted_design(stamp, first, end)
        velocity = design[:, :, _CV]  # (N, 2, 6)
        rows = velocity.reshape(-1, len(_CV))
        try:
            inverse = np.linalg.inv(rows.T @ rows)
        except np.linalg.LinAlgError:
            return np.full(_FIXED_ACCELERATIONS.shape[1], np.inf), np.full(end - first, np.inf)
        # Each frame's 2 x 2 block of the hat matrix, and I - H's inverse (by its adjugate).
        hat = np.einsum('nri,ij,nsj->nrs', velocity, inverse, velocity)
        a, b = 1.0 - hat[:, 0, 0], -hat[:, 0, 1]
        c, d = -hat[:, 1, 0], 1.0 - hat[:, 1, 1]
        determinant = a * d - b * c
        squares = []
        without = np.full(end - first, np.inf)
        for model in range(_FIXED_ACCELERATIONS.shape[1]):
            target = rhs - design[:, :, _ACCELERATION] @ _FIXED_ACCELERATIONS[:, model]
            solution = inverse @ (rows.T @ target.reshape(-1))
            residual = target - velocity @ solution  # (N, 2)
            total = float(np.sum(residual * residual))
            squares.append(total)
            x, y = residual[:, 0], residual[:, 1]
            with np.errstate(divide='ignore', invalid='ignore'):
                drop = (x * (d * x - b * y) + y * (a * y - c * x)) / determinant
            left = np.where(determinant > 1e-9, total - drop, np.inf)
            without = np.minimum(without, left)
        return np.array(squares), without

    def _weighted_design(self, stamp: int, first: int,
                         end: int) -> tuple[np.ndarray, np.ndarray]:
        """
        Return frames [first, end)'s rows in the coefficients at ``stamp``, weighted (pixels).

        :return: ``(design (N, 2, 12), rhs (N, 2))``, no impact's jump (its columns zero)
        """
        maps = _position_map(self._stamp[first:end] - stamp, None)
        weight = self._weight[first:end, None]
        design = np.einsum('nra,nam->nrm', self._rows[first:end], maps) * weight[:, :, None]
        return design, self._rhs[first:end] * weight

    def _window_system(self, stamp: int, first: int,
                       end: int) -> tuple[np.ndarray, np.ndarray]:
        """Return the normal system (1, 12, 12), (1, 12) of frames [first, end) at ``stamp``."""
        design, rhs = self._weighted_design(stamp, first, end)
        return (np.einsum('nri,nrj->ij', design, design)[None],
                np.einsum('nri,nr->i', design, rhs)[None])

    def _refresh_weights(self, stamp: int, beta: np.ndarray, t_break: int | None) -> None:
        """Set the weights of a new flight's first frames from its first path."""
        start, end = self._start, self._end
        stamps = self._stamp[start:end]
        positions = _position_map(stamps - stamp, None if t_break is None
                                  else stamps - t_break)[:, :, :len(beta)] @ beta
        cameras = self._camera[start:end]
        depth = np.einsum('ni,ni->n', positions - self._center[cameras],
                          self._rotation[cameras, 2])
        if np.all(depth > 0.0):
            self._weight[start:end] = self._focal[cameras] / depth
            self._rebuild(start)
            self._weights_guessed = False

    def _fits(self, matrices: np.ndarray, moments: np.ndarray, sizes: np.ndarray,
              columns: int | np.ndarray, position: np.ndarray, index: int, *,
              picks: int | None = None) -> _Fits | None:
        """
        Solve window systems; keep the determined, well-conditioned ones.

        :param matrices: (K, m, m) normal matrices at the event (m >= the unknowns),
            ``moments`` (K, m)
        :param sizes: (K,) window sizes [frames], ascending
        :param columns: the unknowns: a count (the first 9 or 12 coefficients) or an index
            array (already applied to ``matrices`` and ``moments``)
        :param position: (3, 12) map from the coefficients to the position at the event
        :param index: the event's camera
        :param picks: with ``columns`` a count: the coefficients per axis, the position being
            the first of each (4: the constant-jerk fits; ``position`` is then unused)
        :return: ``(sizes, points, covariances per px^2, solutions)``: the kept windows'
            sizes, positions at the event (3 floats each) and their covariances (3 x 3
            nested lists), with ``solutions[k] = (columns, beta (m,), inverse (m, m))``;
            or None
        """
        if picks is not None:
            count = columns
        elif isinstance(columns, int):
            count = columns
            if matrices.shape[1] != count:
                matrices, moments = matrices[:, :count, :count], moments[:, :count]
            # At the event the position is the coefficients of tau^0 (every third), unless
            # the velocity jump of an impact before it enters (the 12-coefficient fits).
            picks = 3 if count == 9 or not position[0, 9] else None
        else:
            count = len(columns)
            picks = 2  # the constant velocity's x0 x1 y0 y1 z0 z1
        # More equations (two per frame) than unknowns; sizes ascend, so a suffix.
        kept = sizes.tolist()
        first = 0 if kept and kept[0] > count // 2 else bisect.bisect_right(kept, count // 2)
        if first == len(kept):
            return None
        if first:
            kept, matrices, moments = kept[first:], matrices[first:], moments[first:]
        try:
            inverses = _inverses(matrices)
        except np.linalg.LinAlgError:
            return None
        # A (numerically) singular system leaves M M^-1 far from the identity.
        # (Ufuncs' own reductions: the array methods add a Python layer per call.)
        unit = np.add.reduce(matrices * inverses.transpose(0, 2, 1), axis=2)
        errors = np.maximum.reduce(np.abs(unit - 1.0), axis=1).tolist()
        betas = np.matmul(inverses, moments[:, :, None])[:, :, 0]
        if picks is None:  # (only with 12 unknowns: ``columns`` is a count)
            selector = position[:, :count]
            points = (betas @ selector.T).tolist()
            covariances = (selector @ inverses @ selector.T).tolist()
        else:
            # x0, y0, z0: the first three of every ``picks`` coefficients.
            points = betas[:, :3 * picks:picks].tolist()
            covariances = inverses[:, :3 * picks:picks, :3 * picks:picks].tolist()
        # The standard deviation in the camera's pixels per pixel of noise is
        # sqrt(variance) * f / depth; NaN compares False (a non-finite fit is dropped).
        limit = self.max_uncertainty / self._focal_list[index]
        limit2 = limit * limit
        (c0, c1, c2), (d0, d1, d2) = self._center_rows[index], self._rotation_rows[index][2]
        good = []
        for k, ((x, y, z), covariance, error) in enumerate(zip(points, covariances, errors)):
            depth = (x - c0) * d0 + (y - c1) * d1 + (z - c2) * d2
            variance = covariance[0][0] + covariance[1][1] + covariance[2][2]
            if error < 1e-6 and depth > 0.0 and 0.0 < variance <= limit2 * depth * depth:
                good.append(k)
        if not good:
            return None
        if len(good) < len(kept):
            kept = [kept[k] for k in good]
            points = [points[k] for k in good]
            covariances = [covariances[k] for k in good]
            betas, inverses = betas[good], inverses[good]
        return kept, points, covariances, _Solutions(columns, betas, inverses)

    @staticmethod
    def _merge(first: _Fits | None, second: _Fits | None) -> _Fits | None:
        """Merge two results of :meth:`_fits` in order of window size."""
        if first is None or second is None:
            return second if first is None else first
        sizes = first[0] + second[0]
        order = sorted(range(len(sizes)), key=sizes.__getitem__)  # stable
        points = first[1] + second[1]
        covariances = first[2] + second[2]
        solutions = [first[3][k] for k in range(len(first[0]))] + \
            [second[3][k] for k in range(len(second[0]))]
        return ([sizes[k] for k in order], [points[k] for k in order],
                [covariances[k] for k in order], [solutions[k] for k in order])

    @staticmethod
    def _full(columns: int | np.ndarray, beta: np.ndarray,
              inverse: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """
        Return a solution as coefficients and their covariance per px^2.

        The first ``columns`` coefficients (9 or 12: as they are; the jump's are zero
        without an impact) or a subset (constant velocity), in place among 12 (zeros
        elsewhere).
        """
        if isinstance(columns, int):
            return beta, inverse
        full_beta = np.zeros(12)
        full_inverse = np.zeros((12, 12))
        full_beta[columns] = beta
        full_inverse[np.ix_(columns, columns)] = inverse
        return full_beta, full_inverse

    @staticmethod
    def _lepski(points: list, covariances: list, sigma2: float, consistency: float) -> int:
        """
        Return the index of the longest window consistent with every shorter one.

        :param points: the windows' positions (3 floats each), shortest window first
        :param covariances: their covariances per px^2 (3 x 3 nested lists)
        :param sigma2: the detection noise's variance [px^2]
        :param consistency: the chi-square bound (3 d.o.f.) of two windows' disagreement
        """
        count = len(points)
        if count == 1:
            return 0
        # The difference X_k - X_j of nested fits of one model has the covariance C_j - C_k
        # (X_k the more efficient); 0.9 C_k keeps the matrix positive.  Windows are tested
        # from the shortest: the first longer window k inconsistent with a shorter one ends
        # the search at k - 1.
        first = covariances[0]
        ridge = 1e-12 * sigma2 * (first[0][0] + first[1][1] + first[2][2])
        for k in range(1, count):
            xk, yk, zk = points[k]
            (l00, l01, l02), (_, l11, l12), (_, _, l22) = covariances[k]
            for j in range(k):
                xj, yj, zj = points[j]
                (s00, s01, s02), (_, s11, s12), (_, _, s22) = covariances[j]
                dx, dy, dz = xk - xj, yk - yj, zk - zj
                statistic = _inverse_form(
                    dx, dy, dz, sigma2 * (s00 - 0.9 * l00) + ridge, sigma2 * (s01 - 0.9 * l01),
                    sigma2 * (s02 - 0.9 * l02), sigma2 * (s11 - 0.9 * l11) + ridge,
                    sigma2 * (s12 - 0.9 * l12), sigma2 * (s22 - 0.9 * l22) + ridge)
                if statistic <= 0.0:
                    # Not positive where the difference of covariances is not (windows with
                    # and without an impact are not nested models): the shorter window's
                    # covariance C_j bounds it.
                    statistic = _inverse_form(
                        dx, dy, dz, sigma2 * s00 + ridge, sigma2 * s01, sigma2 * s02,
                        sigma2 * s11 + ridge, sigma2 * s12, sigma2 * s22 + ridge)
                if statistic > consistency:
                    return k - 1
        return count - 1

    def _measure_noise(self, stamp: int, index: int, residual: tuple[float, float]) -> None:
        """
        Update the detection noise from the newest frame's residual (Rice's estimator).

        The residual (standardized, two floats [px]) comes from a fit of fixed length
        (_NOISE_WINDOW frames): its systematic part (the path's curvature beyond a
        parabola at the window's end, a camera's calibration bias) is nearly the same
        at consecutive frames of a camera and cancels in their difference; the noise
        does not.
        """
        last = self._noise_residual.get(index)
        self._noise_residual[index] = (stamp, self._segment, residual)
        if last is not None and last[1] == self._segment and \
                stamp - last[0] <= self.gate.max_gaps[self._names[index]]:
            change_x, change_y = residual[0] - last[2][0], residual[1] - last[2][1]
            # Two axes, difference of two residuals: sample ~ sigma^2 * Exp(1), whose log has
            # mean log(sigma^2) - Euler's gamma. Averaging logs keeps rare large samples (a
            # curve the fit missed) from inflating the estimate.
            sample = (change_x * change_x + change_y * change_y) / 4.0
            if sample > 0.0:
                self._sigma_count += 1
                alpha = max(_SIGMA_ALPHA, 1.0 / self._sigma_count)
                log_sample = math.log(sample) + _EULER_GAMMA
                self._log_variance = log_sample if self._log_variance is None else \
                    self._log_variance + alpha * (log_sample - self._log_variance)
                self.sigma_px = max(self.min_sigma_px, math.exp(0.5 * self._log_variance))
                if self._sigma_count >= _SIGMA_MATURE:
                    self._gate_sigma = self.sigma_px
                elif self._sigma_count >= _SIGMA_PROVISIONAL:
                    self._gate_sigma = max(_PROVISIONAL_FACTOR * self.sigma_px,
                                           _PROVISIONAL_SIGMA_PX)
