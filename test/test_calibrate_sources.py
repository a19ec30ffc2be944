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
Calibration inputs from the ecosystem: camera_info YAML files and chessboard videos.

``OST_YAML`` is written exactly as ROS ``camera_calibration`` writes ``ost.yaml``
(flow sequences over several lines, numbers like ``0.`` and ``512.33471``, no
extrinsics, with rectification and projection matrices).
"""

from dataclasses import replace

import cv2
import numpy as np
from pseudo_stereo_ros.calibrate import video_boards
from pseudo_stereo_ros.calibration import (CalibrationError, load_calibration, load_camera_info,
                                           save_calibration)
from pseudo_stereo_ros.camera import Camera
from pseudo_stereo_ros.cli.main import main
from pseudo_stereo_ros.errors import CalibrationFitError
from pseudo_stereo_ros.sim.scenarios import look_at_calibration
import pytest
from test_calibrate import (_assert_within, _board_camera, _errors, _points_in_view, BOARD,
                            cramer_rao, render_boards)

OST_YAML = """image_width: 640
image_height: 480
camera_name: narrow_stereo
camera_matrix:
  rows: 3
  cols: 3
  data: [512.33471,   0.     , 318.91023,
           0.     , 511.87216, 241.2247 ,
           0.     ,   0.     ,   1.     ]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [-0.031524, 0.052184, 0.000834, -0.000201, 0.000000]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1., 0., 0.,
         0., 1., 0.,
         0., 0., 1.]
projection_matrix:
  rows: 3
  cols: 4
  data: [507.82507,   0.     , 318.73917,   0.     ,
           0.     , 509.18747, 241.50162,   0.     ,
           0.     ,   0.     ,   1.     ,   0.     ]
