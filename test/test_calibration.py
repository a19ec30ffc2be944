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

"""Calibration files: round trip, the real rig's format, and every malformed case."""

import numpy as np
from pseudo_stereo_ros.calibration import (calibration_to_dict, CalibrationError,
                                           load_calibration, save_calibration)
from pseudo_stereo_ros.rig import config_dir
from pseudo_stereo_ros.sim.scenarios import look_at_calibration
import pytest
import yaml

# The real table-tennis rig's camera_1 file, as ROS camera_calibration-style YAML (MIT, see
# test/data/lfg_table_tennis): a numeric camera_name and an identity projection placeholder.
REAL_FILE = """
camera_matrix: {cols: 3, rows: 3, data: [1271.06626, 0, 638.802346, 0, 1274.4406, 507.83008,
                0, 0, 1]}
camera_model: pinhole
camera_name: 22276213
distortion_coefficients: {cols: 5, rows: 1, data: [-0.247491602, 1.27900468, 3.37977705e-05,
                          2.30885568e-06, -7.72113386]}
distortion_model: radtan
image_height: 1024
image_width: 1280
projection_matrix: {cols: 4, rows: 3, data: [1.0, 0, 0, 0, 0, 1.0, 0, 0, 0, 0, 1.0, 0]}
rectification_matrix: {cols: 3, rows: 3, data: [1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0]}
rotation_matrix: {cols: 3, rows: 3, data: [0.7474627231917774, -0.6642324890021845,
    -0.009730261697155351, -0.3185416786942034, -0.34552542990346896, -0.882690985693579,
    0.5829499775910547, 0.6628781017985026, -0.46985311085764137]}
translation: [-1.180126044809713, -0.39876272512510197, 4.534509910063982]
"""


@pytest.fixture
def real_file(tmp_path):
    path = tmp_path / '22276213_calibration.yaml'
    path.write_text(REAL_FILE)
    return path


def test_real_format_loads_with_numeric_name(real_file):
    calibration = load_calibration(real_file)
    assert calibration.camera_name == '22276213'
    assert calibration.distortion_model == 'radtan'
    assert calibration.dist_coeffs.shape == (5,)
    assert (calibration.image_width, calibration.image_height) == (1280, 1024)
    # x_cam = R x_world + t: the centre maps to the camera origin.
    np.testing.assert_allclose(
        calibration.rotation @ calibration.center + calibration.translation, 0, atol=1e-12)


def test_numeric_name_keeps_its_digits(tmp_path):
    data = yaml.safe_load(REAL_FILE)
    path = tmp_path / 'c.yaml'
    text = yaml.safe_dump(data).replace('camera_name: 22276213', 'camera_name: 007')
    path.write_text(text)
    assert load_calibration(path).camera_name == '007'


@pytest.mark.parametrize('model, count', [('plumb_bob', 5), ('rational_polynomial', 8),
                                          ('equidistant', 4)])
def test_save_load_round_trip(tmp_path, model, count):
    coefficients = np.linspace(-0.01, 0.01, count)
    calibration = look_at_calibration('cam', (0, -2, 3), (1, 1, 1), distortion_model=model,
                                      dist_coeffs=coefficients)
    save_calibration(calibration, tmp_path / 'cam.yaml')
    loaded = load_calibration(tmp_path / 'cam.yaml')
    assert loaded.camera_name == 'cam' and loaded.distortion_model == model
    for name in ('camera_matrix', 'dist_coeffs', 'rotation', 'translation'):
        np.testing.assert_array_equal(getattr(loaded, name), getattr(calibration, name))


def test_default_rig_files_load():
    for name in ('camera1', 'camera2'):
        assert load_calibration(config_dir() / 'rig' / f'{name}.yaml').camera_name == name


def _broken(tmp_path, edit):
    data = yaml.safe_load(REAL_FILE)
    edit(data)
    path = tmp_path / 'broken.yaml'
    path.write_text(yaml.safe_dump(data))
    return path


def _rotate_badly(data):
    data['rotation_matrix']['data'][0] = 2.0


def _set(key, value):
    return lambda data: data.__setitem__(key, value)


