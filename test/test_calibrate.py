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
Calibration: synthetic cameras, rendered chessboards and the real rig are recovered.

Tolerances come from the noise, not from the code's output: for point
correspondences the Cramer-Rao bound (CRB) of each parameter is computed
from the projection Jacobian at the true camera, ``cov = sigma^2 (J^T J)^-1``,
and a single fit must land within 4 CRB standard deviations (a maximum-
likelihood fit does: 40-seed runs measured RMS errors within 0.8-1.2 CRB).
"""

from dataclasses import replace
import math

import cv2
import numpy as np
from pseudo_stereo_ros.calibrate import (calibrate_extrinsics, calibrate_full,
                                         calibrate_intrinsics, CalibrationFitError)
from pseudo_stereo_ros.calibration import CalibrationError, load_calibration, save_calibration
from pseudo_stereo_ros.camera import Camera
from pseudo_stereo_ros.cli.main import main
from pseudo_stereo_ros.sim.scenarios import look_at_calibration
import pytest

NOISE_PX = 0.3
SIGMAS = 4.0
DIST = (-0.12, 0.03, 0.0008, -0.0005, 0.0)
LFG = 'lfg_table_tennis'
REAL_CAMERAS = ('22276213', '22276209', '22276216')


def _synthetic_calibration():
    return look_at_calibration('synthetic', (3.0, -2.0, 1.5), (0.5, 0.5, 0.5),
                               image_size=(640, 480), focal_px=500.0, dist_coeffs=DIST)


def _points_in_view(camera, count, seed, low=(-0.5, -0.5, 0.0), high=(1.5, 1.5, 1.2)):
    rng = np.random.default_rng(seed)
    points = []
    while len(points) < count:
        candidates = rng.uniform(low, high, (200, 3))
        points.extend(candidates[camera.in_image(camera.project(candidates))])
    return np.array(points[:count])


def _rotation_error_deg(r_a, r_b):
    return math.degrees(math.acos(np.clip((np.trace(r_a @ r_b.T) - 1.0) / 2.0, -1.0, 1.0)))


def _perturbed(calibration, p, terms):
    """Camera of parameter vector p = (fx, fy, cx, cy, distortion terms, dtheta (3), centre)."""
    used = {0: [], 2: [0, 1], 4: [0, 1, 2, 3], 5: [0, 1, 2, 3, 4]}[terms]
    dist = np.zeros(5)
    dist[used] = p[4:4 + len(used)]
    n = 4 + len(used)
    rotation = cv2.Rodrigues(p[n:n + 3])[0] @ calibration.rotation
    k = np.array(((p[0], 0.0, p[2]), (0.0, p[1], p[3]), (0.0, 0.0, 1.0)))
    return Camera(replace(calibration, camera_matrix=k, dist_coeffs=dist, rotation=rotation,
                          translation=-rotation @ p[n + 3:n + 6]))


def cramer_rao(calibration, world, sigma_px, terms, *, pose_only=False):
    """Return 1-sigma bounds: fx, fy, cx, cy [px], rotation angle [deg], centre [m]."""
    used = {0: [], 2: [0, 1], 4: [0, 1, 2, 3], 5: [0, 1, 2, 3, 4]}[terms]
    k = calibration.camera_matrix
    p0 = np.concatenate(((k[0, 0], k[1, 1], k[0, 2], k[1, 2]),
                         np.asarray(calibration.dist_coeffs)[used], np.zeros(3),
                         calibration.center))
    f0 = _perturbed(calibration, p0, terms).project(world).ravel()
    jacobian = np.zeros((len(f0), len(p0)))
    for i in range(len(p0)):
        step = 1e-6 * max(1.0, abs(p0[i]))
        p = p0.copy()
        p[i] += step
        jacobian[:, i] = (_perturbed(calibration, p, terms).project(world).ravel() - f0) / step
    n = 4 + len(used)
    if pose_only:
        jacobian = jacobian[:, n:]
        n = 0
    cov = sigma_px ** 2 * np.linalg.inv(jacobian.T @ jacobian)
    sd = np.sqrt(np.diag(cov))
    bounds = {'angle_deg': math.degrees(math.sqrt(np.trace(cov[n:n + 3, n:n + 3]))),
              'centre_m': math.sqrt(np.trace(cov[n + 3:n + 6, n + 3:n + 6]))}
    if not pose_only:
        bounds.update(fx=sd[0], fy=sd[1], cx=sd[2], cy=sd[3])
    return bounds


def _errors(fitted, truth):
    kf, kt = fitted.camera_matrix, truth.camera_matrix
    return {'fx': kf[0, 0] - kt[0, 0], 'fy': kf[1, 1] - kt[1, 1], 'cx': kf[0, 2] - kt[0, 2],
            'cy': kf[1, 2] - kt[1, 2],
            'angle_deg': _rotation_error_deg(fitted.rotation, truth.rotation),
            'centre_m': float(np.linalg.norm(fitted.center - truth.center))}


def _assert_within(errors, bounds, what):
    for key, bound in bounds.items():
        assert abs(errors[key]) <= SIGMAS * bound, (
            f'{what}: {key} error {errors[key]:.4g} > {SIGMAS} x CRB {bound:.4g}')


# -- full calibration ---------------------------------------------------------------------------


@pytest.mark.parametrize('count, seed', [(150, 1), (60, 2)])
def test_full_recovers_synthetic_camera_within_cramer_rao(count, seed):
    truth = _synthetic_calibration()
    camera = Camera(truth)
    world = _points_in_view(camera, count, seed)
    pixels = camera.project(world) + np.random.default_rng(seed + 100).normal(
        0.0, NOISE_PX, (count, 2))
    result = calibrate_full(world, pixels, (640, 480), camera_name='fit')
    assert result.dist_terms == 5
    bounds = cramer_rao(truth, world, NOISE_PX, result.dist_terms)
    _assert_within(_errors(result.calibration, truth), bounds, f'{count} points')
    # The residual of a good fit is the noise: RMS length sqrt(2) sigma, less the fitted dof.
    expected = NOISE_PX * math.sqrt(2.0 * (1.0 - 15.0 / (2 * count)))
    assert abs(result.rms_px - expected) < 0.15 * expected
    assert result.outliers.sum() <= 1


def test_full_flags_a_gross_outlier():
    truth = _synthetic_calibration()
    camera = Camera(truth)
    world = _points_in_view(camera, 80, 5)
    pixels = camera.project(world) + np.random.default_rng(6).normal(0.0, NOISE_PX, (80, 2))
    pixels[17] += (6.0, -5.0)
    result = calibrate_full(world, pixels, (640, 480))
    assert result.outliers[17]
    assert result.outliers.sum() <= 2


def test_full_without_distortion_from_few_points():
    truth = look_at_calibration('pinhole', (3.0, -2.0, 1.5), (0.5, 0.5, 0.5))
    camera = Camera(truth)
    world = _points_in_view(camera, 10, 7)
    pixels = camera.project(world) + np.random.default_rng(8).normal(0.0, NOISE_PX, (10, 2))
    result = calibrate_full(world, pixels, (640, 480))
    assert result.dist_terms == 0
    _assert_within(_errors(result.calibration, truth), cramer_rao(truth, world, NOISE_PX, 0),
                   '10 points')


# -- extrinsics ---------------------------------------------------------------------------------


@pytest.mark.parametrize('planar, count', [(True, 4), (True, 30), (False, 5), (False, 30)])
def test_extrinsics_recovers_pose_within_cramer_rao(planar, count):
    truth = _synthetic_calibration()
    camera = Camera(truth)
    high = (1.5, 1.5, 0.0) if planar else (1.5, 1.5, 1.2)
    world = _points_in_view(camera, count, 11, high=high)
    pixels = camera.project(world) + np.random.default_rng(12).normal(0.0, NOISE_PX,
                                                                      (count, 2))
    intrinsics = replace(truth, rotation=np.eye(3), translation=np.zeros(3))
    result = calibrate_extrinsics(intrinsics, world, pixels, camera_name='posed')
    assert result.calibration.camera_name == 'posed'
    np.testing.assert_array_equal(result.calibration.camera_matrix, truth.camera_matrix)
    bounds = cramer_rao(truth, world, NOISE_PX, 5, pose_only=True)
    _assert_within(_errors(result.calibration, truth), bounds, f'planar={planar} n={count}')


# -- chessboards --------------------------------------------------------------------------------

BOARD = (8, 6)
SQUARE_M = 0.03
PAD = 120


def _board_camera():
    calib = look_at_calibration('board_cam', (0, 0, 0), (1, 0, 0), image_size=(640, 480),
                                dist_coeffs=(-0.15, 0.05, 0.0005, -0.0003, 0.0))
    k = np.array(((520.0, 0.0, 325.0), (0.0, 518.0, 236.0), (0.0, 0.0, 1.0)))
    return replace(calib, camera_matrix=k, rotation=np.eye(3), translation=np.zeros(3))


def render_boards(calibration, count, seed, *, spread=1.0, tilt_deg=35.0):
    """
    Render anti-aliased chessboard images seen by a distorted camera.

    The board is drawn in the undistorted (ideal) image with a homography from a
    texture (INTER_AREA averages texels: anti-aliasing), then warped into raw pixels
    through the camera's own undistortion, blurred (optics) and given sensor noise.
    """
    camera = Camera(calibration)
    width, height = camera.image_size
    u, v = np.meshgrid(np.arange(width, dtype=float), np.arange(height, dtype=float))
    ideal = camera.ideal_pixels(np.column_stack((u.ravel(), v.ravel()))) + PAD
    map_x = ideal[:, 0].reshape(height, width).astype(np.float32)
    map_y = ideal[:, 1].reshape(height, width).astype(np.float32)
    cols, rows = BOARD
    texel = 24  # texels per square
    texture = np.full(((rows + 3) * texel, (cols + 3) * texel), 255, np.uint8)
    for j in range(rows + 1):
        for i in range(cols + 1):
            if (i + j) % 2 == 0:
                texture[(j + 1) * texel:(j + 2) * texel, (i + 1) * texel:(i + 2) * texel] = 0
    # Texel centre (x, y) -> board metres; the first inner corner is the board origin.
    scale = SQUARE_M / texel
    offset = (0.5 / texel - 2.0) * SQUARE_M
    to_board = np.array(((scale, 0.0, offset), (0.0, scale, offset), (0.0, 0.0, 1.0)))
    shift = np.array(((1.0, 0.0, PAD), (0.0, 1.0, PAD), (0.0, 0.0, 1.0)))
    centre = np.array((3.5 * SQUARE_M, 2.5 * SQUARE_M, 0.0))
    rng = np.random.default_rng(seed)
    images = []
    for _ in range(count):
        tilt = np.radians(rng.uniform(-tilt_deg, tilt_deg, 3)) * (1.0, 1.0, 0.3)
        rotation = cv2.Rodrigues(tilt)[0]
        distance = rng.uniform(0.4, 0.6)
        target = np.array((rng.uniform(-0.4, 0.4) * spread * distance,
                           rng.uniform(-0.3, 0.3) * spread * distance, distance))
        translation = target - rotation @ centre
        homography = shift @ camera.K @ np.column_stack(
            (rotation[:, 0], rotation[:, 1], translation)) @ to_board
        undistorted = cv2.warpPerspective(texture, homography,
                                          (width + 2 * PAD, height + 2 * PAD),
                                          flags=cv2.INTER_AREA, borderValue=140)
        raw = cv2.remap(undistorted, map_x, map_y, cv2.INTER_LINEAR, borderValue=140)
        raw = cv2.GaussianBlur(raw, (0, 0), 0.7)
        images.append(np.clip(raw + rng.normal(0.0, 2.0, raw.shape), 0, 255).astype(np.uint8))
    return images


@pytest.fixture(scope='module')
def board_images():
    return render_boards(_board_camera(), 12, 3)


def test_intrinsics_from_rendered_chessboards(board_images):
    truth = _board_camera()
    result = calibrate_intrinsics(board_images, board=BOARD, square_m=SQUARE_M,
                                  camera_name='cam')
    assert len(result.image_labels) == 12 and result.image_rms_px.shape == (12,)
    # Anti-aliased corners are located to ~0.05-0.1 px; OpenCV's 1-sigma from the residuals
    # and the board geometry must then be sub-pixel, and the truth within 4 of them.
    assert result.rms_px < 0.2
    assert np.all(result.intrinsics_std < 1.0)
    k, kt = result.calibration.camera_matrix, truth.camera_matrix
    errors = np.array((k[0, 0] - kt[0, 0], k[1, 1] - kt[1, 1], k[0, 2] - kt[0, 2],
                       k[1, 2] - kt[1, 2]))
    assert np.all(np.abs(errors) <= SIGMAS * result.intrinsics_std), (errors,
                                                                      result.intrinsics_std)
    # Distortion: the fitted lens maps the image like the true one, to a fraction of a pixel.
    grid = np.stack(np.meshgrid(np.linspace(40, 600, 15), np.linspace(40, 440, 11)),
                    -1).reshape(-1, 2)
    fitted = Camera(result.calibration).ideal_pixels(grid) - k[:2, 2]
    true = Camera(truth).ideal_pixels(grid) - kt[:2, 2]
    # Compare the undistortion in normalized units times a common focal length.
    difference = fitted / k[0, 0] * kt[0, 0] - true
    assert np.percentile(np.linalg.norm(difference, axis=1), 95) < 1.0


def test_intrinsics_from_16_bit_images_match_the_8_bit_ones(board_images):
    # A 16-bit camera's frames are stretched to 8 bits (min to max) before the corner search;
    # the rendered boards span 0-255, so the stretch gives the 8-bit frames back exactly.  Every
    # other one in Fortran order (a transposed buffer), which OpenCV's output must not inherit.
    eight = calibrate_intrinsics(board_images, board=BOARD, square_m=SQUARE_M)
    wide = [image.astype(np.uint16) * 250 + 300 for image in board_images]
    sixteen = calibrate_intrinsics([np.asfortranarray(image) if k % 2 else image
                                    for k, image in enumerate(wide)],
                                   board=BOARD, square_m=SQUARE_M)
    np.testing.assert_array_equal(sixteen.calibration.camera_matrix,
                                  eight.calibration.camera_matrix)


def test_intrinsics_refuses_too_few_boards(board_images):
    with pytest.raises(CalibrationFitError, match='too few boards: .* 4 of 4 images'):
        calibrate_intrinsics(board_images[:4], board=BOARD, square_m=SQUARE_M)
    with pytest.raises(CalibrationFitError, match=r'too few boards: .* 0 of 12 images'):
        calibrate_intrinsics(board_images, board=(7, 5), square_m=SQUARE_M)


def test_intrinsics_refuses_poor_coverage_and_parallel_boards():
    truth = _board_camera()
    with pytest.raises(CalibrationFitError, match='poor coverage'):
        calibrate_intrinsics(render_boards(truth, 6, 4, spread=0.0), board=BOARD,
                             square_m=SQUARE_M)
    with pytest.raises(CalibrationFitError, match='too little tilt variety'):
        calibrate_intrinsics(render_boards(truth, 8, 5, tilt_deg=1.0), board=BOARD,
                             square_m=SQUARE_M)


def test_intrinsics_bad_arguments(board_images):
    with pytest.raises(CalibrationFitError, match='cols != rows'):
        calibrate_intrinsics(board_images, board=(6, 6), square_m=SQUARE_M)
    with pytest.raises(CalibrationFitError, match='square size'):
        calibrate_intrinsics(board_images, board=BOARD, square_m=-1.0)
    with pytest.raises(CalibrationFitError, match='cannot read'):
        calibrate_intrinsics(['/nonexistent/board.png'], board=BOARD, square_m=SQUARE_M)


# -- degenerate input ---------------------------------------------------------------------------


@pytest.fixture
def correspondences():
    truth = _synthetic_calibration()
    camera = Camera(truth)
    world = _points_in_view(camera, 40, 21)
    return truth, world, camera.project(world)


def test_degenerate_full_input_is_refused(correspondences):
    truth, world, pixels = correspondences
    size = (640, 480)
    cases = [
        ((world[:5], pixels[:5], size), 'too few points: 5, need at least 6'),
        ((world, pixels[:-1], size), '40 world points but 39 pixels'),
        ((world * (1, 1, 0), pixels, size), 'coplanar'),
        ((np.outer(np.arange(40), (1.0, 0.5, 0.2)), pixels, size), 'collinear'),
        ((world, np.outer(np.arange(40), (5.0, 3.0)) + 10, size), 'pixels are collinear'),
        ((world * (1, -1, 1), pixels, size), 'mirrored|behind'),
        ((world, pixels, (320, 240)), 'contradicts the points: .* outside the image'),
        ((world, pixels, (1280, 960)), 'principal point .* far from the image centre'),
        ((world, np.where(np.arange(40)[:, None] == 3, np.nan, pixels), size), 'non-finite'),
        ((world, pixels, (0, 480)), 'image size must be positive'),
    ]
    for args, message in cases:
        with pytest.raises(CalibrationFitError, match=message):
            calibrate_full(*args)
    # The error class is the core's CalibrationError (the CLI reports it in one line).
    assert issubclass(CalibrationFitError, CalibrationError)


def test_degenerate_extrinsics_input_is_refused(correspondences):
    truth, world, pixels = correspondences
    intrinsics = replace(truth, rotation=np.eye(3), translation=np.zeros(3))
    with pytest.raises(CalibrationFitError, match='too few points: 3, need at least 4'):
        calibrate_extrinsics(intrinsics, world[:3], pixels[:3])
    with pytest.raises(CalibrationFitError, match='collinear'):
        calibrate_extrinsics(intrinsics, np.outer(np.arange(8), (1.0, 2.0, 0.5)), pixels[:8])
    with pytest.raises(CalibrationFitError, match='outside the image'):
        calibrate_extrinsics(intrinsics, world, pixels + (400, 0))
    # A point behind the camera projects to the same pixel as its mirror image in front.
    behind = world.copy()
    behind[7] = 2 * truth.center - world[7]
    with pytest.raises(CalibrationFitError, match='1 of 40 world points are behind'):
        calibrate_extrinsics(intrinsics, behind, pixels)
    # Mirrored world axes: no proper camera sees the points where they were seen.
    with pytest.raises(CalibrationFitError, match='no camera fits the points'):
        calibrate_extrinsics(intrinsics, world * (1, -1, 1), pixels)


def test_repeated_points_are_counted_once(correspondences):
    truth, world, pixels = correspondences
    intrinsics = replace(truth, rotation=np.eye(3), translation=np.zeros(3))
    # 3 distinct points repeated 3 times: 9 rows pass a row count, but the pose is ambiguous.
    triple_world, triple_pixels = np.repeat(world[:3], 3, axis=0), np.repeat(pixels[:3], 3, 0)
    lines = np.arange(2, 11)
    with pytest.raises(CalibrationFitError,
                       match=r'3 distinct of 9 \(lines 3, 4 repeat line 2; lines 6, 7 repeat '
                             r'line 5; lines 9, 10 repeat line 8\).*at least 4 distinct'):
        calibrate_extrinsics(intrinsics, triple_world, triple_pixels, lines=lines)
    with pytest.raises(CalibrationFitError, match='5 distinct of 10 .*at least 6 distinct'):
        calibrate_full(np.repeat(world[:5], 2, axis=0), np.repeat(pixels[:5], 2, axis=0),
                       (640, 480))
    # One repeated row among many still weighs that point twice: refused, naming the point.
    repeated = np.vstack((world, world[7:8])), np.vstack((pixels, pixels[7:8] + 0.2))
    with pytest.raises(CalibrationFitError, match=r'40 distinct of 41 \(point 40 repeats point 7'):
        calibrate_extrinsics(intrinsics, *repeated)
    with pytest.raises(CalibrationFitError, match='40 distinct of 41'):
        calibrate_full(*repeated, (640, 480))
    # Distinct world points but only 3 distinct pixels.
    with pytest.raises(CalibrationFitError, match='too few distinct pixels: 3 of 4'):
        calibrate_extrinsics(intrinsics, world[:4], pixels[[0, 1, 2, 2]])


def test_ambiguous_or_undetermined_pose_is_refused():
    truth = _synthetic_calibration()
    camera = Camera(truth)
    intrinsics = replace(truth, rotation=np.eye(3), translation=np.zeros(3))
    distance = np.linalg.norm(truth.center - (0.5, 0.5, 0.5))
    corners = np.array(((-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)), float)
    # A 20 cm square 4 m away spans ~25 px: the camera mirrored in its plane (the Necker flip)
    # sees the same image to within 0.3 px noise, so either pose is a guess.
    small = (0.5, 0.5, 0.5) + 0.1 * corners
    noisy = camera.project(small) + np.random.default_rng(41).normal(0.0, NOISE_PX, (4, 2))
    with pytest.raises(CalibrationFitError, match='ambiguous pose: two camera poses fit'):
        calibrate_extrinsics(intrinsics, small, noisy)
    # 4 points, one 2 cm off the line of the other three: the centre is not pinned down.
    near_line = np.array(((0, 0, 0.5), (0.6, 0.6, 0.5), (1.2, 1.2, 0.5), (0.6, 0.62, 0.5)))
    with pytest.raises(CalibrationFitError, match='ambiguous pose|do not fix the pose'):
        calibrate_extrinsics(intrinsics, near_line, camera.project(near_line))
    # The same square at 1 m size is fine and reports its uncertainty.
    large = (0.5, 0.5, 0.5) + 0.5 * corners
    result = calibrate_extrinsics(intrinsics, large, camera.project(large))
    assert np.linalg.norm(result.calibration.center - truth.center) < 1e-6 * distance
    assert any('per px of pixel noise' in note for note in result.notes)


# -- the real rig -------------------------------------------------------------------------------


def _triangulated(data_dir, session):
    path = data_dir / LFG / f'{session}_triangulated_xyz.csv'
    return np.loadtxt(path, delimiter=',', skiprows=1, usecols=(2, 3, 4))


@pytest.mark.parametrize('session', ['n1_n1', 'p2_p2'])
@pytest.mark.parametrize('camera_id', REAL_CAMERAS)
def test_full_recovers_the_real_rig(data_dir, session, camera_id):
    truth = load_calibration(data_dir / LFG / f'{camera_id}_calibration.yaml')
    camera = Camera(truth)
    points = _triangulated(data_dir, session)
    pixels = camera.project(points)
    inside = camera.in_image(pixels)
    world, pixels = points[inside], pixels[inside]
    noise = 0.5
    noisy = pixels + np.random.default_rng(int(camera_id) % 1000).normal(0.0, noise,
                                                                         pixels.shape)
    result = calibrate_full(world, noisy, camera.image_size, camera_name=camera_id)
    assert result.dist_terms == 5
    bounds = cramer_rao(truth, world, noise, 5)
    _assert_within(_errors(result.calibration, truth), bounds, f'{session} {camera_id}')
    assert result.rms_px < 1.1 * noise * math.sqrt(2)


def test_real_session_in_one_plane_is_refused(data_dir):
    # n3_p1_v14's flights lie within ~1 cm of one vertical plane: a full calibration from it
    # would have a focal-length CRB of 30-100 px, so it is refused rather than trusted.
    truth = Camera(load_calibration(data_dir / LFG / '22276213_calibration.yaml'))
    world = _triangulated(data_dir, 'n3_p1_v14')
    pixels = truth.project(world)
    inside = truth.in_image(pixels)
    with pytest.raises(CalibrationFitError, match='coplanar'):
        calibrate_full(world[inside], pixels[inside], truth.image_size)


# -- command line -------------------------------------------------------------------------------


def _write_csv(path, world, pixels):
    rows = ['x,y,z,u,v'] + [','.join(repr(float(x)) for x in (*w, *p))
                            for w, p in zip(world, pixels)]
    path.write_text('\n'.join(rows) + '\n')


def test_cli_full_and_extrinsics_write_loadable_files(tmp_path, capsys, correspondences):
    truth, world, pixels = correspondences
    noisy = pixels + np.random.default_rng(31).normal(0.0, NOISE_PX, pixels.shape)
    csv_path = tmp_path / 'corr.csv'
    _write_csv(csv_path, world, noisy)
    out = tmp_path / 'cam.yaml'
    assert main(['calibrate', 'full', '--points', str(csv_path), '--image-size', '640x480',
                 '--out', str(out), '--name', 'left']) == 0
    printed = capsys.readouterr().out
    assert 'RMS' in printed and 'residual_px' in printed
    assert len([line for line in printed.splitlines() if line[:4].strip().isdigit()]) == 40
    fitted = load_calibration(out)
    assert fitted.camera_name == 'left'
    assert (tmp_path / 'cam_residuals.png').stat().st_size > 10_000
    _assert_within(_errors(fitted, truth), cramer_rao(truth, world, NOISE_PX, 5), 'CLI full')

    plot = tmp_path / 'pose.png'
    posed = tmp_path / 'posed.yaml'
    assert main(['calibrate', 'extrinsics', '--intrinsics', str(out), '--points',
                 str(csv_path), '--out', str(posed), '--plot', str(plot)]) == 0
    assert load_calibration(posed).camera_name == 'left' and plot.exists()


def test_cli_intrinsics_from_image_files(tmp_path, capsys, board_images):
    images = tmp_path / 'boards'
    images.mkdir()
    for index, image in enumerate(board_images[:8]):
        cv2.imwrite(str(images / f'board_{index:02d}.png'), image)
    out = tmp_path / 'intrinsics.yaml'
    assert main(['calibrate', 'intrinsics', '--images', str(images), '--board', '8x6',
                 '--square', '0.03', '--out', str(out)]) == 0
    printed = capsys.readouterr().out
    assert 'board_07.png' in printed
    fitted = load_calibration(out)
    assert abs(fitted.camera_matrix[0, 0] - 520.0) < 2.0
    assert (tmp_path / 'intrinsics_residuals.png').exists()


@pytest.mark.parametrize('text, extra, message', [
    ('x,y,z,u\n1,2,3,4\n', [], 'corr.csv:1: missing column(s) v'),
    ('x,y,z,u,v\n1,2,3,4,5\n1,2,abc,4,5\n', [], 'corr.csv:3: column z: not a number'),
    ('x,y,z,u,v\n1,2,3,4,nan\n', [], 'corr.csv:2: column v: not finite'),
    ('x,y,z,u,v\n1,2,3,4,5\n', [], 'too few points: 1, need at least 6'),
    ('x,y,z,u,v\n' + '1,2,3,4,5\n' * 8, ['--image-size', '640by480'], "--image-size '640by480'"),
])
def test_cli_errors_exit_2_with_one_line(tmp_path, capsys, text, extra, message):
    csv_path = tmp_path / 'corr.csv'
    csv_path.write_text(text)
    out = tmp_path / 'cam.yaml'
    size = extra or ['--image-size', '640x480']
    status = main(['calibrate', 'full', '--points', str(csv_path), *size, '--out', str(out)])
    error = capsys.readouterr().err
    assert status == 2
    assert message in error and error.count('\n') == 1
    assert not out.exists()


def test_cli_extrinsics_refuses_repeated_rows(tmp_path, capsys, correspondences):
    truth, world, pixels = correspondences
    csv_path = tmp_path / 'dup.csv'
    _write_csv(csv_path, np.repeat(world[:3], 3, axis=0), np.repeat(pixels[:3], 3, axis=0))
    intrinsics = tmp_path / 'intrinsics.yaml'
    save_calibration(replace(truth, rotation=np.eye(3), translation=np.zeros(3)), intrinsics)
    out = tmp_path / 'posed.yaml'
    status = main(['calibrate', 'extrinsics', '--intrinsics', str(intrinsics), '--points',
                   str(csv_path), '--out', str(out)])
    error = capsys.readouterr().err
    assert status == 2 and error.count('\n') == 1
    assert '3 distinct of 9 (lines 3, 4 repeat line 2;' in error
    assert not out.exists()


def test_cli_missing_intrinsics_file_exits_2(tmp_path, capsys):
    csv_path = tmp_path / 'corr.csv'
    csv_path.write_text('x,y,z,u,v\n' + '1,2,3,4,5\n' * 8)
    status = main(['calibrate', 'extrinsics', '--intrinsics', str(tmp_path / 'none.yaml'),
                   '--points', str(csv_path), '--out', str(tmp_path / 'x.yaml')])
    error = capsys.readouterr().err
    assert status == 2 and 'none.yaml' in error and error.count('\n') == 1


# -- issue 12: `calibrate` reads CSV through the one reader `track` uses -------------------------


@pytest.mark.parametrize('mangle, message', [
    (lambda text: b'\n'.join(text.split(b'\n')[:2] + [b'1,2,3,4,\xe9'] + text.split(b'\n')[2:]),
     'corr.csv:3: not a UTF-8 CSV file (byte 0xe9'),  # before: UnicodeDecodeError traceback
    (lambda text: text + b'1,2,3,4,' + b'5' * 140_000 + b'\n',
     'corr.csv:42: malformed CSV: field larger than field limit'),  # before: _csv.Error
])
def test_cli_full_bad_bytes_are_one_line(tmp_path, capsys, correspondences, mangle, message):
    truth, world, pixels = correspondences
    csv_path = tmp_path / 'corr.csv'
    _write_csv(csv_path, world, pixels)
    csv_path.write_bytes(mangle(csv_path.read_bytes()))
    out = tmp_path / 'cam.yaml'
    status = main(['calibrate', 'full', '--points', str(csv_path), '--image-size', '640x480',
                   '--out', str(out)])
    error = capsys.readouterr().err
    assert status == 2 and error.count('\n') == 1, error
    assert message in error, error
    assert not out.exists()


def test_cli_full_reads_a_byte_order_mark_as_track_does(tmp_path, capsys, correspondences):
    # Before: "missing column(s) x" (the BOM stuck to the first column name).
    truth, world, pixels = correspondences
    plain, marked = tmp_path / 'plain.csv', tmp_path / 'marked.csv'
    _write_csv(plain, world, pixels)
    marked.write_bytes(b'\xef\xbb\xbf' + plain.read_bytes())
    for path in (plain, marked):
        assert main(['calibrate', 'full', '--points', str(path), '--image-size', '640x480',
                     '--out', str(tmp_path / f'{path.stem}.yaml'), '--name', 'cam']) == 0
    capsys.readouterr()
    assert (tmp_path / 'plain.yaml').read_text() == (tmp_path / 'marked.yaml').read_text()
