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
The crash-safe bag writer: what is on disk is always a complete bag, read by rosbags.

A kill is simulated by copying the bag directory at that moment (the files
are what a killed process leaves); the copy must read back exactly the
messages written up to the last checkpoint.  The reference is the list of
messages written, and rosbags' own Writer given the same messages.
"""

import os
import shutil

import numpy as np
from pseudo_stereo_ros.errors import BagError
from pseudo_stereo_ros.formats.bagio import (bag_message_counts, image_message, IMAGE_TYPE,
                                             iter_raw, point_message, typestore,
                                             write_messages)
from pseudo_stereo_ros.formats.checkpoint_bag import CheckpointBagWriter
import pytest

POINT = 'geometry_msgs/msg/PointStamped'
STAMP0 = 1_721_679_791_000_000_000


def _messages(count, seed):
    """Return (topic, msgtype, log time, message) of two point topics, random times and order."""
    rng = np.random.default_rng(seed)
    times = STAMP0 + np.cumsum(rng.integers(1, 2_000_000, count))
    topics = rng.choice(['/a/ball/image_point', '/b/ball/image_point'], count)
    return [(str(topic), POINT, int(t), point_message(int(t), str(topic)[1], k, -k, 0.5))
            for k, (topic, t) in enumerate(zip(topics, times))]


def _read(bag):
    return [(topic, msgtype, stamp, data) for topic, msgtype, stamp, data in iter_raw(bag)]


def _serialized(messages):
    return [(topic, msgtype, stamp, bytes(typestore().serialize_cdr(message, msgtype)))
            for topic, msgtype, stamp, message in messages]


def _copy(bag, tmp_path, name):
    """Return a copy of the bag directory as it is now on disk (what a kill -9 leaves)."""
    target = tmp_path / name / bag.name
    shutil.copytree(bag, target)
    return target


@pytest.mark.parametrize('seed', range(4))
def test_a_kill_at_any_moment_leaves_the_last_checkpoint(tmp_path, seed):
    messages = _messages(400, seed)
    expected = _serialized(messages)
    rng = np.random.default_rng(100 + seed)
    checkpoints = set(rng.choice(len(messages), 6, replace=False).tolist())
    bag = tmp_path / 'live'
    writer = CheckpointBagWriter(bag)
    writer.create()
    assert bag_message_counts(_copy(bag, tmp_path, 'empty')) == {}  # readable from the start
    connections = {}
    at_checkpoint = 0
    for index, (topic, msgtype, stamp, data) in enumerate(expected):
        if topic not in connections:
            connections[topic] = writer.add_connection(topic, msgtype)
        writer.write(connections[topic], stamp, data)
        if index in checkpoints:
            writer.checkpoint()
            at_checkpoint = index + 1
            copy = _copy(bag, tmp_path, f'at{index}')
            assert _read(copy) == sorted(expected[:at_checkpoint], key=lambda m: m[2])
        elif index % 97 == 0:
            # Killed between checkpoints: the bag is the last checkpoint's.
            copy = _copy(bag, tmp_path, f'between{index}')
            assert _read(copy) == sorted(expected[:at_checkpoint], key=lambda m: m[2])
            # The bare mcap (no metadata.yaml) reads the same.
            assert ([m[2] for m in iter_raw(copy / f'{copy.name}.mcap')]
                    == sorted(m[2] for m in expected[:at_checkpoint]))
    writer.close()
    assert writer.message_count == len(expected)
    # Closed: the same messages as rosbags' own Writer writes from them, and the same counts.
    reference = tmp_path / 'reference'
    write_messages(reference, messages)
    assert _read(bag) == _read(reference)
    assert bag_message_counts(bag) == bag_message_counts(reference)


def test_large_messages_start_new_chunks_and_each_is_safe(tmp_path):
    """Over 1 MiB a chunk is closed (and the bag made complete) without waiting."""
    pixels = np.zeros((1, 600_000), np.uint8)
    bag = tmp_path / 'images'
    writer = CheckpointBagWriter(bag)
    writer.create()
    connection = writer.add_connection('/cam/image_raw', IMAGE_TYPE)
    for k in range(3):
        pixels[0, 0] = k
        message = image_message(STAMP0 + k, 'cam', pixels, 'mono8')
        writer.write(connection, STAMP0 + k, bytes(typestore().serialize_cdr(message,
                                                                             IMAGE_TYPE)))
    # No explicit checkpoint: the first two images filled a chunk, which is on disk.
    copy = _copy(bag, tmp_path, 'killed')
    assert [m[2] for m in _read(copy)] == [STAMP0, STAMP0 + 1]
    writer.close()
    assert [m[2] for m in _read(bag)] == [STAMP0, STAMP0 + 1, STAMP0 + 2]
    assert writer.checkpoints >= 3  # create, the full chunk, close


def test_refuses_an_existing_bag_and_an_unknown_type(tmp_path):
    (tmp_path / 'there').mkdir()
    with pytest.raises(BagError, match='exists already'):
        CheckpointBagWriter(tmp_path / 'there').create()
    writer = CheckpointBagWriter(tmp_path / 'new')
    writer.create()
    with pytest.raises(BagError, match='not a ROS 2 Jazzy type'):
        writer.add_connection('/x', 'no_such_msgs/msg/Thing')
    writer.close()
    writer.close()  # idempotent
    assert os.path.exists(tmp_path / 'new' / 'metadata.yaml')
