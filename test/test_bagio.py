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

"""Bags through rosbags: round trips, the real-data bags, and every kind of bad bag."""

import os
from pathlib import Path

import numpy as np
from pseudo_stereo_ros.cli.main import main
from pseudo_stereo_ros.formats.bagio import (bag_cameras, bag_message_counts, BagError,
                                             image_message, image_point_topic, iter_raw,
                                             point_message, read_observations, read_positions,
                                             typestore, write_estimates, write_observations)
from pseudo_stereo_ros.records import Estimate, Observation
from pseudo_stereo_ros.ros import messages
from pseudo_stereo_ros.stamps import ns_to_sec_nanosec, sec_nanosec_to_ns, stamp_fields, stamp_ns
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer

LFG = Path(__file__).resolve().parent / 'data' / 'lfg_table_tennis'
SESSIONS = ('n1_n1', 'n3_p1_v14', 'p2_p2')
CAMERAS = {'camera_1': '22276213', 'camera_2': '22276209', 'camera_3': '22276216'}
EPOCH = 1_721_679_791_176_049_240


def _observations():
    return [Observation('cam_a', EPOCH + 5_950_000 * k, 100.0 + k, 200.5 - k) for k in range(5)] \
        + [Observation('cam_b', EPOCH + 2_500_000 + 5_950_000 * k, 300.25, 40.0 + 0.5 * k)
           for k in range(4)]


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_observations_round_trip(tmp_path, storage):
    observations = _observations()
    assert write_observations(tmp_path / 'bag', observations, storage=storage) == 9
    back = read_observations(tmp_path / 'bag')
    # Integer stamps survive exactly (sec/nanosec split), pixels are float64 in the message.
    assert sorted(back) == sorted(observations)
    assert bag_cameras(tmp_path / 'bag') == ['cam_a', 'cam_b']
    assert read_observations(tmp_path / 'bag', ['cam_b']) == sorted(
        (o for o in observations if o.camera == 'cam_b'), key=lambda o: o.stamp_ns)


def test_estimates_round_trip(tmp_path):
    estimates = [Estimate(EPOCH + 3_000_000 * k, 'cam_a', 0.5 * k, -3.25, 0.125, 'pseudo')
                 for k in range(4)]
    write_estimates(tmp_path / 'est', estimates, frame_id='world')
    positions = read_positions(tmp_path / 'est')
    assert positions == [(e.stamp_ns, e.x, e.y, e.z) for e in estimates]
    topics = {topic for topic, *_ in iter_raw(tmp_path / 'est')}
    assert topics == {'/ball/position'}


STAMPS = [0, 1, 999_999_999, 1_000_000_000, 1_000_000_001, 1_721_679_791_176_049_240,
          (2 ** 31 - 1) * 1_000_000_000 + 999_999_999]


@pytest.mark.parametrize('stamp', STAMPS)
def test_one_stamp_split_for_bags_and_messages(stamp):
    """The rosbags messages of bagio and the rclpy messages of messages.py carry one layout."""
    sec, nanosec = ns_to_sec_nanosec(stamp)
    assert 0 <= nanosec < 1_000_000_000 and sec_nanosec_to_ns(sec, nanosec) == stamp
    assert stamp_fields(stamp) == {'sec': sec, 'nanosec': nanosec}
    bag_point = point_message(stamp, 'cam', 1.0, 2.0, 0.0)
    bag_image = image_message(stamp, 'cam', np.zeros((2, 3), np.uint8), 'mono8')
    ros_stamp = messages.ns_to_stamp(stamp)
    for stamp_msg in (bag_point.header.stamp, bag_image.header.stamp):
        assert (stamp_msg.sec, stamp_msg.nanosec) == (ros_stamp.sec, ros_stamp.nanosec)
        assert stamp_ns(stamp_msg) == messages.stamp_to_ns(ros_stamp) == stamp
    assert isinstance(messages.stamp_to_ns(ros_stamp), int)


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_message_counts_come_from_the_index(tmp_path, storage):
    write_observations(tmp_path / 'bag', _observations(), storage=storage)
    assert bag_message_counts(tmp_path / 'bag') == {
        '/cam_a/ball/image_point': ('geometry_msgs/msg/PointStamped', 5),
        '/cam_b/ball/image_point': ('geometry_msgs/msg/PointStamped', 4)}
    assert bag_message_counts(tmp_path / 'bag', ['/cam_b/ball/image_point']) == {
        '/cam_b/ball/image_point': ('geometry_msgs/msg/PointStamped', 4)}
    with pytest.raises(BagError, match='no topic /cam_c/ball/image_point'):
        bag_message_counts(tmp_path / 'bag', ['/cam_c/ball/image_point'])


def test_refuses_to_overwrite(tmp_path):
    write_observations(tmp_path / 'bag', _observations())
    with pytest.raises(BagError, match='exists'):
        write_observations(tmp_path / 'bag', _observations())