@pytest.mark.parametrize('edit, key, reason', [
    (lambda d: d.pop('camera_matrix'), 'camera_matrix', 'missing'),
    (lambda d: d.pop('translation'), 'translation', 'missing'),
    (lambda d: d.pop('image_width'), 'image_width', 'missing'),
    (lambda d: d.pop('camera_name'), 'camera_name', 'missing'),
    (_set('translation', [1.0, 2.0]), 'translation', 'expected 3 values'),
    (_set('translation', [1.0, float('nan'), 2.0]), 'translation', 'non-finite'),
    (_set('translation', [1.0, 'abc', 2.0]), 'translation', 'not a numeric'),
    (_rotate_badly, 'rotation_matrix', 'not a rotation'),
    (_set('distortion_model', 'kannala'), 'distortion_model', 'unknown model'),
    (lambda d: d['distortion_coefficients'].update(data=[0.0] * 3, cols=3),
     'distortion_coefficients', 'takes 4 or 5'),
    (lambda d: d['camera_matrix'].update(rows=2), 'camera_matrix', 'rows x cols'),
    (_set('image_height', -5), 'image_height', 'positive integer'),
    (_set('camera_name', ['a', 'b']), 'camera_name', 'expected a name'),
    (lambda d: d['camera_matrix']['data'].__setitem__(1, True), 'camera_matrix', 'boolean'),
    (lambda d: d['camera_matrix'].update(rows=9, cols=1), 'camera_matrix', 'expected 3x3'),
    (lambda d: d['camera_matrix']['data'].__setitem__(0, -10.0), 'camera_matrix', 'focal'),
])
def test_malformed_file_names_file_key_and_reason(tmp_path, edit, key, reason):
    path = _broken(tmp_path, edit)
    with pytest.raises(CalibrationError) as info:
        load_calibration(path)
    message = str(info.value)
    assert str(path) in message and repr(key) in message and reason in message


def test_missing_file_and_bad_yaml(tmp_path):
    with pytest.raises(CalibrationError, match='cannot read'):
        load_calibration(tmp_path / 'nope.yaml')
    bad = tmp_path / 'bad.yaml'
    bad.write_text('camera_matrix: [1, 2\n')
    with pytest.raises(CalibrationError, match='not valid YAML'):
        load_calibration(bad)
    bad.write_text('- just a list\n')
    with pytest.raises(CalibrationError, match='expected a YAML mapping'):
        load_calibration(bad)


def test_to_dict_is_camera_info_compatible(real_file):
    data = calibration_to_dict(load_calibration(real_file))
    for key in ('image_width', 'image_height', 'camera_name', 'camera_matrix',
                'distortion_model', 'distortion_coefficients', 'rotation_matrix', 'translation'):
        assert key in data
    assert data['camera_matrix']['rows'] == 3 and len(data['camera_matrix']['data']) == 9


# -- issue 12: every malformed file is one line naming the file and the reason, never a traceback


def _real_with(old, new):
    assert old in REAL_FILE
    return REAL_FILE.replace(old, new, 1)


@pytest.mark.parametrize('text, key', [
    (_real_with('image_width: 1280', 'image_width: .nan'), 'image_width'),
    (_real_with('image_width: 1280', 'image_width: .inf'), 'image_width'),
    (_real_with('image_height: 1024', 'image_height: -.inf'), 'image_height'),
    (_real_with('image_height: 1024', 'image_height: 1.0e+400'), 'image_height'),
    (_real_with('image_width: 1280', 'image_width: 12800000000000000000000'), 'image_width'),
    (_real_with('image_width: 1280', 'image_width: 1280.5'), 'image_width'),
    (_real_with('{cols: 3, rows: 3, data: [1271', '{cols: .inf, rows: 3, data: [1271'),
     'camera_matrix'),
    (_real_with('{cols: 3, rows: 3, data: [1271', '{cols: 3.5, rows: 3, data: [1271'),
     'camera_matrix'),
    (_real_with('{cols: 3, rows: 3, data: [1271', '{cols: .nan, rows: 3, data: [1271'),
     'camera_matrix'),
    (_real_with('data: [1271.06626,', 'data: [.nan,'), 'camera_matrix'),
    (_real_with('data: [0.7474627231917774,', 'data: [.inf,'), 'rotation_matrix'),
    (_real_with('translation: [-1.180126044809713', 'translation: [-.inf'), 'translation'),
    (_real_with('data: [-0.247491602', 'data: [.nan'), 'distortion_coefficients'),
    (REAL_FILE.split('distortion_coefficients:')[0]
     + 'distortion_coefficients: {rows: 1, cols: 5, data: 5}\n'
     + 'distortion_model:' + REAL_FILE.split('distortion_model:')[1],
     'distortion_coefficients'),
    (REAL_FILE.split('distortion_coefficients:')[0] + 'distortion_coefficients: 5\n'
     + 'distortion_model:' + REAL_FILE.split('distortion_model:')[1],
     'distortion_coefficients'),
    (REAL_FILE.split('distortion_coefficients:')[0]
     + 'distortion_coefficients: {rows: 1, cols: 5, data: {a: 1}}\n'
     + 'distortion_model:' + REAL_FILE.split('distortion_model:')[1],
     'distortion_coefficients'),
    (_real_with('camera_matrix: {cols: 3, rows: 3,', 'camera_matrix: {cols: [3], rows: 3,'),
     'camera_matrix'),
])
def test_non_finite_and_wrongly_shaped_values_are_one_line(tmp_path, text, key):
    # Before: ValueError/OverflowError/TypeError tracebacks from int(nan), int(inf), len(5).
    path = tmp_path / 'cam.yaml'
    path.write_text(text)
    with pytest.raises(CalibrationError) as info:
        load_calibration(path)
    message = str(info.value)
    assert str(path) in message and repr(key) in message and '\n' not in message, message


