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
The simulated rig of the paper's Section 3: trajectories, shutters, observations.

Times inside a scenario are seconds from its start (floats are exact enough
for a few seconds); shutter stamps are integer nanoseconds from
:data:`DEFAULT_EPOCH_NS`, a realistic ROS time near 1.7e18 ns, so that
everything downstream is exercised with real-sized stamps.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
import math

import numpy as np

from ..calibration import CameraCalibration
from ..camera import Camera
from ..records import Observation
from ..rig import Rig

__all__ = [
    'DEFAULT_EPOCH_NS',
    'SCENARIOS',
    'Scenario',
    'default_rig',
    'look_at_calibration',
    'make_scenario',
    'observe',
    'shutter_stamps',
    'truth_at',
]

#: 2023-11-14T22:13:20Z in ns: stamps of this size lose precision as float seconds.
DEFAULT_EPOCH_NS = 1_700_000_000_000_000_000
GRAVITY = 9.8  # m/s^2, as in the paper


@dataclass(frozen=True)
class Scenario:
    """
    A ball trajectory: ``position(t)`` maps (N,) seconds to (N, 3) world points [m].

    ``duration_s`` is how long it lasts and ``description`` says what it is.
    """

    name: str
    duration_s: float
    position: Callable[[np.ndarray], np.ndarray]
    description: str


def _straight(speed: float = 3.0) -> Scenario:
    start, end = np.array((0.0, 1.2, 2.0)), np.array((3.0, 1.2, 0.0))
    length = float(np.linalg.norm(end - start))
    direction = (end - start) / length

    def position(t):
        return start + np.outer(np.asarray(t, dtype=float) * speed, direction)

    return Scenario('straight', length / speed, position,
                    f'uniform straight line (0, 1.2, 2) -> (3, 1.2, 0) m at {speed} m/s')


def _spiral(speed: float = 3.0, radius: float = 0.62, height: float = 2.0,
            turns: float = 1.0) -> Scenario:
    # The paper gives no pitch: one turn over the 2 m height of the volume, descending.
    turn_length = math.hypot(2 * math.pi * radius, height / turns)
    duration = turns * turn_length / speed
    omega = 2 * math.pi * turns / duration

    def position(t):
        t = np.asarray(t, dtype=float)
        angle = omega * t
        return np.column_stack((1.0 + radius * np.cos(angle), 1.0 + radius * np.sin(angle),
                                height - height * t / duration))

    return Scenario('spiral', duration, position,
                    f'uniform spiral, radius {radius} m about (1, 1), {turns:g} turn over '
                    f'{height} m, {speed} m/s')


def _bounce(height: float = 2.0, vx: float = 0.8, restitution: float = 0.8,
            duration: float = 2.0) -> Scenario:
    # Piecewise parabolas: a drop from `height`, then bounces off the floor z = 0.
    segments = []  # (start time, z0, vz0)
    t0, z0, vz0 = 0.0, height, 0.0
    while t0 < duration:
        t_hit = (vz0 + math.sqrt(vz0 * vz0 + 2 * GRAVITY * z0)) / GRAVITY
        segments.append((t0, z0, vz0))
        vz_impact = vz0 - GRAVITY * t_hit
        t0, z0, vz0 = t0 + t_hit, 0.0, -restitution * vz_impact
    starts = np.array([s[0] for s in segments])

    def position(t):
        t = np.asarray(t, dtype=float)
        index = np.clip(np.searchsorted(starts, t, side='right') - 1, 0, len(segments) - 1)
        seg = np.array(segments)[index]
        dt = t - seg[:, 0]
        z = seg[:, 1] + seg[:, 2] * dt - 0.5 * GRAVITY * dt * dt
        return np.column_stack((0.6 + vx * t, np.full_like(t, 1.0), z))

    return Scenario('bounce', duration, position,
                    f'non-uniform: falls from {height} m moving {vx} m/s in x, bounces '
                    f'(restitution {restitution}), g = {GRAVITY} m/s^2')


def _turntable(radius: float = 0.5, height: float = 0.65, rpm: float = 45.0,
               duration: float = 2.0) -> Scenario:
    omega = rpm / 60.0 * 2 * math.pi  # 4.712 rad/s (the paper's "0.478" is a slip)

    def position(t):
        angle = omega * np.asarray(t, dtype=float)
        return np.column_stack((1.5 + radius * np.cos(angle), 1.0 + radius * np.sin(angle),
                                np.full_like(angle, height)))

    return Scenario('turntable', duration, position,
                    f'Section 4 turntable: radius {radius} m at height {height} m, {rpm:g} rpm')


#: Scenario name -> factory taking keyword overrides of its parameters.
SCENARIOS: dict[str, Callable[..., Scenario]] = {
    'straight': _straight,
    'spiral': _spiral,
    'bounce': _bounce,
    'turntable': _turntable,
}


def make_scenario(name: str, **parameters) -> Scenario:
    """
    Return the named scenario (see :data:`SCENARIOS`).

    :raises ValueError: for an unknown name
    """
    if name not in SCENARIOS:
        raise ValueError(f'unknown scenario {name!r} (known: {", ".join(SCENARIOS)})')
    return SCENARIOS[name](**parameters)


