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

"""Tests of the ROS-free detector and renderer on rendered, anti-aliased frames."""

import subprocess
import sys

import cv2
from hypothesis import given, strategies as st
import numpy as np
from pseudo_stereo_ros.camera import Camera
from pseudo_stereo_ros.detection import (_median_of_integers, BallDetector, ENCODING_CHANNELS,
                                         EncodingError, image_array)
from pseudo_stereo_ros.sim.rendering import BallRenderer
from pseudo_stereo_ros.sim.scenarios import default_rig, look_at_calibration
import pytest


def _camera(distorted: bool = False) -> Camera:
    coeffs = [-0.25, 0.08, 0.001, -0.001, 0.0] if distorted else None
    return Camera(look_at_calibration('cam', (0.0, -3.0, 1.5), (0.0, 0.0, 1.0),
                                      dist_coeffs=coeffs))


def _convert(image_bgr: np.ndarray, encoding: str) -> np.ndarray:
    conversions = {'bgr8': None, 'rgb8': cv2.COLOR_BGR2RGB, 'bgra8': cv2.COLOR_BGR2BGRA,
                   'rgba8': cv2.COLOR_BGR2RGBA}
    code = conversions[encoding]
    return image_bgr if code is None else cv2.cvtColor(image_bgr, code)


# Ball centres spread over the image, at sub-pixel offsets.
POSITIONS = [(0.0, 0.0, 1.0), (0.61, 0.3, 1.37), (-0.9, -0.4, 0.52), (0.333, 0.9, 1.81)]


@pytest.mark.parametrize('distorted', [False, True])
@pytest.mark.parametrize('radius_m', [0.02, 0.05])
@pytest.mark.parametrize('position', POSITIONS)
def test_centroid_is_subpixel_accurate(distorted, radius_m, position):
    camera = _camera(distorted)
    renderer = BallRenderer(camera, radius_m=radius_m, supersample=8, seed=3)
    detector = BallDetector(search_window_px=0)
    found = detector.detect(renderer.render(position), 'bgr8')
    truth = camera.project(np.array(position))[0]
    assert found is not None
    # Whole-pixel blob centroids err up to ~0.3 px; the soft-weighted one must stay well under.
    assert np.hypot(*(np.array(found) - truth)) < 0.1


def test_noise_keeps_centroid_within_a_fraction_of_a_pixel():
    camera = _camera()
    renderer = BallRenderer(camera, radius_m=0.03, noise_std=3.0, seed=4)
    detector = BallDetector(search_window_px=0)
    errors = []
    for position in POSITIONS:
        found = detector.detect(renderer.render(position), 'bgr8')
        errors.append(np.hypot(*(np.array(found) - camera.project(np.array(position))[0])))
    assert max(errors) < 0.25


@pytest.mark.parametrize('encoding', ['rgb8', 'bgr8', 'rgba8', 'bgra8'])
def test_every_colour_encoding_gives_the_same_centroid(encoding):
    camera = _camera()
    image = BallRenderer(camera, radius_m=0.03, seed=5).render(POSITIONS[1])
    reference = BallDetector(search_window_px=0).detect(image, 'bgr8')
    found = BallDetector(search_window_px=0).detect(_convert(image, encoding), encoding)
    np.testing.assert_allclose(found, reference, atol=1e-9)
    # The search window hands the converter a strided view of the frame (4 channels: alpha
    # included): the same centroid again.
    windowed = BallDetector(search_window_px=30)
    windowed.last = tuple(np.add(reference, (3.0, -2.0)))
    np.testing.assert_allclose(windowed.detect(_convert(image, encoding), encoding), reference,
                               atol=1e-9)
    assert windowed.stats['window_hits'] == 1


@pytest.mark.parametrize('encoding', sorted(ENCODING_CHANNELS))
@pytest.mark.parametrize('height, width', [(0, 0), (0, 640), (480, 0)])
def test_empty_image_is_refused_as_a_bad_image(encoding, height, width):
    # OpenCV asserts (cv2.error) on empty images: they must be refused before, as bad input.
    step = width * ENCODING_CHANNELS[encoding]
    with pytest.raises(EncodingError, match='empty image'):
        image_array(b'', height, width, step, encoding)
    channels = ENCODING_CHANNELS[encoding]
    shape = (height, width) if channels == 1 else (height, width, channels)
    with pytest.raises(ValueError, match='empty image'):
        BallDetector().detect(np.zeros(shape, np.uint8), encoding)


def test_mono8_brightness_threshold():
    camera = _camera()
    renderer = BallRenderer(camera, radius_m=0.04, ball_rgb=(255, 255, 255), texture=False,
                            supersample=8)
    gray = cv2.cvtColor(renderer.render(POSITIONS[1]), cv2.COLOR_BGR2GRAY)
    found = BallDetector(mono_threshold=200, search_window_px=0).detect(gray, 'mono8')
    truth = camera.project(np.array(POSITIONS[1]))[0]
    assert np.hypot(*(np.array(found) - truth)) < 0.1
    # A colour image handed over as mono8 does not fit.
    with pytest.raises(ValueError, match='does not fit'):
        BallDetector().detect(renderer.render(POSITIONS[1]), 'mono8')
    with pytest.raises(ValueError, match='unsupported encoding'):
        BallDetector().detect(gray, '16UC1')


def test_no_ball_gives_none_and_is_counted():
    renderer = BallRenderer(_camera(), seed=6)
    detector = BallDetector()
    assert detector.detect(renderer.render(None), 'bgr8') is None
    assert detector.detect(renderer.render((0.0, 5.0, -9.0)), 'bgr8') is None  # behind
    assert detector.stats['no_ball'] == 2


