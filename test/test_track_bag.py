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

"""``pseudo_stereo track --bag``: estimates as from CSV, images through detectors, errors."""

import dataclasses
import os
from pathlib import Path
import re
import subprocess
import sys

import numpy as np
from pseudo_stereo_ros.camera import Camera
from pseudo_stereo_ros.cli.main import main
from pseudo_stereo_ros.detection import BallDetector
from pseudo_stereo_ros.formats.bagio import (bag_topics, GROUND_TRUTH_TOPIC, image_message,
                                             image_topic, IMAGE_TYPE, iter_raw, point_message,
                                             POSITION_TOPIC, read_images, read_positions,
                                             typestore, write_messages, write_observations)
from pseudo_stereo_ros.formats.csv_io import read_estimates, write_observations as write_csv
from pseudo_stereo_ros.fusion import fuse
from pseudo_stereo_ros.records import Observation
from pseudo_stereo_ros.ros import messages
from pseudo_stereo_ros.sim.rendering import BallRenderer
from pseudo_stereo_ros.sim.scenarios import (default_rig, make_scenario, observe, shutter_stamps,
                                             truth_at)
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer
from test_bagio import BAD_BAGS, CAMERAS as LFG_CAMERAS, LFG

DATA = Path(__file__).resolve().parent / 'data'
SYNTHETIC = DATA / 'synthetic_images'
BAG = SYNTHETIC / 'spiral'
RIG_ARGS = ['--camera', f'camera1={SYNTHETIC / "camera1.yaml"}',
            '--camera', f'camera2={SYNTHETIC / "camera2.yaml"}']
# The detector's sub-pixel accuracy on noise-free renderings (test_detection's bound) [px].
CENTROID_PX = 0.1


def _cameras():
    return [Camera.from_file(SYNTHETIC / f'{name}.yaml') for name in ('camera1', 'camera2')]


def _xyz(estimates):
    return np.array([(e.x, e.y, e.z) for e in estimates]).reshape(-1, 3)


def test_synthetic_bag_is_small_and_complete():
    size = sum(f.stat().st_size for f in SYNTHETIC.rglob('*') if f.is_file())
    assert size < 2_000_000, size
    assert (SYNTHETIC / 'README.md').is_file()
    assert bag_topics(BAG) == {'/camera1/image_raw': IMAGE_TYPE,
                               '/camera2/image_raw': IMAGE_TYPE,
                               GROUND_TRUTH_TOPIC: 'geometry_msgs/msg/PointStamped'}


def test_bag_gives_the_same_estimates_as_the_equivalent_csv(tmp_path):
    cameras = _cameras()
    scenario = make_scenario('bounce')
    stamps = [shutter_stamps(30.0, 1.0, phase_s=i / 60.0) for i in range(2)]
    observations = observe(scenario, cameras, stamps, noise_px=0.3, dropout=0.05, seed=3)
    write_csv(tmp_path / 'obs.csv', observations)
    write_observations(tmp_path / 'obs_bag', observations)
    args = RIG_ARGS
    assert main(['track', *args, '--input', str(tmp_path / 'obs.csv'),
                 '--output', str(tmp_path / 'from_csv.csv')]) == 0
    assert main(['track', *args, '--bag', str(tmp_path / 'obs_bag'),
                 '--output', str(tmp_path / 'from_bag.csv'),
                 '--output-bag', str(tmp_path / 'est_bag'), '--world-frame', 'map']) == 0
    from_csv = read_estimates(tmp_path / 'from_csv.csv')
    from_bag = read_estimates(tmp_path / 'from_bag.csv')
    expected, _ = fuse(cameras, observations)
    assert len(expected) > 50
    assert from_bag == from_csv
    assert [e.stamp_ns for e in from_csv] == [e.stamp_ns for e in expected]
    np.testing.assert_allclose(_xyz(from_csv), _xyz(expected), rtol=0, atol=1e-9)
    # The output bag: /ball/position, PointStamped in the world frame, shutter stamps.
    assert bag_topics(tmp_path / 'est_bag') == {POSITION_TOPIC: 'geometry_msgs/msg/PointStamped'}
    positions = read_positions(tmp_path / 'est_bag')
    assert [p[0] for p in positions] == [e.stamp_ns for e in expected]
    np.testing.assert_allclose([p[1:] for p in positions], _xyz(expected), rtol=0, atol=1e-12)
    frames = {typestore().deserialize_cdr(data, 'geometry_msgs/msg/PointStamped').header.frame_id
              for data in _raw(tmp_path / 'est_bag')}
    assert frames == {'map'}


