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
Simulated recordings with per-camera stamp errors, for the time-offset and refine experiments.

:func:`simulate_flights` plays several scenarios one after another (each a
"flight", with a pause between them in which the ball is out of view) in
front of free-running cameras, and stamps each camera's detections with a
stamp error: the recorded stamp is ``true - offset``, so adding the camera's
``time_offset_s`` gives the true shutter time back.  The truth is returned
on the common (true) clock.  ROS-free.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Dict, List, Mapping, Optional, Sequence, Union

import cv2
import numpy as np

from ..calibration import CameraCalibration
from ..camera import Camera
from ..records import Observation
from ..sim.scenarios import (DEFAULT_EPOCH_NS, GRAVITY, make_scenario, observe, Scenario,
                             shutter_stamps)
from ..stamps import seconds_to_ns

__all__ = ['FlightRecording', 'THROW_VOLUME_M', 'ballistic_throw', 'event_errors_mm',
           'perturbed_calibration', 'random_throws', 'simulate_flights', 'truth_at_stamps']

#: The box [m] (x, y, z lows; x, y, z highs) where throws of the default rig start and end: both
#: cameras see it whole, and nearly all of the arcs above it, from 2 to 6 m away.
THROW_VOLUME_M = ((-0.5, 0.0, 0.0), (3.5, 4.0, 1.5))


@dataclass(frozen=True)
class FlightRecording:
    """
    Observations with raw stamps, and the truth on the common clock.

    ``observations`` carry the cameras' raw stamps [ns]; ``truth_stamps_ns``
    (N,) and ``truth_points`` (N, 3) [m] the true ball at every true shutter
    time of any camera; ``flights`` the (start, end) true stamps of each
    scenario.
    """

    observations: List[Observation]
    truth_stamps_ns: np.ndarray
    truth_points: np.ndarray
    flights: List[tuple]
    offsets_s: Dict[str, float]


def ballistic_throw(start: Union[Sequence[float], np.ndarray],
                    end: Union[Sequence[float], np.ndarray],
                    duration_s: float) -> Scenario:
    """
    Return a throw: a free parabola (gravity along -z) from ``start`` to ``end`` [m].

    :param start: where the ball leaves the hand (3,) [m]
    :param end: where it is caught ``duration_s`` later (3,) [m]
    :param duration_s: flight time [s]
    """
    begin = np.asarray(start, dtype=float)
    finish = np.asarray(end, dtype=float)
    velocity = (finish - begin) / duration_s + np.array((0.0, 0.0, 0.5 * GRAVITY * duration_s))

    def position(t):
        t = np.asarray(t, dtype=float)[:, None]
        return begin + velocity * t - np.array((0.0, 0.0, 0.5 * GRAVITY)) * t * t

    return Scenario('throw', float(duration_s), position,
                    f'throw {np.round(begin, 2)} -> {np.round(finish, 2)} m in {duration_s:.2f} s')


def random_throws(count: int, *, seed: int = 0, duration_s: tuple = (0.6, 1.0),
                  volume_m: tuple = THROW_VOLUME_M) -> List[Scenario]:
    """
    Return ``count`` throws between random points of a box, in random directions.

    What a user does "with a few throws of a ball": across the view, towards
    and away from the cameras, high and low.  Start and end are drawn
    uniformly in ``volume_m``, the flight time in ``duration_s``.

    :param count: number of throws
    :param seed: random seed
    :param duration_s: (shortest, longest) flight time [s]
    :param volume_m: ((x, y, z) low, (x, y, z) high) corners of the box [m]
    """
    rng = np.random.default_rng(seed)
    low, high = (np.asarray(corner, dtype=float) for corner in volume_m)
    return [ballistic_throw(rng.uniform(low, high), rng.uniform(low, high),
                            float(rng.uniform(*duration_s))) for _ in range(count)]