def _yaml_error(tmp_path, content) -> str:
    path = tmp_path / 'cam.yaml'
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content)
    with pytest.raises(CalibrationError) as info:
        load_calibration(path)
    message = str(info.value)
    assert message.startswith(str(path)) and '\n' not in message, message
    return message[len(str(path)):]


def test_deeply_nested_yaml_is_one_line(tmp_path):
    # Before: RecursionError (a 20,000-level flow sequence) with a 1,000-frame traceback.
    message = _yaml_error(tmp_path, 'camera_name: ' + '[' * 20000 + ']' * 20000 + '\n')
    assert 'nested deeper than' in message


def test_invalid_yaml_is_one_line_with_line_and_column(tmp_path):
    # Before: PyYAML's five-line message (problem, mark, source line, caret).
    text = _real_with('camera_name: 22276213', 'camera_name: [22276213')
    message = _yaml_error(tmp_path, text)
    line = text.splitlines().index('camera_name: [22276213') + 1
    assert message.startswith(f':{line + 1}:') and 'not valid YAML' in message, message
    assert 'flow sequence' in message


@pytest.mark.parametrize('content, reason', [
    (bytes(range(256)) * 4, 'not UTF-8 text'),   # before: UnicodeDecodeError traceback
    (b'camera_name: a\x00b\n', 'not valid YAML'),  # before: PyYAML's two-line ReaderError
    (b'a:\n\tb: 1\n', 'not valid YAML'),
])
def test_binary_yaml_is_one_line(tmp_path, content, reason):
    message = _yaml_error(tmp_path, content)
    assert reason in message, message
    assert message.startswith(':1:') or message.startswith(':2:'), message


def _alias_bomb(levels: int) -> str:
    """Return a calibration whose camera_matrix expands to 9**levels numbers."""
    lines = ['a0: &a0 [1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0]']
    for i in range(1, levels):
        lines.append(f'a{i}: &a{i} [' + ', '.join([f'*a{i - 1}'] * 9) + ']')
    body = [line for line in REAL_FILE.splitlines() if not line.startswith('camera_matrix')
            and not line.startswith('                0, 0, 1]')]
    return '\n'.join(lines + [f'camera_matrix: *a{levels - 1}'] + body) + '\n'


def test_alias_bomb_is_refused_before_it_expands(tmp_path):
    # Before: the aliases were expanded (9**8 numbers: 37-60 s and 845 MB) before the size
    # check. Calibration files never need aliases; the first one is refused while parsing.
    message = _yaml_error(tmp_path, _alias_bomb(6))
    assert ':2:' in message and 'alias' in message, message


def test_an_oversized_file_is_refused_unread(tmp_path):
    message = _yaml_error(tmp_path, REAL_FILE + '# padding\n' * 200_000)
    assert 'larger than' in message, message


def test_aliases_and_oversize_do_not_reject_real_files(real_file):
    # The refusals above are about aliases and size, not the real rig's files (2 KB, no alias).
    assert load_calibration(real_file).camera_name == '22276213'