def shutter_stamps(fps: float, duration_s: float, *, phase_s: float = 0.0,
                   epoch_ns: int = DEFAULT_EPOCH_NS) -> np.ndarray:
    """
    Shutter stamps of a free-running camera.

    :param fps: frame rate [Hz]
    :param duration_s: length of the recording [s]
    :param phase_s: time of the first shutter after the start [s]; the delay to another camera
    :param epoch_ns: the stamp of the scenario's time 0 [ns]
    :return: (N,) int64 stamps [ns] with ``0 <= stamp - epoch_ns <= duration``
    """
    if not fps > 0:
        raise ValueError(f'fps must be positive, got {fps}')
    period_ns = 1e9 / fps
    phase_ns = round(phase_s * 1e9) % round(period_ns)
    count = int(math.floor((duration_s * 1e9 - phase_ns) / period_ns)) + 1
    offsets = phase_ns + np.round(np.arange(max(count, 0)) * period_ns).astype(np.int64)
    return np.int64(epoch_ns) + offsets


def truth_at(scenario: Scenario, stamps_ns: np.ndarray, *,
             epoch_ns: int = DEFAULT_EPOCH_NS) -> np.ndarray:
    """Return the (N, 3) true positions [m] at (N,) integer stamps [ns]."""
    seconds = (np.asarray(stamps_ns, dtype=np.int64) - np.int64(epoch_ns)) / 1e9
    return scenario.position(seconds)


def observe(scenario: Scenario, cameras: Sequence[Camera], stamps: Sequence[np.ndarray], *,
            noise_px: float = 0.0, quantization_px: float = 0.05, dropout: float = 0.0,
            seed: int = 0, epoch_ns: int = DEFAULT_EPOCH_NS) -> list[Observation]:
    """
    Project the trajectory into each camera at its shutter stamps.

    :param scenario: the trajectory
    :param cameras: the cameras
    :param stamps: per camera, (N_i,) shutter stamps [ns]
    :param noise_px: standard deviation of Gaussian pixel noise [px]
    :param quantization_px: sub-pixel step the detections are rounded to [px]
        (0.05 px reproduces the paper's non-zero synchronized errors; 0 disables)
    :param dropout: probability that a detection is missed
    :param seed: random seed (noise and dropout)
    :param epoch_ns: the stamp of the scenario's time 0 [ns]
    :return: observations of points inside the images, sorted by stamp
    """
    rng = np.random.default_rng(seed)
    observations: list[Observation] = []
    for camera, camera_stamps in zip(cameras, stamps):
        camera_stamps = np.asarray(camera_stamps, dtype=np.int64)
        pixels = camera.project(truth_at(scenario, camera_stamps, epoch_ns=epoch_ns))
        if noise_px > 0:
            pixels = pixels + rng.normal(0.0, noise_px, pixels.shape)
        if quantization_px > 0:
            pixels = np.round(pixels / quantization_px) * quantization_px
        keep = camera.in_image(pixels)
        if dropout > 0:
            keep &= rng.random(len(pixels)) >= dropout
        observations.extend(Observation(camera.name, int(stamp), float(u), float(v))
                            for stamp, (u, v) in zip(camera_stamps[keep], pixels[keep]))
    observations.sort(key=lambda obs: obs.stamp_ns)
    return observations


def look_at_calibration(name: str, position: Sequence[float], target: Sequence[float], *,
                        image_size=(640, 480), focal_px: float = 500.0,
                        distortion_model: str = 'plumb_bob',
                        dist_coeffs: Sequence[float] | None = None) -> CameraCalibration:
    """
    Build the calibration of a camera at ``position`` looking at ``target`` (world z up).

    :param name: camera name
    :param position: optical centre (3,) [m]
    :param target: a world point on the optical axis (3,) [m]
    :param image_size: (width, height) [px]; the principal point is the image centre
    :param focal_px: focal length [px]
    :param distortion_model: a model of :data:`calibration.DISTORTION_MODELS`
    :param dist_coeffs: its coefficients (zeros by default)
    """
    center = np.asarray(position, dtype=float)
    forward = np.asarray(target, dtype=float) - center
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, (0.0, 0.0, 1.0))
    if np.linalg.norm(right) < 1e-9:
        raise ValueError('the camera looks straight up or down; choose another target')
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    rotation = np.vstack((right, down, forward))  # rows: camera x, y, z axes in the world
    width, height = image_size
    camera_matrix = np.array(((focal_px, 0.0, (width - 1) / 2.0),
                              (0.0, focal_px, (height - 1) / 2.0), (0.0, 0.0, 1.0)))
    if dist_coeffs is None:
        dist_coeffs = [0.0] * (8 if distortion_model == 'rational_polynomial' else
                               4 if distortion_model == 'equidistant' else 5)
    return CameraCalibration(
        camera_name=name, image_width=int(width), image_height=int(height),
        camera_matrix=camera_matrix, distortion_model=distortion_model,
        dist_coeffs=np.asarray(dist_coeffs, dtype=float), rotation=rotation,
        translation=-rotation @ center)


def default_rig() -> list[Camera]:
    """Return the two cameras of the default rig (``config/rig/camera{1,2}.yaml``)."""
    return Rig.default().cameras
