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

"""Command-line errors: exit status 2, one line naming the input, no half-written output."""

import subprocess
import sys

from pseudo_stereo_ros.cli import main
from pseudo_stereo_ros.simulation import config_dir
import pytest

RIG = config_dir() / 'rig'
CAMERAS = ['--camera', f'camera1={RIG / "camera1.yaml"}', '--camera',
           f'camera2={RIG / "camera2.yaml"}']


def track(tmp_path, text, *extra):
    observations = tmp_path / 'obs.csv'
    observations.write_text(text)
    output = tmp_path / 'est.csv'
    status = main(['track', *CAMERAS, '--input', str(observations), '--output', str(output),
                   *extra])
    return status, output


GOOD = ('stamp_ns,camera,u,v\n'
        '1700000000000000000,camera1,300.5,200.25\n'
        '1700000000016666667,camera2,310.0,210.0\n')


@pytest.mark.parametrize('text, message', [
    (GOOD + '1700000000033333333,camera3,1,2\n', 'obs.csv:4: unknown camera'),
    (GOOD + '1700000000033333333,camera1,abc,2\n', 'obs.csv:4: column u: not a number'),
    (GOOD + '1.7e18,camera1,1,2\n', 'obs.csv:4: column stamp_ns: not an integer'),
    ('stamp_ns,camera,u\n1,camera1,2\n', 'obs.csv:1: missing column(s) v'),
    ('', 'missing column(s) stamp_ns, camera, u, v'),
])
def test_bad_observations_exit_2_naming_the_line(tmp_path, capsys, text, message):
    status, output = track(tmp_path, text)
    assert status == 2
    error = capsys.readouterr().err
    assert message in error and error.count('\n') == 1
    assert not output.exists()


def test_bad_camera_arguments(tmp_path, capsys):
    observations = tmp_path / 'obs.csv'
    observations.write_text(GOOD)
    for cameras, message in (
            (['--camera', 'camera1'], 'expected NAME=CALIB.yaml'),
            (['--camera', f'camera1={RIG / "camera1.yaml"}'], 'need at least 2 cameras'),
            (CAMERAS[:2] + ['--camera', f'camera2={tmp_path / "none.yaml"}'], 'cannot read'),
            (CAMERAS + ['--camera', f'camera2={RIG / "camera2.yaml"}'], 'given twice')):
        status = main(['track', *cameras, '--input', str(observations), '--output',
                       str(tmp_path / 'e.csv')])
        assert status == 2
        assert message in capsys.readouterr().err


def test_bad_fuser_options(tmp_path, capsys):
    status, _ = track(tmp_path, GOOD, '--max-gap', '0.0005')
    assert status == 2 and 'must exceed' in capsys.readouterr().err


def test_non_finite_pixels_are_dropped_and_counted(tmp_path, capsys):
    status, output = track(tmp_path, GOOD + '1700000000033333333,camera1,nan,2\n')
    assert status == 0
    assert 'non_finite 1' in capsys.readouterr().err
    assert output.read_text().splitlines()[0] == 'stamp_ns,camera,x,y,z'


def test_console_entry_point_runs():
    result = subprocess.run([sys.executable, '-m', 'pseudo_stereo_ros.cli', '--help'],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 0
    for command in ('table1', 'simulate', 'track', 'bench'):
        assert command in result.stdout
