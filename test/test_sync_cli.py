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

"""``time_offset_s`` in calibration files, ``pseudo_stereo sync`` and ``track --time-offset``."""

from dataclasses import replace
import json
import shutil

import numpy as np
from pseudo_stereo_ros.calibration import (CalibrationError, load_calibration, save_calibration,
                                           write_time_offsets)
from pseudo_stereo_ros.cli.main import main
from pseudo_stereo_ros.evaluation.time_offsets import simulate_flights
from pseudo_stereo_ros.formats.csv_io import read_estimates, write_observations
from pseudo_stereo_ros.fusion import fuse
from pseudo_stereo_ros.offsets import apply_time_offsets
from pseudo_stereo_ros.rig import config_dir
from pseudo_stereo_ros.sim.scenarios import default_rig
import pytest
import yaml

OFFSET_S = 0.007


@pytest.fixture
def real_file(data_dir, tmp_path):
    path = tmp_path / 'camera.yaml'
    shutil.copy(data_dir / 'lfg_table_tennis' / '22276209_calibration.yaml', path)
    return path


def test_time_offset_round_trips_and_files_without_it_load(tmp_path, repo_dir):
    calibration = load_calibration(repo_dir / 'config' / 'rig' / 'camera1.yaml')
    assert calibration.time_offset_s == 0.0  # no key: 0
    path = tmp_path / 'camera1.yaml'
    save_calibration(replace(calibration, time_offset_s=-0.0123456789), path)
    assert load_calibration(path).time_offset_s == -0.0123456789


@pytest.mark.parametrize('value', ["'abc'", '.nan', '.inf', 'true', '[0.1]', 'null'])
def test_a_bad_time_offset_is_refused_naming_the_key(real_file, value):
    real_file.write_text(real_file.read_text() + f'time_offset_s: {value}\n')
    with pytest.raises(CalibrationError, match=f"{real_file}: key 'time_offset_s': expected a "
                                               'finite number of seconds'):
        load_calibration(real_file)


def test_write_time_offsets_changes_only_that_line(real_file, tmp_path):
    original = real_file.read_bytes()
    write_time_offsets({real_file: -0.0081234})
    assert real_file.read_bytes() == original + b'time_offset_s: -0.0081234\n'
    assert load_calibration(real_file).time_offset_s == -0.0081234
    # An existing line is replaced in place, its comment kept; nothing else moves.
    text = real_file.read_text().replace('time_offset_s: -0.0081234',
                                         'time_offset_s: 0.5  # measured 2026-01-01')
    real_file.write_text('# rig A\n' + text)
    write_time_offsets({real_file: 0.00001})
    assert real_file.read_text() == '# rig A\n' + text.replace('0.5  #', '0.00001  #')
    assert load_calibration(real_file).time_offset_s == 1e-5
    # Windows line ends stay.
    crlf = tmp_path / 'crlf.yaml'
    crlf.write_bytes(original.replace(b'\n', b'\r\n').rstrip(b'\r\n'))
    write_time_offsets({crlf: 0.25})
    assert crlf.read_bytes() == original.replace(b'\n', b'\r\n').rstrip(b'\r\n') \
        + b'\r\ntime_offset_s: 0.25\r\n'


def test_write_time_offsets_refuses_without_touching_any_file(real_file, tmp_path, repo_dir):
    flow = tmp_path / 'flow.yaml'
    data = load_calibration(repo_dir / 'config' / 'rig' / 'camera1.yaml')
    save_calibration(data, flow)
    flow.write_text(yaml.safe_dump(yaml.safe_load(flow.read_text()), default_flow_style=True))
    before = {path: path.read_bytes() for path in (real_file, flow)}
    with pytest.raises(CalibrationError, match=f'{flow}: cannot add time_offset_s'):
        write_time_offsets({real_file: 0.001, flow: 0.002})
    assert {path: path.read_bytes() for path in before} == before
    with pytest.raises(CalibrationError, match='finite'):
        write_time_offsets({real_file: float('nan')})
    assert real_file.read_bytes() == before[real_file]


@pytest.fixture(scope='module')
def recording():
    return simulate_flights(default_rig(), offsets_s={'camera2': OFFSET_S}, fps=30.0,
                            noise_px=0.3, seed=11, scenarios=('spiral', 'bounce', 'straight'))


@pytest.fixture
def files(tmp_path, recording):
    paths = {}
    for camera in default_rig():
        paths[camera.name] = tmp_path / f'{camera.name}.yaml'
        shutil.copy(config_dir() / 'rig' / f'{camera.name}.yaml', paths[camera.name])
    obs = tmp_path / 'obs.csv'
    write_observations(obs, recording.observations)
    return paths, obs


def _camera_args(paths):
    return [arg for name, path in paths.items() for arg in ('--camera', f'{name}={path}')]