@pytest.mark.parametrize('session', SESSIONS)
def test_real_data_bags(session):
    """The converted bags hold three cameras at ~168 fps with real, integer stamps."""
    observations = read_observations(LFG / session)
    assert bag_cameras(LFG / session) == sorted(CAMERAS)
    for camera in CAMERAS:
        stamps = sorted(o.stamp_ns for o in observations if o.camera == camera)
        assert len(stamps) > 100
        assert len(set(stamps)) == len(stamps)  # ambiguous duplicates were dropped
        periods = [b - a for a, b in zip(stamps, stamps[1:])]
        median = sorted(periods)[len(periods) // 2]
        # The frame period (5.95 ms) or, for camera_3 with every other frame missing, twice it.
        assert 5_800_000 < median < 6_100_000 or 11_600_000 < median < 12_200_000, median
    for o in observations:
        assert 0 <= o.u < 1280 and 0 <= o.v < 1024
    for name in CAMERAS.values():
        assert (LFG / f'{name}_calibration.yaml').is_file()
    assert 'MIT License' in (LFG / 'LICENSE').read_text()


def test_test_data_is_small():
    total = sum(f.stat().st_size for f in LFG.rglob('*') if f.is_file())
    assert total < 3_000_000, total


# -- bad bags ---------------------------------------------------------------------------------


def _good_bag(tmp_path):
    observations = read_observations(LFG / 'n3_p1_v14')
    path = tmp_path / 'good'
    write_observations(path, observations)
    return path


def _mcap(path):
    return next(Path(path).glob('*.mcap'))


def _truncated(tmp_path):
    path = _good_bag(tmp_path)
    mcap = _mcap(path)
    os.truncate(mcap, mcap.stat().st_size // 2)
    return path


def _corrupt(tmp_path):
    # Records after the mcap magic are overwritten.  (rosbags does not check chunk CRCs, so
    # damage inside a chunk's payload can go unnoticed: see the README.)
    path = _good_bag(tmp_path)
    mcap = _mcap(path)
    data = bytearray(mcap.read_bytes())
    data[8:408] = bytes((37 * k + 11) % 256 for k in range(400))
    mcap.write_bytes(bytes(data))
    return path


def _corrupt_metadata(tmp_path):
    path = _good_bag(tmp_path)
    (path / 'metadata.yaml').write_text('rosbag2_bagfile_information: [broken')
    return path


def _not_a_bag(tmp_path):
    path = tmp_path / 'garbage.mcap'
    path.write_bytes(b'this is not an mcap file' * 10)
    return path


def _empty(tmp_path):
    store = typestore()
    path = tmp_path / 'empty'
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as bag:
        for camera in CAMERAS:
            bag.add_connection(image_point_topic(camera), 'geometry_msgs/msg/PointStamped',
                               typestore=store)
    return path


def _no_topics(tmp_path):
    path = tmp_path / 'nothing'
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP):
        pass
    return path


def _missing_topic(tmp_path):
    observations = [o for o in read_observations(LFG / 'n3_p1_v14') if o.camera != 'camera_3']
    path = tmp_path / 'two'
    write_observations(path, observations)
    return path


def _wrong_type(tmp_path):
    store = typestore()
    path = tmp_path / 'wrong'
    string = store.types['std_msgs/msg/String']
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as bag:
        for camera in ('camera_1', 'camera_2'):
            bag.add_connection(image_point_topic(camera), 'geometry_msgs/msg/PointStamped',
                               typestore=store)
        # camera_3 publishes strings.
        connection = bag.add_connection('/camera_3/ball/image_point', 'std_msgs/msg/String',
                                        typestore=store)
        bag.write(connection, EPOCH, store.serialize_cdr(string(data='ball'),
                                                         'std_msgs/msg/String'))
    return path


BAD_BAGS = {
    'missing': (lambda tmp: tmp / 'does_not_exist', 'no such bag'),
    'not_a_bag': (_not_a_bag, 'not a readable ROS 2 bag'),
    'truncated': (_truncated, 'not a readable ROS 2 bag|corrupt or truncated'),
    'corrupt': (_corrupt, 'not a readable ROS 2 bag'),
    'corrupt_metadata': (_corrupt_metadata, 'not a readable ROS 2 bag'),
    'empty': (_empty, 'no messages'),
    'no_topics': (_no_topics, 'no topic'),
    'missing_topic': (_missing_topic, 'no topic /camera_3/ball/image_point'),
    'wrong_type': (_wrong_type, 'has type std_msgs/msg/String, expected'),
}


@pytest.mark.parametrize('kind', sorted(BAD_BAGS))
def test_bad_bag_raises_bag_error(tmp_path, kind):
    make, match = BAD_BAGS[kind]
    path = make(tmp_path)
    with pytest.raises(BagError, match=match):
        read_observations(path, list(CAMERAS))


@pytest.mark.parametrize('kind', sorted(BAD_BAGS))
def test_bad_bag_cli_exits_cleanly(tmp_path, kind, capsys):
    make, match = BAD_BAGS[kind]
    path = make(tmp_path)
    args = ['holdout', str(path)]
    for camera, serial in CAMERAS.items():
        args += ['--camera', f'{camera}={LFG / f"{serial}_calibration.yaml"}']
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.startswith('pseudo_stereo holdout: error: ')
    assert 'Traceback' not in err
    assert len(err.strip().splitlines()) == 1
