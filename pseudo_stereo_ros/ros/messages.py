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
The one module converting between ROS messages and the core's types.

Stamps are integer nanoseconds everywhere in the core; here they become
``builtin_interfaces/Time`` (``sec``, ``nanosec``) and back, never through
float seconds (a stamp near 1.7e18 ns loses ~200 ns as a float).

Images: ``sensor_msgs/Image`` <-> numpy ``(H, W)`` (mono8) or ``(H, W, C)``
arrays in the encoding's channel order (rgb8, bgr8: C = 3; rgba8, bgra8:
C = 4).  Rows may be padded (``step > width * C``); the padding is dropped.
"""

import array
import importlib
import struct
from typing import Callable, Iterable, Mapping, Optional, Sequence, Tuple, Union

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Point, PointStamped
import numpy as np
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker

from ..calibration import CameraCalibration
from ..detection import ENCODING_CHANNELS, EncodingError, image_array
from ..errors import StartupError
from ..records import Estimate, GroundTruth, Observation
# The ns <-> (sec, nanosec) arithmetic, shared with bagio.
from ..stamps import ns_to_sec_nanosec, stamp_fields, stamp_ns as stamp_to_ns

__all__ = [
    'ENCODING_CHANNELS',
    'EncodingError',
    'array_to_image',
    'calibration_to_camera_info',
    'decode_point',
    'diagnostic_array',
    'diagnostic_status',
    'estimate_to_point',
    'header',
    'image_point',
    'image_to_array',
    'message_class',
    'ns_to_stamp',
    'observation_to_point',
    'point_encoder',
    'point_to_observation',
    'point_to_xyz',
    'stamp_to_ns',
    'trail_marker',
]

#: Diagnostic level names -> DiagnosticStatus level bytes.
_LEVELS = {
    'ok': DiagnosticStatus.OK,
    'warn': DiagnosticStatus.WARN,
    'error': DiagnosticStatus.ERROR,
    'stale': DiagnosticStatus.STALE,
}


# -- time -----------------------------------------------------------------------------------------

def ns_to_stamp(stamp_ns: int) -> Time:
    """
    Return integer nanoseconds as a ``builtin_interfaces/Time``.

    :param stamp_ns: a non-negative stamp [ns]
    :return: the message (``sec``, ``nanosec`` with ``0 <= nanosec < 1e9``)
    """
    return Time(**stamp_fields(stamp_ns))


def header(stamp_ns: int, frame_id: str = '') -> Header:
    """Return a ``std_msgs/Header`` with the stamp [ns] and frame."""
    return Header(stamp=ns_to_stamp(stamp_ns), frame_id=frame_id)


# -- points ---------------------------------------------------------------------------------------

def point_to_observation(msg: PointStamped, camera: str) -> Observation:
    """
    Return the detection in a ``ball/image_point`` message as an observation.

    :param msg: ``point.x = u``, ``point.y = v`` in raw pixels, stamp = shutter time
    :param camera: the name of the camera that published it
    :return: the observation (``u``, ``v`` may be non-finite; the fuser drops them)
    """
    return Observation(camera, stamp_to_ns(msg.header.stamp), float(msg.point.x),
                       float(msg.point.y))


def observation_to_point(observation: Observation, frame_id: str = '') -> PointStamped:
    """Return an observation as a ``ball/image_point`` message (``z = 0``)."""
    return PointStamped(header=header(observation.stamp_ns, frame_id),
                        point=Point(x=float(observation.u), y=float(observation.v), z=0.0))


def image_point(image_header: Header, u: float, v: float) -> PointStamped:
    """
    Return a detection as a ``ball/image_point`` message.

    :param image_header: the image's header (shutter stamp and camera frame), kept unchanged
    :param u: column [raw px]
    :param v: row [raw px]
    :return: the message (``z = 0``)
    """
    return PointStamped(header=image_header, point=Point(x=float(u), y=float(v), z=0.0))


def estimate_to_point(estimate: Union[Estimate, GroundTruth], frame_id: str) -> PointStamped:
    """
    Return an estimate as a ``/ball/position`` message.

    :param estimate: the estimate; its stamp is the shutter stamp of the event
    :param frame_id: the world frame
    :return: the message, position in metres
    """
    return PointStamped(header=header(estimate.stamp_ns, frame_id),
                        point=Point(x=float(estimate.x), y=float(estimate.y),
                                    z=float(estimate.z)))


def point_to_xyz(msg: PointStamped) -> Tuple[int, float, float, float]:
    """Return ``(stamp_ns, x, y, z)`` of a ``PointStamped``."""
    return (stamp_to_ns(msg.header.stamp), float(msg.point.x), float(msg.point.y),
            float(msg.point.z))


def point_encoder(frame_id: str) -> Callable[[int, float, float, float], bytes]:
    """
    Return ``encode(stamp_ns, x, y, z)``: a ``PointStamped`` of ``frame_id``, serialized.

    For ``publish(bytes)``, the fastest path of a point out of a process: rclpy's
    conversion of a message object costs 50 to 100 us, this 2 us.  The bytes are
    what rclpy serializes (XCDR1, little endian: stamp, frame_id, then three float64
    8-byte aligned), the frame part built once.

    :param frame_id: the frame of every point
    :return: the encoder; its stamp is in ns, ``x``, ``y``, ``z`` are the point
    """
    name = frame_id.encode('utf-8') + b'\0'
    # Offsets count from after the 4-byte encapsulation header: 8 bytes of stamp, then the
    # string's length and bytes; the doubles start at the next multiple of 8.
    middle = struct.pack('<I', len(name)) + name
    middle += bytes(-(8 + len(middle)) % 8)
    stamp = struct.Struct('<4siI')
    point = struct.Struct('<3d')

    def encode(stamp_ns: int, x: float, y: float, z: float) -> bytes:
        sec, nanosec = ns_to_sec_nanosec(stamp_ns)
        return stamp.pack(b'\0\1\0\0', sec, nanosec) + middle + point.pack(x, y, z)

    return encode


_LITTLE_ENDIAN_CDR = b'\0\1'
_STAMP = struct.Struct('<iII')  # sec, nanosec, then the frame_id's length (NUL included)
_XYZ = struct.Struct('<3d')


def decode_point(data: bytes) -> Tuple[int, float, float, float]:
    """
    Return ``(stamp_ns, x, y, z)`` of a serialized ``PointStamped``.

    For ``create_subscription(..., raw=True)``, the fastest path of a point into a
    process: 1 to 2 us against rclpy's 20 to 60 us for taking it as a message object
    (its conversion runs before the callback).  Little-endian CDR, what every ROS 2
    middleware on x86 and ARM writes, is read here; anything else goes through
    rclpy's deserialization.

    :param data: the serialized message
    :return: the header stamp [ns] and the point
    :raises EncodingError: the bytes are not a serialized ``PointStamped``
    """
    if data[:2] == _LITTLE_ENDIAN_CDR and len(data) >= 16:
        sec, nanosec, length = _STAMP.unpack_from(data, 4)
        # The doubles start at the first multiple of 8 (counted after the 4-byte
        # encapsulation header) after the string; a serializer may pad the end to 4 bytes.
        start = 16 + length
        start += -(start - 4) % 8
        if 0 < length and start + 24 <= len(data) < start + 28 and data[15 + length] == 0:
            return (sec * 1_000_000_000 + nanosec, *_XYZ.unpack_from(data, start))
    try:
        return point_to_xyz(deserialize_message(bytes(data), PointStamped))
    except RuntimeError as err:  # rclpy's RMWError: not a PointStamped
        raise EncodingError(f'not a serialized PointStamped ({len(data)} bytes): '
                            f'{type(err).__name__}: {err}') from err


# -- images ---------------------------------------------------------------------------------------

def image_to_array(msg: Image) -> np.ndarray:
    """
    Return the pixels of an image message as a numpy array (a view where possible).

    :param msg: an 8-bit image in one of :data:`ENCODING_CHANNELS`
    :return: (H, W) uint8 for mono8, (H, W, C) uint8 in the encoding's channel order
    :raises EncodingError: unsupported encoding, or ``step``/``data`` inconsistent with the size
    """
    return image_array(msg.data, msg.height, msg.width, msg.step, msg.encoding)


def array_to_image(pixels: np.ndarray, encoding: str, stamp_ns: int,
                   frame_id: str = '') -> Image:
    """
    Return a numpy image as a ``sensor_msgs/Image`` (rows unpadded).

    :param pixels: (H, W) or (H, W, C) uint8 in the encoding's channel order
    :param encoding: one of :data:`ENCODING_CHANNELS`
    :param stamp_ns: the shutter stamp [ns]
    :param frame_id: the camera's optical frame
    :return: the message
    :raises EncodingError: unknown encoding or a shape that does not match it
    """
    channels = ENCODING_CHANNELS.get(encoding)
    if channels is None:
        raise EncodingError(f'unsupported image encoding {encoding!r}')
    pixels = np.ascontiguousarray(pixels, dtype=np.uint8)
    if pixels.ndim == 2:
        pixels = pixels[:, :, None]
    if pixels.ndim != 3 or pixels.shape[2] != channels:
        raise EncodingError(f'array of shape {pixels.shape} does not fit encoding {encoding!r}')
    height, width = pixels.shape[:2]
    msg = Image(header=header(stamp_ns, frame_id), height=height, width=width,
                encoding=encoding, is_bigendian=0, step=width * channels)
    # array.array from bytes is a memcpy; a plain sequence would be checked element by element.
    msg.data = array.array('B', pixels.tobytes())
    return msg


def calibration_to_camera_info(calibration: CameraCalibration, stamp_ns: int,
                               frame_id: str = '') -> CameraInfo:
    """
    Return a calibration's intrinsics as a ``sensor_msgs/CameraInfo``.

    :param calibration: the camera's calibration (the pose is not part of CameraInfo)
    :param stamp_ns: the shutter stamp [ns]
    :param frame_id: the camera's optical frame
    :return: the message (``r`` identity, ``p = [K | 0]``)
    """
    k = np.asarray(calibration.camera_matrix, dtype=float)
    projection = np.zeros((3, 4))
    projection[:, :3] = k
    model = calibration.distortion_model
    return CameraInfo(header=header(stamp_ns, frame_id), height=calibration.image_height,
                      width=calibration.image_width,
                      distortion_model='plumb_bob' if model == 'radtan' else model,
                      d=[float(x) for x in calibration.dist_coeffs],
                      k=[float(x) for x in k.ravel()],
                      r=[float(x) for x in np.eye(3).ravel()],
                      p=[float(x) for x in projection.ravel()])


# -- visualization and diagnostics ----------------------------------------------------------------

def trail_marker(points: Iterable[Sequence[float]], stamp_ns: int, frame_id: str, *,
                 namespace: str = 'ball_trail', marker_id: int = 0, width_m: float = 0.01,
                 rgba: Sequence[float] = (1.0, 0.5, 0.0, 1.0)) -> Marker:
    """
    Return an RViz LINE_STRIP marker through the given points.

    :param points: (N, 3) world points [m], oldest first
    :param stamp_ns: the stamp of the newest point [ns]
    :param frame_id: the world frame
    :param namespace: the marker namespace
    :param marker_id: the marker id (the same id replaces the previous trail)
    :param width_m: line width [m]
    :param rgba: colour, components in [0, 1]
    :return: the marker
    """
    marker = Marker(header=header(stamp_ns, frame_id), ns=namespace, id=int(marker_id),
                    type=Marker.LINE_STRIP, action=Marker.ADD)
    marker.pose.orientation.w = 1.0
    marker.scale.x = float(width_m)
    marker.color = ColorRGBA(r=float(rgba[0]), g=float(rgba[1]), b=float(rgba[2]),
                             a=float(rgba[3]))
    marker.points = [Point(x=float(p[0]), y=float(p[1]), z=float(p[2])) for p in points]
    return marker


def diagnostic_status(name: str, level: str, message: str,
                      values: Optional[Mapping[str, object]] = None, *,
                      hardware_id: str = '') -> DiagnosticStatus:
    """
    Return one ``diagnostic_msgs/DiagnosticStatus``.

    :param name: the status name, e.g. ``'fuser: camera1'``
    :param level: ``'ok'``, ``'warn'``, ``'error'`` or ``'stale'``
    :param message: a one-line summary
    :param values: key -> value (written with ``str``; floats with 6 significant digits)
    :param hardware_id: optional hardware id
    :return: the status
    """
    items = []
    for key, value in (values or {}).items():
        text = f'{value:.6g}' if isinstance(value, float) else str(value)
        items.append(KeyValue(key=str(key), value=text))
    return DiagnosticStatus(level=_LEVELS[level], name=name, message=message,
                            hardware_id=hardware_id, values=items)


def diagnostic_array(stamp_ns: int, statuses: Sequence[DiagnosticStatus]) -> DiagnosticArray:
    """Return a ``diagnostic_msgs/DiagnosticArray`` of the statuses, stamped [ns]."""
    return DiagnosticArray(header=header(stamp_ns), status=list(statuses))


# -- message types --------------------------------------------------------------------------------

def message_class(msgtype: str):
    """
    Return the rclpy message class of a type name such as ``geometry_msgs/msg/PointStamped``.

    :param msgtype: ``package/msg/Name``
    :return: the class (for ``create_subscription``, ``deserialize_message``)
    :raises StartupError: the type's Python package is not installed
    """
    try:
        from rosidl_runtime_py.utilities import get_message
    except ImportError:
        get_message = None
    try:
        if get_message is not None:
            return get_message(msgtype)
        package, kind, name = msgtype.split('/')
        return getattr(importlib.import_module(f'{package}.{kind}'), name)
    except (ValueError, ImportError, AttributeError) as err:
        raise StartupError(f'message type {msgtype!r} is not available in this environment '
                           f'({err})') from err
