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
Two-view geometry: rays, epipolar lines, triangulation.

Vectorized functions take (N, k) arrays; the ``*_one`` functions do the same
for one point with plain floats, for the fuser's per-event path (numpy costs
microseconds per call on 3-vectors).  Tests hold the two versions equal.

Degenerate policy (see :mod:`pseudo_stereo_ros.camera`), never an exception:
rays that are parallel, or whose crossing point lies behind either ray's
origin (behind a camera: ray directions point out of the camera), have no
crossing point.  The vectorized functions return NaN rows for it, the
``*_one`` functions None (cheaper to test per event than NaN).
"""

from __future__ import annotations

import numpy as np

from .camera import Camera
from .records import Point3

__all__ = [
    'PARALLEL_EPS',
    'epipolar_distance',
    'epipolar_lines',
    'fundamental_matrix',
    'nearest_point_on_line',
    'nearest_point_on_line_one',
    'project_onto_lines',
    'relative_pose',
    'triangulate_pixels',
    'triangulate_rays',
    'triangulate_rays_one',
]

#: Rays whose unit directions have |sin(angle)|^2 below this count as parallel.
PARALLEL_EPS = 1e-12


def relative_pose(cam_a: Camera, cam_b: Camera) -> tuple[np.ndarray, np.ndarray]:
    """
    Return (R_ab, t_ab) with ``x_b = R_ab @ x_a + t_ab`` between the two camera frames.

    :param cam_a: the first camera
    :param cam_b: the second camera
    :return: rotation (3, 3) and translation (3,) [m]
    """
    r_ab = cam_b.R @ cam_a.R.T
    return r_ab, cam_b.t - r_ab @ cam_a.t


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array(((0.0, -v[2], v[1]), (v[2], 0.0, -v[0]), (-v[1], v[0], 0.0)))


def fundamental_matrix(cam_a: Camera, cam_b: Camera) -> np.ndarray:
    """
    Return F (3, 3) with ``p_b^T F p_a = 0`` for homogeneous *ideal* pixels.

    Distortion bends epipolar lines in raw pixels, so the line lives in camera
    b's undistorted (ideal) image; see :meth:`Camera.ideal_pixels`.
    """
    r_ab, t_ab = relative_pose(cam_a, cam_b)
    essential = _skew(t_ab) @ r_ab
    return np.linalg.inv(cam_b.K).T @ essential @ np.linalg.inv(cam_a.K)


def epipolar_lines(cam_a: Camera, ideal_a: np.ndarray, cam_b: Camera) -> np.ndarray:
    """
    Epipolar lines in camera b of ideal pixels of camera a.

    :param cam_a: the camera that saw the points
    :param ideal_a: (N, 2) ideal pixels in camera a
    :param cam_b: the other camera
    :return: (N, 3) lines (a, b, c), a*u + b*v + c = 0 with a^2 + b^2 = 1, in b's ideal pixels
    """
    ideal_a = np.asarray(ideal_a, dtype=float).reshape(-1, 2)
    homogeneous = np.hstack((ideal_a, np.ones((len(ideal_a), 1))))
    lines = homogeneous @ fundamental_matrix(cam_a, cam_b).T
    norm = np.hypot(lines[:, 0], lines[:, 1])
    with np.errstate(invalid='ignore', divide='ignore'):
        return lines / norm[:, None]


def project_onto_lines(points: np.ndarray, lines: np.ndarray) -> np.ndarray:
    """
    Return the nearest points (N, 2) on normalized 2D lines (N, 3) to points (N, 2).

    :param points: (N, 2) points
    :param lines: (N, 3) lines with a^2 + b^2 = 1
    :return: (N, 2) foot points
    """
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    lines = np.asarray(lines, dtype=float).reshape(-1, 3)
    distance = np.einsum('ij,ij->i', points, lines[:, :2]) + lines[:, 2]
    return points - distance[:, None] * lines[:, :2]


def epipolar_distance(cam_a: Camera, pixels_a: np.ndarray, cam_b: Camera,
                      pixels_b: np.ndarray) -> np.ndarray:
    """
    Symmetric epipolar distance of raw-pixel correspondences, in ideal pixels.

    :return: (N,) mean of the distance of b to a's line and of a to b's line [px]
    """
    ideal_a = cam_a.ideal_pixels(pixels_a)
    ideal_b = cam_b.ideal_pixels(pixels_b)
    lines_b = epipolar_lines(cam_a, ideal_a, cam_b)
    lines_a = epipolar_lines(cam_b, ideal_b, cam_a)
    d_b = np.abs(np.einsum('ij,ij->i', ideal_b, lines_b[:, :2]) + lines_b[:, 2])
    d_a = np.abs(np.einsum('ij,ij->i', ideal_a, lines_a[:, :2]) + lines_a[:, 2])
    return 0.5 * (d_a + d_b)


def triangulate_rays(origin_a: np.ndarray, directions_a: np.ndarray,
                     origin_b: np.ndarray, directions_b: np.ndarray) -> np.ndarray:
    """
    Crossing points of ray pairs: midpoints of their common perpendiculars.

    :param origin_a: (3,) or (N, 3) ray origins [m]
    :param directions_a: (N, 3) directions (any length)
    :param origin_b: (3,) or (N, 3) ray origins [m]
    :param directions_b: (N, 3) directions (any length)
    :return: (N, 3) points [m]; NaN rows for parallel rays or a crossing behind an origin
    """
    d1 = np.asarray(directions_a, dtype=float).reshape(-1, 3)
    d2 = np.asarray(directions_b, dtype=float).reshape(-1, 3)
    o1 = np.broadcast_to(np.asarray(origin_a, dtype=float), d1.shape)
    o2 = np.broadcast_to(np.asarray(origin_b, dtype=float), d2.shape)
    w = o1 - o2
    a = np.einsum('ij,ij->i', d1, d1)
    b = np.einsum('ij,ij->i', d1, d2)
    c = np.einsum('ij,ij->i', d2, d2)
    d = np.einsum('ij,ij->i', d1, w)
    e = np.einsum('ij,ij->i', d2, w)
    denominator = a * c - b * b
    parallel = ~(denominator > PARALLEL_EPS * a * c)
    with np.errstate(invalid='ignore', divide='ignore'):
        s = (b * e - c * d) / denominator
        t = (a * e - b * d) / denominator
        points = 0.5 * (o1 + s[:, None] * d1 + o2 + t[:, None] * d2)
    points[parallel | ~(s > 0) | ~(t > 0)] = np.nan
    return points


def triangulate_pixels(cam_a: Camera, pixels_a: np.ndarray, cam_b: Camera,
                       pixels_b: np.ndarray) -> np.ndarray:
    """Triangulate (N, 2) raw-pixel correspondences of two cameras to (N, 3) world points [m]."""
    origin_a, directions_a = cam_a.rays(pixels_a)
    origin_b, directions_b = cam_b.rays(pixels_b)
    return triangulate_rays(origin_a, directions_a, origin_b, directions_b)


def nearest_point_on_line(points: np.ndarray, origin: np.ndarray,
                          directions: np.ndarray) -> np.ndarray:
    """
    Nearest points on lines ``origin + k * direction`` (the paper's Eq. 5).

    :param points: (N, 3) points [m]
    :param origin: (3,) or (N, 3) line origins [m]
    :param directions: (N, 3) directions (any nonzero length)
    :return: (N, 3) foot points [m]
    """
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    directions = np.asarray(directions, dtype=float).reshape(-1, 3)
    origin = np.asarray(origin, dtype=float)
    k = (np.einsum('ij,ij->i', points - origin, directions)
         / np.einsum('ij,ij->i', directions, directions))
    return origin + k[:, None] * directions


def triangulate_rays_one(o1: Point3, d1: Point3, o2: Point3, d2: Point3) -> Point3 | None:
    """
    Return the crossing point of one pair of rays (scalar :func:`triangulate_rays`).

    :param o1: origin of the first ray (3 floats) [m]
    :param d1: its direction (3 floats)
    :param o2: origin of the second ray [m]
    :param d2: its direction
    :return: (x, y, z) [m], or None for parallel rays or a crossing behind an origin
    """
    w0, w1, w2 = o1[0] - o2[0], o1[1] - o2[1], o1[2] - o2[2]
    a = d1[0] * d1[0] + d1[1] * d1[1] + d1[2] * d1[2]
    b = d1[0] * d2[0] + d1[1] * d2[1] + d1[2] * d2[2]
    c = d2[0] * d2[0] + d2[1] * d2[1] + d2[2] * d2[2]
    d = d1[0] * w0 + d1[1] * w1 + d1[2] * w2
    e = d2[0] * w0 + d2[1] * w1 + d2[2] * w2
    denominator = a * c - b * b
    if not denominator > PARALLEL_EPS * a * c:
        return None
    s = (b * e - c * d) / denominator
    t = (a * e - b * d) / denominator
    if not (s > 0.0 and t > 0.0):
        return None
    return (0.5 * (o1[0] + s * d1[0] + o2[0] + t * d2[0]),
            0.5 * (o1[1] + s * d1[1] + o2[1] + t * d2[1]),
            0.5 * (o1[2] + s * d1[2] + o2[2] + t * d2[2]))


def nearest_point_on_line_one(point: Point3, origin: Point3, direction: Point3) -> Point3:
    """
    Return the nearest point on one line to a point (scalar :func:`nearest_point_on_line`).

    :param point: the point (3 floats) [m]
    :param origin: a point of the line [m]
    :param direction: the line's direction (nonzero)
    :return: (x, y, z) [m]
    """
    k = ((point[0] - origin[0]) * direction[0] + (point[1] - origin[1]) * direction[1]
         + (point[2] - origin[2]) * direction[2]) / (
        direction[0] * direction[0] + direction[1] * direction[1] + direction[2] * direction[2])
    return (origin[0] + k * direction[0], origin[1] + k * direction[1],
            origin[2] + k * direction[2])