"""
NOISE_PX = 0.3


def test_camera_info_yaml_gives_intrinsics_and_an_identity_pose(tmp_path):
    path = tmp_path / 'ost.yaml'
    path.write_text(OST_YAML)
    calibration = load_camera_info(path)
    assert calibration.camera_name == 'narrow_stereo'
    assert (calibration.image_width, calibration.image_height) == (640, 480)
    np.testing.assert_array_equal(calibration.camera_matrix,
                                  [[512.33471, 0, 318.91023], [0, 511.87216, 241.2247],
                                   [0, 0, 1]])
    np.testing.assert_array_equal(calibration.dist_coeffs,
                                  [-0.031524, 0.052184, 0.000834, -0.000201, 0.0])
    np.testing.assert_array_equal(calibration.rotation, np.eye(3))
    np.testing.assert_array_equal(calibration.translation, np.zeros(3))
    # The rig loader stays strict: a camera in a rig needs its pose.
    with pytest.raises(CalibrationError, match="key 'rotation_matrix': missing"):
        load_calibration(path)


def test_camera_info_loader_keeps_a_pose_and_refuses_half_of_one(tmp_path):
    posed = tmp_path / 'posed.yaml'
    truth = look_at_calibration('cam', (3.0, -2.0, 1.5), (0.5, 0.5, 0.5))
    save_calibration(truth, posed)
    np.testing.assert_array_equal(load_camera_info(posed).rotation, truth.rotation)
    half = tmp_path / 'half.yaml'
    half.write_text(OST_YAML + 'translation: [0.0, 0.0, 1.0]\n')
    with pytest.raises(CalibrationError, match="half.yaml: key 'rotation_matrix': missing"):
        load_camera_info(half)
    with pytest.raises(CalibrationError, match='none.yaml: cannot read'):
        load_camera_info(tmp_path / 'none.yaml')


def test_cli_extrinsics_accepts_a_camera_calibration_ost_yaml(tmp_path, capsys):
    ost = tmp_path / 'ost.yaml'
    ost.write_text(OST_YAML)
    intrinsics = load_camera_info(ost)
    truth = replace(look_at_calibration('narrow_stereo', (3.0, -2.0, 1.5), (0.5, 0.5, 0.5)),
                    camera_matrix=intrinsics.camera_matrix, dist_coeffs=intrinsics.dist_coeffs)
    camera = Camera(truth)
    world = _points_in_view(camera, 30, 5, high=(1.5, 1.5, 0.0))  # points on the floor
    pixels = camera.project(world) + np.random.default_rng(6).normal(0.0, NOISE_PX, (30, 2))
    csv_path = tmp_path / 'points.csv'
    csv_path.write_text('x,y,z,u,v\n' + ''.join(
        ','.join(repr(float(x)) for x in (*w, *p)) + '\n' for w, p in zip(world, pixels)))
    out = tmp_path / 'camera1.yaml'
    assert main(['calibrate', 'extrinsics', '--intrinsics', str(ost), '--points', str(csv_path),
                 '--out', str(out)]) == 0
    fitted = load_calibration(out)
    assert fitted.camera_name == 'narrow_stereo'
    np.testing.assert_array_equal(fitted.camera_matrix, intrinsics.camera_matrix)
    _assert_within(_errors(fitted, truth), cramer_rao(truth, world, NOISE_PX, 5,
                                                      pose_only=True), 'ost.yaml extrinsics')


# -- chessboard videos ---------------------------------------------------------------------------

@pytest.fixture(scope='module')
def board_video(tmp_path_factory):
    """Write an MJPG video: 12 boards, each for 3 frames, 2 frames without a board between."""
    images = render_boards(_board_camera(), 12, 3)
    path = tmp_path_factory.mktemp('boards') / 'boards.avi'
    writer = cv2.VideoWriter(str(path), cv2.CAP_OPENCV_MJPEG, cv2.VideoWriter_fourcc(*'MJPG'),
                             15.0, (640, 480))
    assert writer.isOpened() and writer.set(cv2.VIDEOWRITER_PROP_QUALITY, 95)
    blank = np.full((480, 640, 3), 140, np.uint8)
    for image in images:
        for frame in [cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)] * 3 + [blank] * 2:
            writer.write(frame)
    writer.release()
    return path


def test_video_boards_takes_every_nth_frame_that_shows_the_board(board_video):
    images, labels, count = video_boards(str(board_video), board=BOARD, every_n=5)
    assert count == 60
    # Every 5th frame is the first of a board's three: all 12 boards, no blank frame.
    assert labels == [f'frame {5 * i}' for i in range(12)]
    images, labels, _ = video_boards(str(board_video), board=BOARD, every_n=1, max_boards=7)
    assert len(images) == 7 and labels[0] == 'frame 0' and labels[-1] == 'frame 57'
    _, labels, count = video_boards(str(board_video), board=BOARD, every_n=5, max_frames=20)
    assert count == 20 and len(labels) == 4


def test_cli_intrinsics_from_a_video(tmp_path, capsys, board_video):
    out = tmp_path / 'intrinsics.yaml'
    assert main(['calibrate', 'intrinsics', '--video', str(board_video), '--every', '5',
                 '--board', '8x6', '--square', '0.03', '--out', str(out)]) == 0
    printed = capsys.readouterr().out
    assert '60 frames read; using 12' in printed and 'frame 55' in printed
    fitted, truth = load_calibration(out), _board_camera()
    # As from the image files (test_calibrate): the focal length within a few px of 520.
    assert abs(fitted.camera_matrix[0, 0] - truth.camera_matrix[0, 0]) < 3.0
    assert abs(fitted.camera_matrix[1, 2] - truth.camera_matrix[1, 2]) < 3.0


@pytest.mark.parametrize('args, message', [
    (['--video', 'VIDEO_DIR/none.avi'], 'none.avi: no such video file'),
    (['--video', '/dev/video_none', '--frames', '10'], '/dev/video_none: no such device'),
    (['--video', '/dev/video_none'], 'a camera needs a frame count (--frames)'),
    (['--video', 'VIDEO_DIR/garbage.avi'], 'garbage.avi: cannot open the video'),
    (['--video', 'VIDEO_DIR/garbage.avi', '--images', 'x'], 'not allowed with'),
])
def test_cli_video_errors_exit_2_with_one_line(tmp_path, capsys, args, message):
    (tmp_path / 'garbage.avi').write_bytes(b'not a video')
    args = [a.replace('VIDEO_DIR', str(tmp_path)) for a in args]
    out = tmp_path / 'x.yaml'
    with pytest.raises(SystemExit) if '--images' in args else _no_exit():
        status = main(['calibrate', 'intrinsics', *args, '--board', '8x6', '--square', '0.03',
                       '--out', str(out)])
        assert status == 2
    error = capsys.readouterr().err
    assert message in error and not out.exists()


class _no_exit:  # noqa: N801 - a context manager used like pytest.raises
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


def test_video_boards_rejects_bad_options(board_video):
    with pytest.raises(CalibrationFitError, match='every_n >= 1'):
        video_boards(str(board_video), board=BOARD, every_n=0)


def test_camera_info_files_go_through_the_guarded_yaml_reader(tmp_path):
    # The same reader as calibration files: an alias (a YAML bomb's building block) is refused
    # at once, with the file's name, instead of being expanded.
    path = tmp_path / 'bomb.yaml'
    path.write_text(OST_YAML + 'a: &a [1, 1, 1]\nb: [*a, *a, *a]\n')
    with pytest.raises(CalibrationError, match='bomb.yaml:.*aliases are not allowed'):
        load_camera_info(path)
