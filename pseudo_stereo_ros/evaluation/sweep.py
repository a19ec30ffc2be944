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
Varied simulated cases: ``trajectory`` against ``paper`` beyond Table 1's one rig.

A :class:`Case` varies what the method never saw while it was designed: the
rig (the default one, a wider one with a longer focal length, one with lens
distortion), the frame rate (30 or 60 fps), the offset between the cameras,
the detections (rounded to 0.05 px, or 0.3 px Gaussian noise), the timing
(regular shutters, or jittered intervals with 10% of the detections
dropped) and the motion (Table 1's straight line, spiral and bouncing ball).
Both methods run on the same observations; each case reports their
per-coordinate MAE, the share of shutter events with an estimate and the
largest error.  :func:`full_cases` takes other offsets and seeds, for cases
the method was not tuned on.  :func:`impact_errors` measures the error right
after each impact of the bouncing ball.  :func:`run_strays` puts wrong blobs
among the detections (:func:`with_strays`): outlier gating and impact
detection on the same flights.  ROS-free; ``pseudo_stereo sweep`` prints it.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
import itertools
import math
from typing import NamedTuple

import numpy as np

from .table1 import Run, score, simulate_run
from ..camera import Camera
from ..fusion import fuse
from ..records import Observation, positions_array
from ..sim.scenarios import (DEFAULT_EPOCH_NS, default_rig, GRAVITY, look_at_calibration,
                             make_scenario, observe, truth_at)

__all__ = [
    'Case',
    'CaseResult',
    'RIGS',
    'StrayResult',
    'full_cases',
    'impact_errors',
    'impact_times',
    'make_rig',
    'run_case',
    'run_strays',
    'small_cases',
    'stray_runs',
    'summarize',
    'with_strays',
]

#: The volume's centre, where every rig looks [m].
_TARGET = (1.5, 1.0, 1.0)
#: Rig name -> (camera positions [m], focal length [px], image size, distortion k1, k2).
RIGS = {
    'default': (((0.0, -2.0, 3.0), (3.0, -2.0, 3.0)), 500.0, (640, 480), (0.0, 0.0)),
    'wide': (((-1.0, -2.5, 2.0), (4.5, -0.5, 3.5)), 650.0, (800, 600), (0.0, 0.0)),
    'distorted': (((0.0, -2.0, 3.0), (3.0, -2.0, 3.0)), 480.0, (752, 480), (-0.28, 0.09)),
    'three': (((0.0, -2.0, 3.0), (3.0, -2.0, 3.0), (1.5, 4.0, 3.0)), 500.0, (640, 480),
              (0.0, 0.0)),
}


class Case(NamedTuple):
    """One simulated case (see the module docstring)."""

    rig: str
    fps: float
    offset: float  # camera 2's delay as a fraction of the frame period
    noise_px: float  # Gaussian noise; 0 means rounding to 0.05 px only
    jitter: bool  # jittered shutter intervals and 10% of the detections dropped
    scenario: str
    seed: int = 0

    def label(self) -> str:
        """Return a short readable label."""
        detections = f'noise {self.noise_px:g}px' if self.noise_px else 'round 0.05px'
        timing = 'jitter+drops' if self.jitter else 'regular'
        return (f'{self.rig:<9} {self.fps:>2.0f}fps off {self.offset:.2f} {detections:<13} '
                f'{timing:<12} {self.scenario}')


class CaseResult(NamedTuple):
    """Both methods on one case: MAE [mm], coverage (share of events), largest error [m]."""

    case: Case
    paper_mae_mm: float
    mae_mm: float
    coverage: float
    max_error_m: float

    @property
    def ratio(self) -> float:
        """Return the trajectory's MAE over paper's."""
        return self.mae_mm / self.paper_mae_mm


def make_rig(name: str) -> list[Camera]:
    """Return the cameras of a rig of :data:`RIGS`, named camera1, camera2, ..."""
    positions, focal, size, (k1, k2) = RIGS[name]
    return [Camera(look_at_calibration(f'camera{k + 1}', position, _TARGET, image_size=size,
                                       focal_px=focal, dist_coeffs=[k1, k2, 0.0, 0.0, 0.0]))
            for k, position in enumerate(positions)]


def _stamps(case: Case, duration_s: float, count: int, rng) -> list[np.ndarray]:
    """Shutter stamps [ns] per camera: regular, or with jittered intervals (+-15%)."""
    period = 1.0 / case.fps
    stamps = []
    for camera in range(count):
        phase = (case.offset * camera) % 1.0 * period
        times = phase + np.arange(0.0, duration_s - phase, period)
        if case.jitter:
            times = times + rng.uniform(-0.15, 0.15, len(times)) * period
            times = np.sort(times[(times >= 0.0) & (times <= duration_s)])
        stamps.append(DEFAULT_EPOCH_NS + np.round(times * 1e9).astype(np.int64))
    return stamps


def simulate_case(case: Case, cameras: Sequence[Camera]):
    """Return (observations, truth stamps (N,), truth points (N, 3)) of a case."""
    scenario = make_scenario(case.scenario)
    rng = np.random.default_rng(case.seed)
    stamps = _stamps(case, scenario.duration_s, len(cameras), rng)
    observations = observe(scenario, cameras, stamps, noise_px=case.noise_px,
                           quantization_px=0.05, dropout=0.1 if case.jitter else 0.0,
                           seed=case.seed)
    truth_stamps = np.unique(np.concatenate(stamps))
    return observations, truth_stamps, truth_at(scenario, truth_stamps)


def run_case(case: Case, *, cameras: Sequence[Camera] | None = None,
             **options) -> CaseResult:
    """
    Run ``paper`` (first two cameras) and ``trajectory`` (all cameras) on one case.

    :param case: the case
    :param cameras: the rig (default: :func:`make_rig` of the case)
    :param options: options of the trajectory fuser
    :return: the result
    """
    cameras = make_rig(case.rig) if cameras is None else list(cameras)
    observations, truth_stamps, truth_points = simulate_case(case, cameras)
    pair = {camera.name for camera in cameras[:2]}
    paper, _ = fuse(cameras[:2], [o for o in observations if o.camera in pair])
    estimates, _ = fuse(cameras, observations, method='trajectory', **options)
    events = len({o.stamp_ns for o in observations})
    return CaseResult(case, score(paper, truth_stamps, truth_points).mae_mm,
                      score(estimates, truth_stamps, truth_points).mae_mm,
                      len(estimates) / events,
                      _largest_error_m(estimates, truth_stamps, truth_points))


def _largest_error_m(estimates, truth_stamps: np.ndarray, truth_points: np.ndarray) -> float:
    """Return the largest 3D error [m] of estimates at shutter stamps among the truth's."""
    index = np.searchsorted(truth_stamps, [e.stamp_ns for e in estimates])
    return float(np.linalg.norm(positions_array(estimates) - truth_points[index],
                                axis=1).max())


def small_cases() -> list[Case]:
    """Return the in-suite sweep: every rig, rate, detection and timing, a few combinations."""
    cases = []
    rigs = ('default', 'wide', 'distorted')
    for k, (scenario, noise, jitter) in enumerate(itertools.product(
            ('straight', 'spiral', 'bounce'), (0.0, 0.3), (False, True))):
        cases.append(Case(rigs[k % 3], (30.0, 60.0)[k // 3 % 2], (0.5, 0.3)[k % 2], noise,
                          jitter, scenario, seed=k))
    return cases


def full_cases(*, offsets: Sequence[float] = (0.5, 0.3), seed_offset: int = 0) -> list[Case]:
    """
    Return the full sweep: every combination (144 cases with two offsets).

    :param offsets: camera 2's delays as fractions of the frame period (the defaults are
        the cases the method was tuned on; the README's unseen cases use 0.4 and 0.2)
    :param seed_offset: added to each case's seed (the unseen cases: 1000)
    """
    return [Case(rig, fps, offset, noise, jitter, scenario, seed=k + seed_offset)
            for k, (rig, fps, offset, noise, jitter, scenario) in enumerate(itertools.product(
                ('default', 'wide', 'distorted'), (30.0, 60.0), tuple(offsets), (0.0, 0.3),
                (False, True), ('straight', 'spiral', 'bounce')))]


def summarize(results: Sequence[CaseResult]) -> dict[str, float]:
    """Return the geometric-mean ratio, the worst ratio, coverage and largest error."""
    ratios = np.array([r.ratio for r in results])
    return {'geometric_mean_ratio': float(np.exp(np.mean(np.log(ratios)))),
            'worst_ratio': float(ratios.max()),
            'lowest_coverage': float(min(r.coverage for r in results)),
            'largest_error_m': float(max(r.max_error_m for r in results))}


def impact_times(height: float = 2.0, restitution: float = 0.8, duration: float = 2.0):
    """Return the times [s] of the ``bounce`` scenario's impacts (its default parameters)."""
    times: list[float] = []
    t0, z0, vz0 = 0.0, height, 0.0
    while True:  # as the scenario: piecewise parabolas off the floor z = 0
        t_hit = (vz0 + math.sqrt(vz0 * vz0 + 2 * GRAVITY * z0)) / GRAVITY
        if t0 + t_hit > duration:
            return times
        times.append(t0 + t_hit)
        t0, z0, vz0 = t0 + t_hit, 0.0, -restitution * (vz0 - GRAVITY * t_hit)


def impact_errors(estimates, truth_stamps: np.ndarray, truth_points: np.ndarray,
                  impacts_s: Sequence[float], *, events: int = 4,
                  observations: Sequence[Observation] = ()) -> np.ndarray:
    """
    Errors [m] at the first shutter events after each impact.

    :param estimates: a method's estimates
    :param truth_stamps: (N,) truth stamps [ns] (every shutter event)
    :param truth_points: (N, 3) truth [m]
    :param impacts_s: impact times [s] from the scenario's start
    :param events: shutter events counted after each impact
    :param observations: when given, only events with an observation count
    :return: (impacts, events) 3D errors [m]; NaN where the method gave no estimate
    """
    by_stamp = {e.stamp_ns: np.array((e.x, e.y, e.z)) for e in estimates}
    truth = dict(zip(np.asarray(truth_stamps).tolist(), truth_points))
    shutters = np.array(sorted({o.stamp_ns for o in observations} or truth))
    out = np.full((len(impacts_s), events), np.nan)
    for row, impact in enumerate(impacts_s):
        first = np.searchsorted(shutters, DEFAULT_EPOCH_NS + int(round(impact * 1e9)))
        for column, stamp in enumerate(shutters[first:first + events]):
            if stamp in by_stamp:
                out[row, column] = np.linalg.norm(by_stamp[stamp] - truth[stamp])
    return out


def with_strays(observations: Sequence[Observation], *, seed: int, share: float = 0.02,
                low_px: float = 5.0, high_px: float = 60.0,
                skip: int = 20) -> tuple[list[Observation], set[int]]:
    """
    Move a share of the detections to wrong blobs: ``low_px`` to ``high_px`` away, any direction.

    :param observations: the detections, in stamp order
    :param seed: of the random choice
    :param share: the share of the detections moved (after the first ``skip``)
    :return: (the detections with the stray ones, the indices moved)
    """
    rng = np.random.default_rng(seed)
    count = round(share * len(observations))
    stray = set(rng.choice(np.arange(skip, len(observations)), count, replace=False).tolist())
    out = []
    for k, o in enumerate(observations):
        if k in stray:
            angle, size = rng.uniform(0.0, 2.0 * math.pi), rng.uniform(low_px, high_px)
            o = o._replace(u=o.u + size * math.cos(angle), v=o.v + size * math.sin(angle))
        out.append(o)
    return out, stray


class StrayResult(NamedTuple):
    """One flight with stray detections: MAE [mm] with and without them, paper's, counts."""

    scenario: str
    fps: float
    seed: int
    offset: float
    mae_mm: float
    clean_mae_mm: float
    paper_mae_mm: float
    max_error_m: float
    strays: int
    stats: Counter[str]  # the trajectory fuser's counters (0 for a reason never seen)

    @property
    def ratio(self) -> float:
        """Return the trajectory's MAE over paper's, both with the stray detections."""
        return self.mae_mm / self.paper_mae_mm


def run_strays(scenario: str, fps: float, seed: int, *, offset: float = 0.5,
               **options) -> StrayResult:
    """
    Run ``trajectory`` and ``paper`` on Table 1's rig with 2 % stray detections (from 5 px).

    0.3 px noise; the strays' seed is ``seed + 100``.

    :param scenario: ``bounce``, ``spiral`` or ``straight``
    :param fps: the frame rate
    :param seed: the noise's seed
    :param offset: camera 2's delay as a fraction of the frame period (0: synchronized)
    :param options: options of the trajectory fuser
    """
    cameras = default_rig()
    data = simulate_run(Run(scenario, fps=fps, delta12_s=offset / fps, noise_px=0.3,
                            seed=seed), cameras)
    noisy, stray = with_strays(data.observations, seed=seed + 100)
    ours, stats = fuse(cameras, noisy, method='trajectory', **options)
    clean, _ = fuse(cameras, data.observations, method='trajectory', **options)
    paper, _ = fuse(cameras, noisy)
    return StrayResult(scenario, fps, seed, offset,
                       score(ours, data.truth_stamps, data.truth_points).mae_mm,
                       score(clean, data.truth_stamps, data.truth_points).mae_mm,
                       score(paper, data.truth_stamps, data.truth_points).mae_mm,
                       _largest_error_m(ours, data.truth_stamps, data.truth_points),
                       len(stray), stats)


def stray_runs(seeds: Sequence[int] = range(1, 31)) -> list[tuple[str, float, int]]:
    """Return the README's stray-detection runs: bounce and spiral, 30 and 60 fps, the seeds."""
    return list(itertools.product(('bounce', 'spiral'), (30.0, 60.0), seeds))