def simulate_flights(cameras: Sequence[Camera], *, offsets_s: Mapping[str, float],
                     scenarios: Sequence[Union[str, Scenario]] = ('spiral', 'bounce',
                                                                  'straight'),
                     fps: float = 30.0, phases_s: Optional[Sequence[float]] = None,
                     noise_px: float = 0.0, quantization_px: float = 0.05,
                     pause_s: float = 0.5, dropout: float = 0.0, seed: int = 0,
                     epoch_ns: int = DEFAULT_EPOCH_NS,
                     scenario_options: Optional[Mapping[str, dict]] = None) -> FlightRecording:
    """
    Simulate flights seen by free-running cameras whose stamps are off by ``-offset``.

    :param cameras: the cameras (their calibrations are the truth)
    :param offsets_s: camera name -> true offset [s] (recorded stamp = true time - offset)
    :param scenarios: scenarios (or their names), played in order with ``pause_s`` between
        them
    :param fps: frame rate of every camera [Hz]
    :param phases_s: per camera, its first shutter after the start [s] (default: evenly
        spread over one frame period)
    :param noise_px: Gaussian pixel noise [px]
    :param quantization_px: sub-pixel step of detections [px]
    :param pause_s: ball out of view between flights [s]
    :param dropout: probability of a missed detection
    :param seed: random seed
    :param epoch_ns: true time of the first flight's start [ns]
    :param scenario_options: scenario name -> keyword overrides of its parameters
    :return: the recording
    """
    options = dict(scenario_options or {})
    flights, start = [], 0.0
    for name in scenarios:
        scenario = (name if isinstance(name, Scenario)
                    else make_scenario(name, **options.get(name, {})))
        flights.append((start, scenario))
        start += scenario.duration_s + pause_s
    duration = start
    if phases_s is None:
        phases_s = [k / (len(cameras) * fps) for k in range(len(cameras))]
    stamps = [shutter_stamps(fps, duration, phase_s=phase, epoch_ns=epoch_ns)
              for phase in phases_s]
    observations, truth_stamps, truth_points, bounds = [], [], [], []
    for number, (begin, scenario) in enumerate(flights):
        begin_ns = epoch_ns + seconds_to_ns(begin)
        end_ns = begin_ns + seconds_to_ns(scenario.duration_s)
        inside = [s[(s >= begin_ns) & (s <= end_ns)] for s in stamps]
        observations += observe(scenario, cameras, inside, noise_px=noise_px,
                                quantization_px=quantization_px, dropout=dropout,
                                seed=seed + 1000 * number, epoch_ns=begin_ns)
        every = np.unique(np.concatenate(inside))
        truth_stamps.append(every)
        truth_points.append(scenario.position((every - begin_ns) / 1e9))
        bounds.append((begin_ns, end_ns))
    shift = {camera.name: seconds_to_ns(offsets_s.get(camera.name, 0.0)) for camera in cameras}
    raw = [obs._replace(stamp_ns=obs.stamp_ns - shift[obs.camera]) for obs in observations]
    raw.sort(key=lambda obs: obs.stamp_ns)
    return FlightRecording(raw, np.concatenate(truth_stamps), np.vstack(truth_points), bounds,
                           {camera.name: float(offsets_s.get(camera.name, 0.0))
                            for camera in cameras})


def truth_at_stamps(recording: FlightRecording, stamps_ns: np.ndarray) -> np.ndarray:
    """
    Return the true positions (M, 3) [m] at true stamps (NaN rows where unknown).

    Exact at the recording's truth stamps; other stamps get NaN (scores then use
    only estimates stamped at true shutter times).
    """
    stamps_ns = np.asarray(stamps_ns, dtype=np.int64)
    index = np.searchsorted(recording.truth_stamps_ns, stamps_ns)
    index = np.minimum(index, len(recording.truth_stamps_ns) - 1)
    found = recording.truth_stamps_ns[index] == stamps_ns
    points = np.full((len(stamps_ns), 3), np.nan)
    points[found] = recording.truth_points[index[found]]
    return points


def event_errors_mm(recording: FlightRecording, estimates: Sequence,
                    applied_offsets_s: Mapping[str, float]) -> np.ndarray:
    """
    Return the 3D errors [mm] of estimates against the truth at their events' true times.

    An estimate belongs to a shutter event of ``estimate.camera``; its stamp is
    that camera's raw stamp plus the offset that was applied.  The true time of
    the event is the raw stamp plus the camera's true offset, so estimates are
    scored against the right instant whatever offsets (none, estimated, true)
    were applied.

    :param recording: the simulated recording (true offsets and truth)
    :param estimates: the fuser's estimates
    :param applied_offsets_s: camera -> the offset [s] that was added to its stamps
    :return: (N,) distances [mm] (estimates without a truth sample left out)
    """
    stamps = np.array([e.stamp_ns - seconds_to_ns(applied_offsets_s.get(e.camera, 0.0))
                       + seconds_to_ns(recording.offsets_s.get(e.camera, 0.0))
                       for e in estimates], dtype=np.int64)
    truth = truth_at_stamps(recording, stamps)
    points = np.array([(e.x, e.y, e.z) for e in estimates], dtype=float).reshape(-1, 3)
    found = np.all(np.isfinite(truth), axis=1)
    return 1e3 * np.linalg.norm(points[found] - truth[found], axis=1)


def perturbed_calibration(calibration: CameraCalibration, *, degrees: float, metres: float,
                          seed: int = 0) -> CameraCalibration:
    """
    Return a calibration rotated by ``degrees`` about a random axis and moved ``metres``.

    :param calibration: the true calibration
    :param degrees: rotation angle [deg] (about a random axis through the optical centre)
    :param metres: distance the optical centre moves, in a random direction [m]
    :param seed: random seed of the axis and the direction
    """
    rng = np.random.default_rng(seed)
    axis = rng.normal(size=3)
    direction = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    direction /= np.linalg.norm(direction)
    rotation = cv2.Rodrigues(axis * np.radians(degrees))[0] @ calibration.rotation
    centre = calibration.center + metres * direction
    return replace(calibration, rotation=rotation, translation=-rotation @ centre)