def _raw(path):
    return [data for _, _, _, data in iter_raw(path)]


def test_image_bag_runs_the_detectors_and_tracks_within_the_bound(tmp_path, capsys):
    """
    Error against ground truth = the method's own error + what the detector adds.

    The method's error is measured in the same run on exact projections of the bag's ground
    truth (what a perfect detector would give).  The detector adds at most
    CENTROID_PX * range / f metres sideways to each of the two rays of an estimate; two
    rays at angle theta then move the triangulated point by at most (e1 + e2) / sin(theta).
    """
    cameras = _cameras()
    out = tmp_path / 'est.csv'
    assert main(['track', '--bag', str(BAG), *RIG_ARGS, '--output', str(out)]) == 0
    err = capsys.readouterr()
    assert 'camera1: ball found in 31 of 31 images' in err.err
    assert 'camera2: ball found in 30 of 30 images' in err.err
    assert 'error against' in err.out and '/ball/ground_truth' in err.out
    estimates = read_estimates(out)

    truth = {p[0]: np.array(p[1:]) for p in read_positions(BAG, GROUND_TRUTH_TOPIC)}
    image_stamps = {camera.name: [s for s, _, _, _ in read_images(BAG, image_topic(camera.name))]
                    for camera in cameras}
    exact = sorted((Observation(camera.name, s, *camera.project(truth[s][None])[0])
                    for camera in cameras for s in image_stamps[camera.name]),
                   key=lambda o: o.stamp_ns)
    reference, _ = fuse(cameras, exact)
    assert [e.stamp_ns for e in estimates] == [e.stamp_ns for e in reference]
    assert len(estimates) >= 58  # 61 shutter events, 3 to warm up

    points = np.array([truth[s] for s in truth])
    ranges = [np.linalg.norm(points - camera.center, axis=1) for camera in cameras]
    lateral_m = [CENTROID_PX * r.max() / camera.K[0, 0] for r, camera in zip(ranges, cameras)]
    rays = [points - camera.center for camera in cameras]
    cos_theta = np.sum(rays[0] * rays[1], axis=1) / ranges[0] / ranges[1]
    sin_theta_min = np.sqrt(1 - cos_theta ** 2).min()
    bound_m = sum(lateral_m) / sin_theta_min  # 2.8 mm on this rig
    assert 1e-3 < bound_m < 5e-3

    detector_effect = np.linalg.norm(_xyz(estimates) - _xyz(reference), axis=1)
    assert detector_effect.max() < bound_m
    errors = np.linalg.norm(_xyz(estimates) - [truth[e.stamp_ns] for e in estimates], axis=1)
    method_errors = np.linalg.norm(_xyz(reference) - [truth[e.stamp_ns] for e in reference],
                                   axis=1)
    assert errors.mean() < method_errors.mean() + bound_m
    # Naive pairing on the same detections is an order of magnitude worse (time offset).
    assert main(['track', '--bag', str(BAG), *RIG_ARGS, '--output', str(out),
                 '--method', 'naive']) == 0
    naive = read_estimates(out)
    naive_errors = np.linalg.norm(_xyz(naive) - [truth[e.stamp_ns] for e in naive], axis=1)
    assert errors.mean() < naive_errors.mean() / 5


def test_detector_params_file_is_used(tmp_path, repo_dir):
    out = tmp_path / 'est.csv'
    assert main(['track', '--bag', str(BAG), *RIG_ARGS, '--output', str(out),
                 '--detector-params', str(repo_dir / 'config' / 'detector.yaml')]) == 0
    default = read_estimates(out)
    # A hue range that excludes the orange ball: no detections, hence no estimates.
    blue = tmp_path / 'blue.yaml'
    blue.write_text('/**/detector:\n  ros__parameters:\n    hsv_lower: [100, 120, 100]\n'
                    '    hsv_upper: [130, 255, 255]\n')
    assert main(['track', '--bag', str(BAG), *RIG_ARGS, '--output', str(out),
                 '--detector-params', str(blue)]) == 0
    assert len(default) >= 58 and read_estimates(out) == []


