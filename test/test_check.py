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

"""``check``: epipolar consistency of a camera pair on unsynchronized observations."""

from dataclasses import replace
import math

import cv2
import numpy as np
from pseudo_stereo_ros.calibrate import epipolar_check
from pseudo_stereo_ros.calibration import save_calibration
from pseudo_stereo_ros.camera import Camera
from pseudo_stereo_ros.cli.main import main
from pseudo_stereo_ros.formats.csv_io import write_observations
from pseudo_stereo_ros.geometry import epipolar_lines
from pseudo_stereo_ros.sim.scenarios import (default_rig, make_scenario, observe, shutter_stamps,
                                             truth_at)
import pytest

ANGLE_DEG = 0.5
NOISE_PX = 0.2


def _tracks(observations, name):
    mine = [o for o in observations if o.camera == name]
    return (np.array([o.stamp_ns for o in mine], dtype=np.int64),
            np.array([(o.u, o.v) for o in mine]))


@pytest.fixture(scope='module')
def unsynchronized():
    cam_a, cam_b = default_rig()
    scenario = make_scenario('bounce')
    # 60 fps cameras 7.3 ms apart: camera b never shoots when camera a does.
    stamps = [shutter_stamps(60.0, scenario.duration_s),
              shutter_stamps(60.0, scenario.duration_s, phase_s=0.0073)]
    observations = observe(scenario, (cam_a, cam_b), stamps, noise_px=NOISE_PX, seed=4)
    return cam_a, cam_b, scenario, observations


def _rotated(camera, angle_deg):
    """Camera turned about its own x axis (pitch): its image moves by f * angle vertically."""
    turn = cv2.Rodrigues(np.array((math.radians(angle_deg), 0.0, 0.0)))[0]
    calib = camera.calibration
    return Camera(replace(calib, rotation=turn @ calib.rotation,
                          translation=turn @ calib.translation))


def test_correct_calibration_is_at_noise_level(unsynchronized):
    cam_a, cam_b, _, observations = unsynchronized
    result = epipolar_check(cam_a, *_tracks(observations, cam_a.name), cam_b,
                            *_tracks(observations, cam_b.name), max_gap_ns=100_000_000)
    assert result.count > 80
    # Noise sigma per axis in each image; the symmetric distance averages two line distances,
    # each |N(0, sigma * sqrt(2))|-like, so its median is below sigma * 1.5; the bounce's
    # curvature over a 16.7 ms interpolation adds at most g dt^2 / 8 = 0.3 mm (0.1 px).
    assert np.median(result.distances_px) < 0.5
    assert np.median(result.distances_px) < 1.5 * NOISE_PX + 0.1


def test_rotated_camera_gives_f_times_angle(unsynchronized):
    cam_a, cam_b, scenario, observations = unsynchronized
    wrong_b = _rotated(cam_b, ANGLE_DEG)
    result = epipolar_check(cam_a, *_tracks(observations, cam_a.name), wrong_b,
                            *_tracks(observations, cam_b.name), max_gap_ns=100_000_000)
    # Expected: camera b's image shifts by f * angle vertically; the epipolar distance is the
    # part across the epipolar line, |normal_v| of the line through the true point in b.
    shift = cam_b.K[1, 1] * math.radians(ANGLE_DEG)
    truth = truth_at(scenario, result.stamps_ns)
    lines = epipolar_lines(cam_a, cam_a.ideal_pixels(cam_a.project(truth)), cam_b)
    expected = np.median(shift * np.abs(lines[:, 1]))
    assert shift > 4.0  # 500 px * 8.7 mrad = 4.4 px
    measured = np.median(result.distances_px)
    assert 0.7 * expected < measured < 1.3 * expected, (measured, expected)
    assert measured > 5 * np.median(epipolar_check(
        cam_a, *_tracks(observations, cam_a.name), cam_b, *_tracks(observations, cam_b.name),
        max_gap_ns=100_000_000).distances_px)


def test_gaps_longer_than_max_gap_are_not_interpolated(unsynchronized):
    cam_a, cam_b, _, observations = unsynchronized
    stamps_b, pixels_b = _tracks(observations, cam_b.name)
    keep = np.ones(len(stamps_b), bool)
    keep[20:30] = False  # a 183 ms hole in camera b
    full = epipolar_check(cam_a, *_tracks(observations, cam_a.name), cam_b, stamps_b, pixels_b,
                          max_gap_ns=100_000_000)
    holed = epipolar_check(cam_a, *_tracks(observations, cam_a.name), cam_b, stamps_b[keep],
                           pixels_b[keep], max_gap_ns=100_000_000)
    assert full.count - holed.count == 11
    assert holed.skipped - full.skipped == 11


