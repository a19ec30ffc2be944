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

"""The rig: named cameras built one way, with their pairwise geometry."""

import numpy as np
from pseudo_stereo_ros.errors import CalibrationError, RigError
from pseudo_stereo_ros.geometry import fundamental_matrix
from pseudo_stereo_ros.rig import check_camera_name, config_dir, Rig
from pseudo_stereo_ros.sim.scenarios import default_rig
import pytest


def test_default_rig_names_order_and_geometry():
    rig = Rig.default()
    assert rig.names == ['camera1', 'camera2'] == list(rig)
    assert [c.name for c in default_rig()] == rig.names
    f = rig.fundamental('camera1', 'camera2')
    np.testing.assert_allclose(f, fundamental_matrix(rig['camera1'], rig['camera2']))
    # A world point's ideal pixels satisfy the epipolar constraint of the pair.
    point = np.array([[1.5, 1.0, 1.0]])
    p_a = np.append(rig['camera1'].ideal_pixels(rig['camera1'].project(point))[0], 1.0)
    p_b = np.append(rig['camera2'].ideal_pixels(rig['camera2'].project(point))[0], 1.0)
    assert abs(p_b @ f @ p_a) / np.linalg.norm((f @ p_a)[:2]) < 1e-6
    assert rig.pairs() == [('camera1', 'camera2')]


def test_user_name_overrides_the_file_name():
    path = config_dir() / 'rig' / 'camera1.yaml'
    rig = Rig.from_files([('left', path), ('right', config_dir() / 'rig' / 'camera2.yaml')])
    assert rig.names == ['left', 'right'] and rig['left'].name == 'left'


@pytest.mark.parametrize('names, match', [
    (['a', 'a'], 'unique'),
    (['a'], 'at least 2'),
])
def test_bad_rigs_are_refused(names, match):
    path = config_dir() / 'rig' / 'camera1.yaml'
    with pytest.raises(RigError, match=match):
        Rig.from_files([(name, path) for name in names], minimum=2)


def test_missing_file_names_the_file(tmp_path):
    with pytest.raises(CalibrationError, match='nothing.yaml'):
        Rig.from_files([('a', tmp_path / 'nothing.yaml')])


@pytest.mark.parametrize('name', ['cam-1', 'cam 1', '22276213', '_cam', 'camera/1', 'kamera_é',
                                  'a' * 101, ''])
def test_names_that_are_not_ros_names_are_refused(name):
    # Before: accepted here, then a 26-line InvalidTopicNameException in the fuser node.
    path = config_dir() / 'rig' / 'camera1.yaml'
    with pytest.raises(RigError) as info:
        Rig.from_files([(name, path), ('camera2', path)])
    message = str(info.value)
    assert repr(name) in message and '\n' not in message
    assert 'a letter, then letters, digits or underscores' in message


@pytest.mark.parametrize('name, suggestion', [('cam-1', 'cam_1'), ('22276213', 'camera_22276213'),
                                              ('cam 1', 'cam_1'), ('_cam', 'camera_cam')])
def test_the_refusal_suggests_a_valid_name(name, suggestion):
    with pytest.raises(RigError, match=f"e.g. '{suggestion}'"):
        check_camera_name(name)
    check_camera_name(suggestion)


@pytest.mark.parametrize('name', ['camera1', 'camera_1', 'Cam2', 'c', 'left_cam_22276213',
                                  'a' * 100])
def test_ros_names_are_accepted(name):
    assert check_camera_name(name) == name
