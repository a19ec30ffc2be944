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

from pseudo_stereo_ros.cli.main import main
from pseudo_stereo_ros.rig import config_dir
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


def test_bad_option_values_exit_2(tmp_path, capsys):
    status, output = track(tmp_path, GOOD, '--max-gap', 'inf')
    assert status == 2 and 'finite' in capsys.readouterr().err and not output.exists()
    assert main(['simulate', '--scenario', 'straight', '--noise', 'nan', '--out',
                 str(tmp_path / 's')]) == 2
    assert '--noise' in capsys.readouterr().err
    assert main(['table1', '--noise', '-1', '--out', str(tmp_path / 't')]) == 2


def test_unwritable_output_exits_2(tmp_path, capsys):
    observations = tmp_path / 'obs.csv'
    observations.write_text(GOOD)
    status = main(['track', *CAMERAS, '--input', str(observations), '--output', str(tmp_path)])
    assert status == 2 and 'is a directory' in capsys.readouterr().err


def test_encodings(tmp_path, capsys):
    # A byte-order mark (spreadsheet export) is fine; bytes that are not UTF-8 are an error.
    observations = tmp_path / 'obs.csv'
    observations.write_bytes(b'\xef\xbb\xbf' + GOOD.encode())
    assert main(['track', *CAMERAS, '--input', str(observations), '--output',
                 str(tmp_path / 'e.csv')]) == 0
    observations.write_bytes(GOOD.encode() + b'1700000000033333333,camera1,\xff\xfe,2\n')
    assert main(['track', *CAMERAS, '--input', str(observations), '--output',
                 str(tmp_path / 'f.csv')]) == 2
    assert 'not a UTF-8 CSV' in capsys.readouterr().err
    assert not (tmp_path / 'f.csv').exists()


def test_truth_in_any_order_and_a_mismatch_writes_nothing(tmp_path, capsys):
    assert main(['simulate', '--scenario', 'straight', '--out', str(tmp_path)]) == 0
    lines = (tmp_path / 'truth.csv').read_text().splitlines()
    shuffled = tmp_path / 'shuffled.csv'
    shuffled.write_text('\n'.join([lines[0]] + lines[:0:-1]) + '\n')
    args = ['track', '--camera', f'camera1={tmp_path / "camera1.yaml"}', '--camera',
            f'camera2={tmp_path / "camera2.yaml"}', '--input', str(tmp_path / 'observations.csv')]
    assert main(args + ['--output', str(tmp_path / 'a.csv'), '--truth', str(shuffled)]) == 0
    shuffled.write_text('\n'.join(lines[:5]) + '\n')  # truth of the first stamps only
    assert main(args + ['--output', str(tmp_path / 'b.csv'), '--truth', str(shuffled)]) == 2
    assert 'no ground truth' in capsys.readouterr().err
    assert not (tmp_path / 'b.csv').exists()


# -- issue 12: one line, never a traceback ------------------------------------------------------


@pytest.mark.parametrize('command', ['check', 'track'])
@pytest.mark.parametrize('stamp', [10 ** 30, 2 ** 63, -2 ** 63 - 1])
def test_stamps_outside_int64_are_refused_where_they_are_read(tmp_path, capsys, command, stamp):
    # Before: `check` died with OverflowError in numpy; `track` accepted 10^30 ns.
    observations = tmp_path / 'obs.csv'
    observations.write_text(GOOD + f'{stamp},camera1,300,200\n')
    output = tmp_path / 'est.csv'
    args = [command, *CAMERAS, '--input', str(observations)]
    status = main(args + (['--output', str(output)] if command == 'track' else []))
    error = capsys.readouterr().err
    assert status == 2 and error.count('\n') == 1, error
    assert 'obs.csv:4: column stamp_ns:' in error and 'int64' in error
    assert not output.exists()


def test_int64_limits_are_valid_stamps(tmp_path, capsys):
    observations = tmp_path / 'obs.csv'
    observations.write_text(GOOD + f'{2 ** 63 - 1},camera1,300,200\n'
                            f'{-2 ** 63},camera2,300,200\n')
    status, output = track(tmp_path, observations.read_text())
    assert status == 0, capsys.readouterr().err


def test_a_bad_byte_far_into_a_file_names_its_line(tmp_path, capsys):
    # Decoding happens in 8 KB chunks; the line named is the bad byte's, not the chunk's.
    rows = [f'{1700000000000000000 + k * 16666667},camera{1 + k % 2},300.5,200.25\n'
            for k in range(2000)]
    observations = tmp_path / 'obs.csv'
    head, tail = 'stamp_ns,camera,u,v\n' + ''.join(rows[:1500]), ''.join(rows[1500:])
    observations.write_bytes(head.encode() + b'1700000000000000000,caf\xe9,1,2\n' + tail.encode())
    status = main(['track', *CAMERAS, '--input', str(observations), '--output',
                   str(tmp_path / 'e.csv')])
    error = capsys.readouterr().err
    assert status == 2 and error.count('\n') == 1
    assert 'obs.csv:1502: not a UTF-8 CSV file (byte 0xe9' in error, error


def test_a_field_over_the_csv_limit_is_one_line(tmp_path, capsys):
    status, output = track(tmp_path, GOOD + '1700000000033333333,camera1,' + '1' * 200_000
                           + ',2\n')
    error = capsys.readouterr().err
    assert status == 2 and error.count('\n') == 1
    assert 'obs.csv:4: malformed CSV: field larger than field limit' in error, error
    assert not output.exists()


@pytest.mark.parametrize('name', ['cam-1', 'cam 1', '22276213', '_cam', 'camera/1'])
def test_camera_names_that_are_not_ros_names_are_refused(tmp_path, capsys, name):
    # One rule for the CLI and the nodes: the name is the topic namespace of its image points.
    observations = tmp_path / 'obs.csv'
    observations.write_text(GOOD.replace('camera1', name))
    status = main(['track', '--camera', f'{name}={RIG / "camera1.yaml"}', *CAMERAS[2:],
                   '--input', str(observations), '--output', str(tmp_path / 'e.csv')])
    error = capsys.readouterr().err
    assert status == 2 and error.count('\n') == 1, error
    assert f'{name!r} is not a valid ROS name' in error and 'a letter, then letters' in error


@pytest.mark.parametrize('offset_ns', [-1_800_000_000_000_000_000, 600_000_000_000_000_000])
def test_stamps_a_bag_cannot_hold_are_refused_before_writing(tmp_path, capsys, offset_ns):
    # Valid int64 stamps before 1970 or after 2038 (Time.sec is an int32): before, the bag
    # writer's struct.error traceback, after the CSV had been written.
    assert main(['simulate', '--scenario', 'straight', '--out', str(tmp_path)]) == 0
    lines = (tmp_path / 'observations.csv').read_text().splitlines()
    shifted = tmp_path / 'shifted.csv'
    shifted.write_text('\n'.join([lines[0]] + [
        f'{int(line.split(",", 1)[0]) + offset_ns},{line.split(",", 1)[1]}'
        for line in lines[1:]]) + '\n')
    output, bag = tmp_path / 'e.csv', tmp_path / 'bag'
    capsys.readouterr()
    status = main(['track', *CAMERAS, '--input', str(shifted), '--output', str(output),
                   '--output-bag', str(bag)])
    error = capsys.readouterr().err
    assert status == 2 and error.count('\n') == 1, error
    assert 'cannot write stamp' in error and 'Time.sec is an int32' in error
    assert not output.exists() and not bag.exists()