def _image_bag(tmp_path, *, wrong_type=False, messages=True):
    cameras = default_rig()
    path = tmp_path / 'images'
    store = typestore()
    if not messages:
        with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as bag:
            for camera in cameras:
                bag.add_connection(image_topic(camera.name), IMAGE_TYPE, typestore=store)
        return path
    scenario = make_scenario('spiral')
    stamp = int(shutter_stamps(30.0, 0.1)[1])
    position = truth_at(scenario, np.array([stamp]))[0]
    items = []
    for camera in cameras:
        pixels = BallRenderer(camera, texture=False).render(position)
        if wrong_type and camera.name == 'camera2':
            items.append((image_topic(camera.name), 'geometry_msgs/msg/PointStamped', stamp,
                          point_message(stamp, 'camera2', 1.0, 2.0, 0.0)))
        else:
            items.append((image_topic(camera.name), IMAGE_TYPE, stamp,
                          image_message(stamp, camera.name, pixels)))
    write_messages(path, items, compress=True)
    return path


def _truncated_compressed(tmp_path):
    path = _image_bag(tmp_path)
    data = next(path.glob('*.zstd'))
    os.truncate(data, data.stat().st_size // 2)
    return path


IMAGE_BAD_BAGS = {
    'image_wrong_type': (lambda tmp: _image_bag(tmp, wrong_type=True),
                         'topic /camera2/image_raw has type geometry_msgs/msg/PointStamped, '
                         'expected sensor_msgs/msg/Image'),
    'image_empty': (lambda tmp: _image_bag(tmp, messages=False),
                    'no messages on /camera1/image_raw'),
    'image_truncated': (_truncated_compressed, 'not a readable ROS 2 bag|corrupt or truncated'),
}


def _lfg_args():
    args = []
    for camera, serial in LFG_CAMERAS.items():
        args += ['--camera', f'{camera}={LFG / f"{serial}_calibration.yaml"}']
    return args


@pytest.mark.parametrize('kind', sorted(BAD_BAGS) + sorted(IMAGE_BAD_BAGS))
def test_bad_bag_exits_2_with_one_line(tmp_path, kind, capsys):
    make, match = {**BAD_BAGS, **IMAGE_BAD_BAGS}[kind]
    path = make(tmp_path)
    cameras = RIG_ARGS if kind.startswith('image') else _lfg_args()
    out = tmp_path / 'est.csv'
    assert main(['track', '--bag', str(path), *cameras, '--output', str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith('pseudo_stereo track: error: ')
    assert len(err.strip().splitlines()) == 1
    assert re.search(match, err), err
    assert not out.exists()


def test_image_bag_without_ball_images_is_fine(tmp_path, capsys):
    path = _image_bag(tmp_path)
    assert main(['track', '--bag', str(path), *RIG_ARGS, '--output',
                 str(tmp_path / 'e.csv')]) == 0
    assert 'ball found in 1 of 1 images' in capsys.readouterr().err


def test_empty_and_wrong_encoding_images_are_counted_not_fatal(tmp_path, capsys):
    # An empty image made OpenCV assert (cv2.error) and the command crash with a traceback.
    cameras = default_rig()
    scenario = make_scenario('spiral')
    stamps = [int(s) for s in shutter_stamps(30.0, 0.2)[1:4]]
    items = []
    for stamp in stamps:
        position = truth_at(scenario, np.array([stamp]))[0]
        for camera in cameras:
            items.append((image_topic(camera.name), IMAGE_TYPE, stamp, image_message(
                stamp, camera.name, BallRenderer(camera, texture=False).render(position))))
    good = items[-1][3]
    empty = dataclasses.replace(good, height=0, width=0, step=0, data=np.zeros(0, np.uint8))
    wrong = dataclasses.replace(good, encoding='16UC1')
    late = stamps[-1] + 10_000_000
    items += [(image_topic('camera2'), IMAGE_TYPE, late, empty),
              (image_topic('camera2'), IMAGE_TYPE, late + 1, wrong)]
    path = tmp_path / 'images'
    write_messages(path, items)
    assert main(['track', '--bag', str(path), *RIG_ARGS, '--output',
                 str(tmp_path / 'e.csv')]) == 0
    err = capsys.readouterr().err
    assert 'camera1: ball found in 3 of 3 images' in err
    assert 'camera2: ball found in 3 of 5 images of /camera2/image_raw (2 unusable)' in err


@pytest.mark.parametrize('extra, message', [
    ([], 'give --output EST.csv and/or --output-bag OUT'),
    (['--output-bag', '{tmp}'], 'exists already'),
    (['--output', '{tmp}/e.csv', '--detector-params', '{tmp}/none.yaml'],
     '--detector-params .*none.yaml: cannot read'),
    (['--output', '{tmp}/e.csv', '--detector-params', '{params}'],
     "unknown detector parameter 'hue'"),
])
def test_bad_options_exit_2(tmp_path, capsys, extra, message):
    params = tmp_path / 'params.yaml'
    params.write_text('detector:\n  ros__parameters:\n    hue: 3\n')
    extra = [x.format(tmp=tmp_path, params=params) for x in extra]
    assert main(['track', '--bag', str(BAG), *RIG_ARGS, *extra]) == 2
    err = capsys.readouterr().err
    assert re.search(message, err) and len(err.strip().splitlines()) == 1, err


def test_input_and_bag_are_exclusive(tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(['track', '--bag', str(BAG), '--input', 'x.csv', *RIG_ARGS, '--output', 'e.csv'])
    assert exit_info.value.code == 2
    assert 'not allowed with argument' in capsys.readouterr().err


def test_console_script_bad_bag_has_no_traceback(tmp_path):
    garbage = tmp_path / 'bad.mcap'
    garbage.write_bytes(b'not a bag' * 100)
    result = subprocess.run([str(Path(sys.executable).parent / 'pseudo_stereo'), 'track',
                             '--bag', str(garbage), *RIG_ARGS, '--output',
                             str(tmp_path / 'e.csv')],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 2
    assert 'Traceback' not in result.stderr
    assert result.stderr.startswith('pseudo_stereo track: error: ')


def test_detection_in_the_bag_path_equals_the_node_conversion():
    # image_array (bag path) and messages.image_to_array (node path) are one function.
    stamp, encoding, pixels, problem = next(read_images(BAG, '/camera1/image_raw'))
    assert problem is None and encoding == 'bgr8'
    msg = messages.array_to_image(pixels, encoding, stamp, 'camera1')
    np.testing.assert_array_equal(messages.image_to_array(msg), pixels)
    assert BallDetector().detect(pixels, encoding) == \
        BallDetector().detect(messages.image_to_array(msg), msg.encoding)


@pytest.mark.parametrize('unusable', ['camera2', 'both'])
def test_a_camera_whose_every_image_is_unusable_exits_2(tmp_path, capsys, unusable):
    # Before: exit status 0 and an empty estimates file, the reason only in a count.
    cameras = default_rig()
    scenario = make_scenario('spiral')
    items = []
    for stamp in [int(s) for s in shutter_stamps(30.0, 0.2)[1:4]]:
        position = truth_at(scenario, np.array([stamp]))[0]
        for camera in cameras:
            message = image_message(stamp, camera.name,
                                    BallRenderer(camera, texture=False).render(position))
            if unusable == 'both' or camera.name == 'camera2':
                message = dataclasses.replace(message, encoding='16UC1')
            items.append((image_topic(camera.name), IMAGE_TYPE, stamp, message))
    path = tmp_path / 'images'
    write_messages(path, items)
    out, out_bag = tmp_path / 'e.csv', tmp_path / 'e_bag'
    assert main(['track', '--bag', str(path), *RIG_ARGS, '--output', str(out),
                 '--output-bag', str(out_bag)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1, err
    first = 'camera1' if unusable == 'both' else 'camera2'
    assert f'all 3 images of /{first}/image_raw are unusable' in err, err
    assert "'16UC1'" in err
    assert not out.exists() and not out_bag.exists()
