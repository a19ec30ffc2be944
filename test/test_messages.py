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

"""Tests of pseudo_stereo_ros.ros.messages: the one conversion between messages and core types."""

import math

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PointStamped
from hypothesis import given, strategies as st
import numpy as np
from pseudo_stereo_ros.records import Estimate, GroundTruth, Observation
from pseudo_stereo_ros.ros.messages import (
    array_to_image, calibration_to_camera_info, decode_point, diagnostic_array,
    diagnostic_status, ENCODING_CHANNELS, EncodingError, estimate_to_point,
    image_point, image_to_array, ns_to_stamp, observation_to_point, point_encoder,
    point_to_observation, point_to_xyz, stamp_to_ns, trail_marker)
from pseudo_stereo_ros.sim.scenarios import DEFAULT_EPOCH_NS, default_rig
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import Image
from visualization_msgs.msg import Marker


@pytest.mark.parametrize('stamp_ns', [0, 1, 999_999_999, 1_000_000_000, DEFAULT_EPOCH_NS + 1,
                                      DEFAULT_EPOCH_NS + 16_666_667, 2 ** 62 + 123])
def test_stamp_round_trip_is_exact(stamp_ns):
    stamp = ns_to_stamp(stamp_ns)
    assert 0 <= stamp.nanosec < 1_000_000_000
    assert stamp_to_ns(stamp) == stamp_ns
    assert isinstance(stamp_to_ns(stamp), int)