def test_sync_json_then_write_then_track_uses_the_offset(files, capsys, tmp_path, recording):
    paths, obs = files
    before = {name: path.read_bytes() for name, path in paths.items()}
    assert main(['sync', *_camera_args(paths), '--input', str(obs), '--json']) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out) >= {'offsets_s', 'uncertainty_s'}
    assert out['offsets_s']['camera1'] == 0.0
    assert abs(out['offsets_s']['camera2'] - OFFSET_S) < 0.5e-3
    assert 0 < out['uncertainty_s']['camera2'] < 0.5e-3
    assert {name: path.read_bytes() for name, path in paths.items()} == before  # no --write

    assert main(['sync', *_camera_args(paths), '--input', str(obs), '--write']) == 0
    captured = capsys.readouterr()
    assert 'camera2' in captured.out and 'wrote time_offset_s' in captured.err
    assert paths['camera1'].read_bytes() == before['camera1']  # the reference keeps its own
    written = paths['camera2'].read_text()
    assert written.startswith(before['camera2'].decode())
    assert written.count('\n') == before['camera2'].decode().count('\n') + 1
    offset = load_calibration(paths['camera2']).time_offset_s
    assert abs(offset - OFFSET_S) < 0.5e-3

    # track applies the file's offset: the same estimates as fusing corrected observations.
    out_csv = tmp_path / 'est.csv'
    assert main(['track', *_camera_args(paths), '--input', str(obs), '--output',
                 str(out_csv)]) == 0
    expected, _ = fuse(default_rig(), apply_time_offsets(recording.observations,
                                                         {'camera2': offset}))
    got = read_estimates(out_csv)
    assert [e.stamp_ns for e in got] == [e.stamp_ns for e in expected]
    np.testing.assert_allclose([(e.x, e.y, e.z) for e in got],
                               [(e.x, e.y, e.z) for e in expected], atol=1e-9)
    # --time-offset overrides the file.
    assert main(['track', *_camera_args(paths), '--input', str(obs), '--output', str(out_csv),
                 '--time-offset', 'camera2=0']) == 0
    plain, _ = fuse(default_rig(), recording.observations)
    assert [e.stamp_ns for e in read_estimates(out_csv)] == [e.stamp_ns for e in plain]


def test_sync_write_is_refused_while_a_camera_has_a_warning(files, capsys, tmp_path,
                                                            recording):
    paths, _ = files
    short = tmp_path / 'short.csv'
    write_observations(short, recording.observations[:20])
    before = {name: path.read_bytes() for name, path in paths.items()}
    assert main(['sync', *_camera_args(paths), '--input', str(short), '--write']) == 2
    err = capsys.readouterr().err
    assert 'warning: camera2: too short' in err
    assert err.splitlines()[-1].startswith('pseudo_stereo sync: error: --write: not writing: '
                                           'camera2')
    assert {name: path.read_bytes() for name, path in paths.items()} == before


@pytest.mark.parametrize('command', ['sync', 'refine'])
@pytest.mark.parametrize('case, message', [
    ('missing', 'cannot read'),
    ('unknown camera', "unknown camera 'camera9'"),
    ('no reference', "no observations of camera 'camera1'"),
    ('bad number', '--max-gap-s'),
    ('bad calibration', "key 'camera_matrix'"),
    ('missing bag', 'nope'),
])
def test_bad_input_is_one_line_exit_2_and_nothing_written(files, capsys, tmp_path, command,
                                                          case, message, recording):
    paths, obs = files
    args = _camera_args(paths)
    source = ['--input', str(obs)]
    extra = ['--write'] if command == 'sync' else ['--out-dir', str(tmp_path / 'out')]
    if case == 'missing':
        source = ['--input', str(tmp_path / 'none.csv')]
    elif case == 'unknown camera':
        obs.write_text(obs.read_text() + f'{recording.observations[-1].stamp_ns},camera9,1,2\n')
    elif case == 'no reference':
        write_observations(obs, [o for o in recording.observations if o.camera == 'camera2'])
    elif case == 'bad number':
        extra += ['--max-gap-s', '-1']
    elif case == 'bad calibration':
        paths['camera2'].write_text('camera_name: camera2\nimage_width: 640\n'
                                    'image_height: 480\n')
    elif case == 'missing bag':
        source = ['--bag', str(tmp_path / 'nope')]
    before = {name: path.read_bytes() for name, path in paths.items()}
    assert main([command, *args, *source, *extra]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count('\n') == 1, err
    assert {name: path.read_bytes() for name, path in paths.items()} == before
    assert not (tmp_path / 'out').exists()


def test_track_rejects_a_bad_time_offset(files, capsys, tmp_path):
    paths, obs = files
    for value, message in (('camera2', 'expected NAME=SECONDS'), ('camera2=x', 'NAME=SECONDS'),
                           ('camera2=nan', 'NAME=SECONDS'),
                           ('camera7=0.1', "no camera 'camera7'")):
        assert main(['track', *_camera_args(paths), '--input', str(obs), '--output',
                     str(tmp_path / 'e.csv'), '--time-offset', value]) == 2
        err = capsys.readouterr().err
        assert message in err and err.count('\n') == 1
    assert not (tmp_path / 'e.csv').exists()