def _write_rig(tmp_path, cam_a, cam_b):
    paths = []
    for camera in (cam_a, cam_b):
        path = tmp_path / f'{camera.name}.yaml'
        save_calibration(camera.calibration, path)
        paths.append(path)
    return paths


def test_cli_verdicts(tmp_path, capsys, unsynchronized):
    cam_a, cam_b, _, observations = unsynchronized
    path_a, path_b = _write_rig(tmp_path, cam_a, cam_b)
    obs = tmp_path / 'obs.csv'
    write_observations(obs, observations)
    assert main(['check', '--camera', f'camera1={path_a}', '--camera', f'camera2={path_b}',
                 '--input', str(obs)]) == 0
    printed = capsys.readouterr().out
    assert 'verdict: OK' in printed and 'median' in printed and 'p90' in printed
    wrong = tmp_path / 'wrong.yaml'
    save_calibration(_rotated(cam_b, ANGLE_DEG).calibration, wrong)
    assert main(['check', '--camera', f'camera1={path_a}', '--camera', f'camera2={wrong}',
                 '--input', str(obs)]) == 0
    assert 'verdict: BAD' in capsys.readouterr().out


@pytest.mark.parametrize('cameras, text, message', [
    (1, None, 'need at least 2 cameras'),
    (2, 'stamp_ns,camera,u,v\n1.5e18,camera1,1,2\n', 'obs.csv:2: column stamp_ns: not an '
                                                     'integer'),
    (2, 'stamp_ns,camera,u,v\n1,camera1,1,2\n', "no observations of camera 'camera2'"),
    (2, 'stamp_ns,camera,u,v\n1,camera1,1,2\n900000000,camera2,1,2\n1000000000,camera2,1,2\n',
     'nothing to compare'),
])
def test_cli_errors_exit_2_with_one_line(tmp_path, capsys, unsynchronized, cameras, text,
                                         message):
    cam_a, cam_b, _, observations = unsynchronized
    path_a, path_b = _write_rig(tmp_path, cam_a, cam_b)
    obs = tmp_path / 'obs.csv'
    if text is None:
        write_observations(obs, observations)
    else:
        obs.write_text(text)
    args = ['check', '--camera', f'camera1={path_a}']
    if cameras == 2:
        args += ['--camera', f'camera2={path_b}']
    status = main(args + ['--input', str(obs)])
    error = capsys.readouterr().err
    assert status == 2
    assert message in error and error.count('\n') == 1


@pytest.mark.parametrize('session', ['n3_p1_v14'])
def test_real_rig_epipolar_distance(tmp_path, capsys, data_dir, session):
    bagio = pytest.importorskip('pseudo_stereo_ros.formats.bagio')
    folder = data_dir / 'lfg_table_tennis'
    obs = tmp_path / 'obs.csv'
    write_observations(obs, bagio.read_observations(folder / session))
    files = {'camera_1': '22276213', 'camera_2': '22276209', 'camera_3': '22276216'}
    medians = {}
    for a, b in (('camera_1', 'camera_3'), ('camera_2', 'camera_3'), ('camera_1', 'camera_2')):
        assert main(['check', '--camera', f'{a}={folder / (files[a] + "_calibration.yaml")}',
                     '--camera', f'{b}={folder / (files[b] + "_calibration.yaml")}',
                     '--input', str(obs), '--max-gap-s', '0.02']) == 0
        line = [x for x in capsys.readouterr().out.splitlines() if 'median' in x][0]
        medians[a, b] = float(line.split('median ')[1].split(' px')[0])
    # The data's README puts the rig's noise floor (interpolated cameras, held-out camera 3)
    # at 1.1-1.7 px: the pairs with camera 3 are consistent at that level.
    assert medians['camera_1', 'camera_3'] < 2.0
    assert medians['camera_2', 'camera_3'] < 2.0
    # Measured, not a bound: camera_1/camera_2 disagree by ~8 px in all three sessions
    # (reported to the lead); the check must at least see a finite distance.
    assert math.isfinite(medians['camera_1', 'camera_2'])
