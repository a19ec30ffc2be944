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

"""Geometry: projection round trips, epipolar lines, triangulation, degenerate cases."""

import numpy as np
from pseudo_stereo_ros.camera import Camera
from pseudo_stereo_ros.geometry import (epipolar_distance, epipolar_lines,
                                        nearest_point_on_line, nearest_point_on_line_one,
                                        project_onto_lines, triangulate_pixels,
                                        triangulate_rays, triangulate_rays_one)
from pseudo_stereo_ros.sim.scenarios import look_at_calibration
import pytest

DISTORTIONS = {
    'none': ('plumb_bob', [0.0] * 5),
    'plumb_bob': ('plumb_bob', [-0.25, 0.08, 0.001, -0.0005, -0.01]),
    'rational_polynomial': ('rational_polynomial', [-0.2, 0.05, 0.001, 0.001, 0.0, 0.01,
                                                    0.0, 0.0]),
    'equidistant': ('equidistant', [0.05, -0.01, 0.002, 0.0]),
}


def rig(distortion='none'):
    model, coefficients = DISTORTIONS[distortion]
    return (Camera(look_at_calibration('a', (0.0, -2.0, 3.0), (1.5, 1.0, 1.0),
                                       distortion_model=model, dist_coeffs=coefficients)),
            Camera(look_at_calibration('b', (3.0, -2.0, 3.0), (1.5, 1.0, 1.0),
                                       distortion_model=model, dist_coeffs=coefficients)))


def volume_points(count=200, seed=1):
    rng = np.random.default_rng(seed)
    return rng.uniform((0.5, 0.3, 0.3), (2.5, 1.7, 1.7), (count, 3))


@pytest.mark.parametrize('distortion', sorted(DISTORTIONS))
def test_project_then_rays_pass_through_the_points(distortion):
    camera, _ = rig(distortion)
    points = volume_points()
    pixels = camera.project(points)
    assert np.all(np.isfinite(pixels))
    origin, directions = camera.rays(pixels)
    # The distance of each point from its own viewing ray is round-off only (< 1 um).
    foot = nearest_point_on_line(points, origin, directions)
    assert np.max(np.linalg.norm(foot - points, axis=1)) < 1e-6


@pytest.mark.parametrize('distortion', sorted(DISTORTIONS))
def test_triangulation_round_trip(distortion):
    camera_a, camera_b = rig(distortion)
    points = volume_points()
    estimated = triangulate_pixels(camera_a, camera_a.project(points), camera_b,
                                   camera_b.project(points))
    np.testing.assert_allclose(estimated, points, atol=1e-6)


def test_empty_input_gives_empty_output():
    camera, _ = rig('plumb_bob')
    assert camera.project(np.empty((0, 3))).shape == (0, 2)
    assert camera.normalize(np.empty((0, 2))).shape == (0, 2)


@pytest.mark.parametrize('distortion', sorted(DISTORTIONS))
def test_normalize_one_is_opencvs_undistortion_bit_for_bit(distortion):
    # Without distortion normalize_one takes a closed form instead of OpenCV's call: the
    # same floats, for pixels inside and outside the image; distorted lenses use OpenCV.
    camera, _ = rig(distortion)
    pixels = np.random.default_rng(5).uniform(-300.0, 2500.0, (500, 2))
    expected = camera.normalize(pixels)
    found = np.array([camera.normalize_one(u, v) for u, v in pixels.tolist()])
    assert (camera._pinhole is not None) == (distortion == 'none')
    np.testing.assert_array_equal(found, expected)
    if distortion == 'none':  # the closed form really is (u - cx) / fx, not a copy of OpenCV
        np.testing.assert_allclose(found, (pixels - camera.K[:2, 2]) / np.diag(camera.K)[:2],
                                   rtol=1e-15, atol=1e-15)


def test_ideal_pixels_round_trip_through_normalized():
    camera, _ = rig('plumb_bob')
    pixels = camera.project(volume_points())
    ideal = camera.ideal_pixels(pixels)
    np.testing.assert_allclose(camera.normalized_to_ideal(camera.ideal_to_normalized(ideal)),
                               ideal, atol=1e-9)


def test_epipolar_line_holds_the_true_correspondence():
    camera_a, camera_b = rig('plumb_bob')
    points = volume_points()
    pixels_a, pixels_b = camera_a.project(points), camera_b.project(points)
    assert np.max(epipolar_distance(camera_a, pixels_a, camera_b, pixels_b)) < 1e-6
    # Moving a point along the line keeps it on the line; off the line is measured in px.
    lines = epipolar_lines(camera_a, camera_a.ideal_pixels(pixels_a), camera_b)
    ideal_b = camera_b.ideal_pixels(pixels_b)
    shifted = ideal_b + 3.0 * lines[:, :2]  # 3 px along the line normal
    np.testing.assert_allclose(project_onto_lines(shifted, lines), ideal_b, atol=1e-9)


def test_scalar_and_vectorized_versions_agree():
    rng = np.random.default_rng(3)
    o1, o2 = rng.normal(size=3), rng.normal(size=3)
    d1, d2 = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    vectorized = triangulate_rays(o1, d1, o2, d2)
    crossing = np.isfinite(vectorized[:, 0])
    assert 5 < crossing.sum() < 45  # random rays cross in front of both origins, or not
    for k in range(50):
        scalar = triangulate_rays_one(tuple(o1), tuple(d1[k]), tuple(o2), tuple(d2[k]))
        if crossing[k]:
            np.testing.assert_allclose(scalar, vectorized[k], rtol=1e-9, atol=1e-12)
        else:
            assert scalar is None
    points = rng.normal(size=(50, 3))
    feet = nearest_point_on_line(points, o1, d1)
    for k in range(50):
        np.testing.assert_allclose(nearest_point_on_line_one(tuple(points[k]), tuple(o1),
                                                             tuple(d1[k])), feet[k], atol=1e-12)


def test_skew_rays_meet_at_the_midpoint_of_the_common_perpendicular():
    # x axis and a line parallel to y at z = 2: common perpendicular from (1,0,0) to (1,0,2).
    point = triangulate_rays((0, 0, 0), [(1, 0, 0)], (1, -5, 2), [(0, 1, 0)])
    np.testing.assert_allclose(point[0], (1, 0, 1))


def test_degenerate_policy_is_nan():
    # Parallel rays have no crossing point.
    assert np.all(np.isnan(triangulate_rays((0, 0, 0), [(1, 0, 0)], (0, 1, 0), [(2, 0, 0)])))
    assert triangulate_rays_one((0, 0, 0), (1, 0, 0), (0, 1, 0), (2, 0, 0)) is None
    # Rays that cross behind an origin: the crossing (-1, 0, 0) is behind the first ray.
    assert np.all(np.isnan(triangulate_rays((0, 0, 0), [(1, 0, 0)], (0, 1, 0), [(-1, -1, 0)])))
    assert triangulate_rays_one((0, 0, 0), (1, 0, 0), (0, 1, 0), (-1, -1, 0)) is None
    assert triangulate_rays_one((0, 0, 0), (-1, 0, 0), (0, 1, 0), (-1, -1, 0)) is not None
    # A point behind the camera does not project.
    camera, _ = rig()
    behind = 2 * camera.center - np.array((1.5, 1.0, 1.0))
    assert np.all(np.isnan(camera.project(behind)))
