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
The optimised detector against the detector before its latency work, frame by frame.

:class:`detection_reference.ReferenceDetector` is the old search (the square
window around the last detection, then the full frame) and the old centroid.
The detections must be equal to the last bit on rendered flights (three
cameras, three noise levels, windowed and full frame) and on messy
sequences (drops, doubled frames, jumps, frames without a ball, specks,
bounces, a ball leaving the image, other encodings, the ``nearest``
choice), while the tight window around the predicted position is used
for most frames.  The one place they may differ by design (a larger
orange object inside the square but away from the predicted position) is
checked against the ground truth.
"""

import cv2
from detection_reference import ReferenceDetector
import numpy as np
from pseudo_stereo_ros.camera import Camera
from pseudo_stereo_ros.detection import BallDetector
from pseudo_stereo_ros.sim.rendering import BallRenderer
from pseudo_stereo_ros.sim.scenarios import (default_rig, look_at_calibration, make_scenario,
                                             shutter_stamps, truth_at)
import pytest


def _cameras():
    third = Camera(look_at_calibration('camera3', (0.0, -3.0, 1.5), (1.0, 1.0, 1.0),
                                       dist_coeffs=[-0.25, 0.08, 0.001, -0.001, 0.0]))
    return default_rig() + [third]


def _flight(name: str, fps: float = 30.0) -> np.ndarray:
    scenario = make_scenario(name)
    return truth_at(scenario, shutter_stamps(fps, scenario.duration_s))


def _compare(images, encoding='bgr8', **options):
    """Run both detectors over ``images``; return the new one (its counts) and the pairs."""
    reference, detector = ReferenceDetector(**options), BallDetector(**options)
    pairs = [(reference.detect(image, encoding), detector.detect(image, encoding))
             for image in images]
    return detector, pairs


def _assert_identical(pairs):
    differing = [(i, old, new) for i, (old, new) in enumerate(pairs) if old != new]
    assert not differing, f'{len(differing)} of {len(pairs)} differ, first: {differing[:3]}'


@pytest.mark.parametrize('camera_index', [0, 1, 2])
def test_detections_are_bit_identical_on_rendered_flights(camera_index):
    camera = _cameras()[camera_index]
    compared = tight = windowed = 0
    runs = [(scenario, noise) for scenario in ('spiral', 'bounce') for noise in (0.0, 2.0, 8.0)]
    runs += [('straight', 2.0), ('turntable', 2.0)]
    for scenario, noise in runs:
        renderer = BallRenderer(camera, noise_std=noise, seed=camera_index)
        images = [renderer.render(p) for p in _flight(scenario)]
        detector, pairs = _compare(images, search_window_px=48)
        _assert_identical(pairs)
        assert all(new is not None for _, new in pairs)
        tight += detector.stats['tight_hits']
        windowed += len(images)
        # The full frame (no window) on every sixth frame: the same code after the search.
        _, full = _compare(images[::6], search_window_px=0)
        _assert_identical(full)
        compared += len(pairs) + len(full)
    assert compared >= 450
    # The tight window is the usual path (it misses at the bounces' impacts).
    assert tight >= 0.85 * windowed


def _specks(image, rng, count, colour=(0, 120, 255)):
    """Paint ``count`` orange 3x3 squares (they survive the opening as 5-pixel blobs)."""
    height, width = image.shape[:2]
    for x, y in zip(rng.integers(2, width - 2, count), rng.integers(2, height - 2, count)):
        image[y - 1:y + 2, x - 1:x + 2] = colour
    return image


def _messy_sequence(camera, seed=0):
    """Render frames with drops, doubles, a jump, gaps, specks and a ball leaving the image."""
    rng = np.random.default_rng(seed)
    renderer = BallRenderer(camera, noise_std=3.0, seed=seed)
    spiral, bounce = _flight('spiral'), _flight('bounce', fps=60.0)
    positions = []
    for index, point in enumerate(spiral):
        if index % 7 == 3:
            continue  # a dropped frame
        positions.append(point)
        if index % 11 == 5:
            positions.append(point)  # a doubled frame
        if index == 20:
            positions.extend([None, None])  # the ball hidden for two frames
    positions.extend(bounce[::2])  # a jump to another flight, bounces in it
    # The ball leaving the image to the right at the camera's depth of the last point.
    last = np.array(bounce[-1])
    positions.extend(last + (dx, 0.0, 0.0) for dx in np.linspace(0.2, 4.0, 12))
    images = []
    for index, position in enumerate(positions):
        image = renderer.render(position)
        if index % 3 == 0:
            image = _specks(image, rng, 12)
        images.append(image)
    return images


@pytest.mark.parametrize('encoding', ['bgr8', 'rgb8', 'bgra8', 'mono8'])
@pytest.mark.parametrize('choice', ['largest', 'nearest'])
def test_messy_sequences_are_bit_identical(encoding, choice):
    camera = _cameras()[0]
    images = _messy_sequence(camera)
    options = {'choice': choice, 'search_window_px': 48}
    if encoding == 'mono8':
        # Brightness: the ball's red channel is bright, the background's is not.
        images = [np.ascontiguousarray(image[:, :, 2]) for image in images]
        options['mono_threshold'] = 200
    elif encoding == 'rgb8':
        images = [cv2.cvtColor(image, cv2.COLOR_BGR2RGB) for image in images]
    elif encoding == 'bgra8':
        images = [cv2.cvtColor(image, cv2.COLOR_BGR2BGRA) for image in images]
    detector, pairs = _compare(images, encoding, **options)
    _assert_identical(pairs)
    found = sum(new is not None for _, new in pairs)
    assert detector.stats['tight_hits'] >= 0.6 * found
    assert detector.stats['tight_misses'] > 0 and detector.stats['no_ball'] > 0


def test_other_detector_settings_are_bit_identical():
    camera = _cameras()[1]
    images = _messy_sequence(camera, seed=1)
    for options in ({'open_kernel_px': 0, 'search_window_px': 90},
                    {'open_kernel_px': 5, 'min_area_px': 30.0}, {'search_window_px': 20}):
        detector, pairs = _compare(images, **{'search_window_px': 48, **options})
        _assert_identical(pairs)


def test_warm_up_keeps_the_motion_state():
    camera = _cameras()[0]
    renderer = BallRenderer(camera, noise_std=2.0, seed=4)
    images = [renderer.render(p) for p in _flight('spiral')[:20]]
    plain, warmed = BallDetector(), BallDetector()
    for previous, image in zip([images[0]] + images[:-1], images):
        warmed.warm_up(previous[::-1].copy())  # a different image: must change nothing
        assert warmed.detect(image) == plain.detect(image)
    assert warmed.stats == plain.stats and plain.stats['tight_hits'] > 10


def test_a_larger_orange_object_near_the_path_no_longer_captures_the_window():
    # The square window takes the largest blob in it, so an orange object larger than the
    # ball within 48 px of it wins and the track jumps to it; the tight window searches only
    # around the predicted position and stays on the ball.
    camera = _cameras()[0]
    renderer = BallRenderer(camera, noise_std=2.0, seed=5)
    points = _flight('spiral')[5:25]
    truth = camera.project(points)
    # Across the direction of motion, 30 px beside the ball: in the square, not in the tight
    # window; from the fourth frame on, when the track is set.
    direction = np.gradient(truth, axis=0)
    normal = np.column_stack((-direction[:, 1], direction[:, 0]))
    normal /= np.hypot(*normal.T)[:, None]
    images = []
    for index, (point, (u, v), (nu, nv)) in enumerate(zip(points, truth, normal)):
        image = renderer.render(point)
        if index >= 3:
            cv2.circle(image, (int(u + 30 * nu), int(v + 30 * nv)), 8, (0, 120, 255), -1)
        images.append(image)
    _, pairs = _compare(images, search_window_px=48)
    old = np.array([p[0] for p in pairs])
    new = np.array([p[1] for p in pairs])
    new_error = np.hypot(*(new - truth).T)
    old_error = np.hypot(*(old - truth).T)
    assert np.all(new_error < 0.5)
    assert np.median(old_error[3:]) > 20.0  # the square's search went to the disc