def _two_balls(camera, first, second):
    big = BallRenderer(camera, radius_m=0.06, seed=7)
    small = BallRenderer(camera, radius_m=0.03, seed=7)
    image = big.render(first)
    x0, y0, patch = small.coverage(second)
    h, w = patch.shape
    region = image[y0:y0 + h, x0:x0 + w].astype(np.float32)
    image[y0:y0 + h, x0:x0 + w] = np.round(
        region * (1 - patch[:, :, None]) + small.ball_bgr * patch[:, :, None]).astype(np.uint8)
    return image


def test_blob_choice_largest_or_nearest():
    camera = _camera()
    big, small = (0.5, 0.0, 1.0), (-0.5, 0.0, 1.0)
    image = _two_balls(camera, big, small)
    big_px, small_px = camera.project(np.array([big, small]))
    largest = BallDetector(choice='largest', search_window_px=0).detect(image, 'bgr8')
    assert np.hypot(*(np.array(largest) - big_px)) < 0.2
    nearest = BallDetector(choice='nearest', search_window_px=0)
    nearest.last = tuple(small_px + 5.0)
    assert np.hypot(*(np.array(nearest.detect(image, 'bgr8')) - small_px)) < 0.2


def test_area_limits_reject_blobs():
    camera = _camera()
    image = BallRenderer(camera, radius_m=0.05, seed=8).render(POSITIONS[0])
    assert BallDetector(max_area_px=20.0).detect(image, 'bgr8') is None
    assert BallDetector(min_area_px=5000.0, max_area_px=9000.0).detect(image, 'bgr8') is None


def test_search_window_matches_full_frame_and_falls_back():
    camera = _camera()
    renderer = BallRenderer(camera, radius_m=0.03, noise_std=2.0, seed=9)
    windowed = BallDetector(search_window_px=40)
    full = BallDetector(search_window_px=0)
    # A smooth path, then a jump far outside the window.
    path = [(x, 0.0, 1.0) for x in np.linspace(-0.5, 0.5, 6)] + [(-0.9, 0.5, 0.4)]
    for position in path:
        image = renderer.render(position)
        np.testing.assert_allclose(windowed.detect(image, 'bgr8'), full.detect(image, 'bgr8'),
                                   atol=1e-9)
    assert windowed.stats['window_hits'] == 5
    assert windowed.stats['window_misses'] == 1  # the jump: found again in the full frame
    assert windowed.stats['detections'] == len(path)


@given(st.lists(st.integers(0, 255), min_size=1, max_size=80))
def test_ring_median_is_numpys_median_exactly(values):
    # The background level of the centroid: exactly np.median, so detections do not change.
    signal = np.array(values, dtype=np.float32)
    assert _median_of_integers(signal) == float(np.median(signal))


def test_warm_up_changes_neither_state_nor_results():
    camera = _camera()
    renderer = BallRenderer(camera, radius_m=0.03, noise_std=2.0, seed=5)
    images = [renderer.render((x, 0.1, 1.0)) for x in np.linspace(-0.4, 0.4, 8)]
    plain, warmed = BallDetector(search_window_px=40), BallDetector(search_window_px=40)
    assert not warmed.warm_up(images[0])  # no last position: no full-frame search
    previous = None
    for image in images:
        if previous is not None:
            last, stats = warmed.last, dict(warmed.stats)
            assert warmed.warm_up(previous)
            assert warmed.last == last and dict(warmed.stats) == stats
        assert warmed.detect(image) == plain.detect(image)
        previous = image
    assert warmed.stats == plain.stats
    assert not BallDetector(search_window_px=0).warm_up(images[0])


def test_invalid_parameters_are_named():
    with pytest.raises(ValueError, match='hsv_lower'):
        BallDetector(hsv_lower=(5, 120))
    with pytest.raises(ValueError, match='min_area_px'):
        BallDetector(min_area_px=10.0, max_area_px=5.0)
    with pytest.raises(ValueError, match='choice'):
        BallDetector(choice='brightest')


def test_hue_range_wrapping_around_red():
    camera = _camera()
    image = BallRenderer(camera, radius_m=0.04, ball_rgb=(230, 0, 30), seed=10,
                         supersample=8).render(POSITIONS[1])
    found = BallDetector(hsv_lower=(170, 120, 100), hsv_upper=(10, 255, 255),
                         search_window_px=0).detect(image, 'bgr8')
    truth = camera.project(np.array(POSITIONS[1]))[0]
    assert np.hypot(*(np.array(found) - truth)) < 0.1


def test_renderer_is_seeded_and_follows_the_rig():
    camera = default_rig()[0]
    first = BallRenderer(camera, noise_std=2.0, seed=11).render((1.0, 1.0, 1.0))
    again = BallRenderer(camera, noise_std=2.0, seed=11).render((1.0, 1.0, 1.0))
    other = BallRenderer(camera, noise_std=2.0, seed=12).render((1.0, 1.0, 1.0))
    assert first.shape == (480, 640, 3) and first.dtype == np.uint8
    np.testing.assert_array_equal(first, again)
    assert np.any(first != other)


def test_core_modules_import_without_ros():
    code = ('import sys; import pseudo_stereo_ros.detection, pseudo_stereo_ros.sim.rendering, '
            'pseudo_stereo_ros.reorder; '
            "bad = [m for m in sys.modules if m.startswith(('rclpy', 'sensor_msgs', "
            "'geometry_msgs'))]; print(bad); sys.exit(1 if bad else 0)")
    result = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True)
    assert result.returncode == 0, result.stdout + result.stderr