def test_stamp_near_epoch_keeps_nanoseconds_that_float_seconds_lose():
    stamp_ns = DEFAULT_EPOCH_NS + 123  # float seconds near 1.7e9 s resolve ~240 ns
    assert round((stamp_ns / 1e9) * 1e9) != stamp_ns
    assert stamp_to_ns(Time(sec=stamp_ns // 10 ** 9, nanosec=stamp_ns % 10 ** 9)) == stamp_ns


def test_point_observation_round_trip():
    observation = Observation('camera2', DEFAULT_EPOCH_NS + 16_666_667, 321.125, 12.5)
    msg = observation_to_point(observation, 'camera2_optical_frame')
    assert msg.header.frame_id == 'camera2_optical_frame'
    assert msg.point.z == 0.0
    assert point_to_observation(msg, 'camera2') == observation


def test_image_point_keeps_the_image_header():
    image = array_to_image(np.zeros((4, 5, 3), np.uint8), 'bgr8', DEFAULT_EPOCH_NS + 7, 'cam')
    msg = image_point(image.header, 1.25, 2.5)
    assert msg.header == image.header
    assert (msg.point.x, msg.point.y, msg.point.z) == (1.25, 2.5, 0.0)


@given(frame_id=st.text(max_size=20).filter(lambda text: '\0' not in text),
       stamp_ns=st.integers(0, 2 ** 31 * 10 ** 9 - 1),
       xyz=st.tuples(*[st.floats(allow_nan=False, width=64)] * 3))
def test_encoded_point_is_what_rclpy_serializes(frame_id, stamp_ns, xyz):
    encoded = point_encoder(frame_id)(stamp_ns, *xyz)
    expected = serialize_message(estimate_to_point(GroundTruth(stamp_ns, *xyz), frame_id))
    # Byte for byte but the alignment padding before the doubles (rclpy leaves it unset).
    string_end = 4 + 8 + 4 + len(frame_id.encode()) + 1
    assert len(encoded) == len(expected)
    assert encoded[:string_end] == expected[:string_end]
    assert encoded[-24:] == expected[-24:]
    msg = deserialize_message(encoded, PointStamped)
    assert msg.header.frame_id == frame_id
    assert point_to_xyz(msg) == (stamp_ns, *xyz)


@given(frame_id=st.text(max_size=20).filter(lambda text: '\0' not in text),
       stamp_ns=st.integers(0, 2 ** 31 * 10 ** 9 - 1),
       xyz=st.tuples(*[st.floats(allow_nan=False, width=64)] * 3))
def test_decoded_point_is_what_rclpy_deserializes(frame_id, stamp_ns, xyz):
    msg = estimate_to_point(GroundTruth(stamp_ns, *xyz), frame_id)
    data = serialize_message(msg)
    assert decode_point(data) == point_to_xyz(deserialize_message(data, PointStamped))
    assert decode_point(data) == (stamp_ns, *xyz)
    assert decode_point(point_encoder(frame_id)(stamp_ns, *xyz)) == (stamp_ns, *xyz)
    # Any shorter prefix is not a PointStamped: an error naming it, never a wrong point.
    for end in range(len(data)):
        with pytest.raises(EncodingError, match='not a serialized PointStamped'):
            decode_point(data[:end])


def test_decoded_point_keeps_non_finite_values_for_the_fuser_to_drop():
    data = serialize_message(estimate_to_point(GroundTruth(5, math.nan, math.inf, -0.0), 'c'))
    stamp_ns, x, y, z = decode_point(data)
    assert stamp_ns == 5 and math.isnan(x) and y == math.inf and math.copysign(1.0, z) < 0


def test_estimate_to_point():
    estimate = Estimate(DEFAULT_EPOCH_NS + 5, 'camera1', 1.0, -2.0, 0.5, 'pseudo')
    msg = estimate_to_point(estimate, 'world')
    assert msg.header.frame_id == 'world'
    assert point_to_xyz(msg) == (DEFAULT_EPOCH_NS + 5, 1.0, -2.0, 0.5)


@pytest.mark.parametrize('encoding', sorted(ENCODING_CHANNELS))
def test_image_round_trip(encoding):
    rng = np.random.default_rng(1)
    channels = ENCODING_CHANNELS[encoding]
    shape = (7, 9) if channels == 1 else (7, 9, channels)
    pixels = rng.integers(0, 256, shape, dtype=np.uint8)
    msg = array_to_image(pixels, encoding, DEFAULT_EPOCH_NS, 'cam')
    assert (msg.height, msg.width, msg.step) == (7, 9, 9 * channels)
    assert stamp_to_ns(msg.header.stamp) == DEFAULT_EPOCH_NS
    np.testing.assert_array_equal(image_to_array(msg), pixels)


@pytest.mark.parametrize('encoding', ['mono8', 'bgr8', 'rgba8'])
def test_image_with_padded_rows(encoding):
    channels = ENCODING_CHANNELS[encoding]
    height, width, pad = 5, 6, 7
    step = width * channels + pad
    rng = np.random.default_rng(2)
    raw = rng.integers(0, 256, (height, step), dtype=np.uint8)
    msg = Image(height=height, width=width, encoding=encoding, step=step)
    msg.data = raw.tobytes()
    pixels = image_to_array(msg)
    expected = raw[:, :width * channels]
    if channels > 1:
        expected = expected.reshape(height, width, channels)
    np.testing.assert_array_equal(pixels, expected)


@pytest.mark.parametrize('encoding', ['16UC1', 'yuv422', 'bayer_rggb8', ''])
def test_unsupported_encoding_is_named(encoding):
    msg = Image(height=2, width=2, encoding=encoding, step=4)
    msg.data = bytes(8)
    with pytest.raises(EncodingError, match='unsupported image encoding'):
        image_to_array(msg)


def test_inconsistent_image_sizes_raise():
    msg = Image(height=4, width=4, encoding='bgr8', step=12)
    msg.data = bytes(12 * 3)
    with pytest.raises(EncodingError, match='data has 36 bytes'):
        image_to_array(msg)
    msg.step = 8
    with pytest.raises(EncodingError, match='step 8'):
        image_to_array(msg)
    with pytest.raises(EncodingError, match='does not fit'):
        array_to_image(np.zeros((2, 2, 3), np.uint8), 'mono8', 0)


def test_camera_info_carries_the_intrinsics():
    camera = default_rig()[0]
    info = calibration_to_camera_info(camera.calibration, DEFAULT_EPOCH_NS, 'cam')
    np.testing.assert_array_equal(np.reshape(info.k, (3, 3)), camera.K)
    np.testing.assert_array_equal(info.d, camera.D)
    assert (info.width, info.height) == camera.image_size
    assert stamp_to_ns(info.header.stamp) == DEFAULT_EPOCH_NS


def test_marker_and_diagnostics():
    points = [(0.0, 1.0, 2.0), (0.5, 1.5, 2.5)]
    marker = trail_marker(points, DEFAULT_EPOCH_NS, 'world')
    assert marker.type == Marker.LINE_STRIP
    assert [(p.x, p.y, p.z) for p in marker.points] == points
    assert marker.header.frame_id == 'world'
    status = diagnostic_status('fuser', 'warn', 'stale', {'rate [Hz]': 59.98765432, 'drops': 3})
    assert status.level == DiagnosticStatus.WARN
    assert {kv.key: kv.value for kv in status.values} == {'rate [Hz]': '59.9877', 'drops': '3'}
    array = diagnostic_array(DEFAULT_EPOCH_NS, [status])
    assert array.status[0].name == 'fuser'
    assert stamp_to_ns(array.header.stamp) == DEFAULT_EPOCH_NS
