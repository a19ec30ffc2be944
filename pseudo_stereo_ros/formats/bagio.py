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
ROS 2 bags without ROS: observations in, estimates out, through ``rosbags``.

A bag (a rosbag2 directory, or a bare ``.mcap`` / ``.db3`` file) carries one
``geometry_msgs/msg/PointStamped`` topic ``/<camera>/ball/image_point`` per
camera (``point.x`` = u, ``point.y`` = v in raw pixels, header stamp = the
shutter stamp) and, written by :func:`write_estimates`, ``/ball/position``
(metres, in ``frame_id``).  Stamps are integer nanoseconds
(``sec * 10**9 + nanosec``) everywhere.  Camera images
(``sensor_msgs/msg/Image`` on ``/<camera>/image_raw``) are read as arrays by
:func:`read_images` through the core's
:func:`~pseudo_stereo_ros.detection.image_array`, the function the detector
node uses too; :func:`write_messages` writes any mix of points and images.

Everything that can go wrong with a bag a user hands in (no such file, not a
bag, truncated or corrupt, a missing topic, a topic of another type, no
messages) raises :class:`BagError` with a message naming the bag and the
reason.  This module imports rosbags only, never rclpy.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
import os
from pathlib import Path
import re
import sqlite3
import struct
from typing import cast, Protocol, TYPE_CHECKING

import numpy as np
from rosbags.rosbag2 import Reader, ReaderError, StoragePlugin, Writer, WriterError
from rosbags.typesys import get_typestore, Stores

from ..detection import EncodingError, image_array
from ..errors import BagError

try:
    from rosbags.rosbag2 import CompressionFormat, CompressionMode
except ImportError:  # rosbags < 0.11 nests them in Writer (the installed stubs are newer)
    CompressionFormat, CompressionMode = (  # type: ignore[misc]
        Writer.CompressionFormat, Writer.CompressionMode)  # type: ignore[attr-defined]
from ..records import Estimate, Observation
from ..stamps import BAG_STAMP_MAX_NS, stamp_fields, stamp_ns

if TYPE_CHECKING:
    from rosbags.interfaces import Connection
    from rosbags.typesys.store import Msg, Typestore

__all__ = [
    'BagError',
    'GROUND_TRUTH_TOPIC',
    'IMAGE_POINT_TYPE',
    'IMAGE_TYPE',
    'POSITION_TOPIC',
    'bag_cameras',
    'bag_message_counts',
    'bag_topics',
    'check_bag_stamps',
    'image_message',
    'image_point_topic',
    'image_topic',
    'iter_raw',
    'point_message',
    'read_images',
    'read_observations',
    'read_positions',
    'write_estimates',
    'write_messages',
    'write_observations',
    'write_points',
]

PathLike = str | os.PathLike[str]

#: Message type of image points and positions.
IMAGE_POINT_TYPE = 'geometry_msgs/msg/PointStamped'
#: Topic of the fused 3D positions.
POSITION_TOPIC = '/ball/position'
#: Message type of camera images.
IMAGE_TYPE = 'sensor_msgs/msg/Image'
#: Topic of the true ball position of a simulation (PointStamped, metres).
GROUND_TRUTH_TOPIC = '/ball/ground_truth'

_IMAGE_POINT_RE = re.compile(r'^/([A-Za-z_][A-Za-z0-9_]*)/ball/image_point$')
_STORAGE = {'mcap': StoragePlugin.MCAP, 'sqlite3': StoragePlugin.SQLITE3}
# A damaged bag makes rosbags and the mcap / sqlite / CDR layers under it raise one of these;
# reading is the only thing inside these handlers, so each means "this bag is damaged".  Other
# exceptions (a bug here) keep their traceback.
_READ_ERRORS = (ReaderError, OSError, EOFError, struct.error, sqlite3.DatabaseError, OverflowError,
                KeyError, IndexError, TypeError, ValueError, UnicodeDecodeError)

_typestore: Typestore | None = None


class _Time(Protocol):
    sec: int
    nanosec: int


class _Header(Protocol):
    stamp: _Time


class _Point(Protocol):
    x: float
    y: float
    z: float


class _Stamped(Protocol):
    header: _Header


class _PointStamped(_Stamped, Protocol):
    """A deserialized ``geometry_msgs/msg/PointStamped`` (rosbags returns ``object``)."""

    point: _Point


class _Image(_Stamped, Protocol):
    """A deserialized ``sensor_msgs/msg/Image``."""

    height: int
    width: int
    step: int
    encoding: str
    data: np.ndarray


def typestore() -> Typestore:
    """Return the shared ROS 2 Jazzy typestore of rosbags."""
    global _typestore
    if _typestore is None:
        _typestore = get_typestore(Stores.ROS2_JAZZY)
    return _typestore


def image_point_topic(camera: str) -> str:
    """Return the image point topic of a camera: ``/<camera>/ball/image_point``."""
    return f'/{camera}/ball/image_point'


def image_topic(camera: str) -> str:
    """Return the image topic of a camera: ``/<camera>/image_raw``."""
    return f'/{camera}/image_raw'


def _open(path: PathLike) -> Reader:
    path = Path(path)
    if not path.exists():
        raise BagError(f'{path}: no such bag')
    try:
        reader = Reader(path)
        reader.open()
    except _READ_ERRORS as err:
        raise BagError(f'{path}: not a readable ROS 2 bag ({_reason(err)})') from err
    return reader


def _reason(err: BaseException) -> str:
    text = str(err).strip() or type(err).__name__
    return text.splitlines()[0]


def _topics(reader: Reader) -> dict[str, str]:
    """Return topic -> message type (each topic once)."""
    return {connection.topic: connection.msgtype for connection in reader.connections}


def bag_topics(path: PathLike) -> dict[str, str]:
    """
    Return the topics of a bag and their message types.

    :param path: the bag (directory, ``.mcap`` or ``.db3``)
    :return: topic -> type name such as ``'geometry_msgs/msg/PointStamped'``
    """
    reader = _open(path)
    try:
        return _topics(reader)
    finally:
        reader.close()


def bag_cameras(path: PathLike) -> list[str]:
    """
    Return the camera names that have an image point topic in a bag.

    :param path: the bag (directory, ``.mcap`` or ``.db3``)
    :return: the names, sorted
    """
    reader = _open(path)
    try:
        topics = _topics(reader)
    finally:
        reader.close()
    return sorted(m.group(1) for m in map(_IMAGE_POINT_RE.match, topics) if m)


def _connections(reader: Reader, path: PathLike, topics: Sequence[str] | None
                 ) -> list[Connection]:
    """Return the reader's connections of the topics (all when None); each must exist."""
    if topics is None:
        return list(reader.connections)
    available = _topics(reader)
    missing = [topic for topic in topics if topic not in available]
    if missing:
        raise BagError(f'{path}: no topic {", ".join(missing)} (the bag has: '
                       f'{", ".join(sorted(available)) or "no topics"})')
    return [c for c in reader.connections if c.topic in set(topics)]


def bag_message_counts(path: PathLike, topics: Sequence[str] | None = None
                       ) -> dict[str, tuple[str, int]]:
    """
    Return the topics of a bag with their type and message count, from the bag's index.

    No message is read, so this takes the same time for any bag size; damage inside the
    message data shows only when the messages are read (:func:`iter_raw` raises then).

    :param path: the bag (directory, ``.mcap`` or ``.db3``)
    :param topics: the topics (all when None); each must exist
    :return: topic -> ``(msgtype, message_count)``
    """
    reader = _open(path)
    try:
        counts: dict[str, tuple[str, int]] = {}
        for connection in _connections(reader, path, topics):
            _, count = counts.get(connection.topic, (connection.msgtype, 0))
            counts[connection.topic] = (connection.msgtype, count + int(connection.msgcount))
        return counts
    finally:
        reader.close()


def iter_raw(path: PathLike, topics: Sequence[str] | None = None
             ) -> Iterator[tuple[str, str, int, bytes]]:
    """
    Iterate over the raw messages of a bag in log-time order.

    :param path: the bag
    :param topics: the topics to read (all when None); each must exist
    :return: an iterator of ``(topic, msgtype, log_time_ns, cdr_bytes)``
    """
    reader = _open(path)
    try:
        connections = _connections(reader, path, topics)
        try:
            for connection, stamp, data in reader.messages(connections=connections):
                yield connection.topic, connection.msgtype, int(stamp), bytes(data)
        except BagError:
            raise
        except _READ_ERRORS as err:
            raise BagError(f'{path}: corrupt or truncated bag ({_reason(err)})') from err
    finally:
        try:
            reader.close()
        except _READ_ERRORS:
            pass


def _read_messages(path: PathLike, topics: Sequence[str], expected: str = IMAGE_POINT_TYPE
                   ) -> Iterator[tuple[str, object]]:
    """Yield ``(topic, message)`` of the given topics, checking their type."""
    store = typestore()
    checked: set[str] = set()
    for topic, msgtype, _, data in iter_raw(path, topics):
        if topic not in checked:
            if msgtype != expected:
                raise BagError(f'{path}: topic {topic} has type {msgtype}, expected {expected}')
            checked.add(topic)
        try:
            msg = store.deserialize_cdr(data, msgtype)
        except _READ_ERRORS as err:
            raise BagError(f'{path}: a message on {topic} does not decode '
                           f'({_reason(err)})') from err
        yield topic, msg


def _check_types(path: PathLike, topics: Sequence[str], expected: str = IMAGE_POINT_TYPE
                 ) -> None:
    """Raise BagError when a topic is missing or not of the expected type (before reading)."""
    reader = _open(path)
    try:
        available = _topics(reader)
    finally:
        reader.close()
    for topic in topics:
        if topic not in available:
            raise BagError(f'{path}: no topic {topic} (the bag has: '
                           f'{", ".join(sorted(available)) or "no topics"})')
        if available[topic] != expected:
            raise BagError(f'{path}: topic {topic} has type {available[topic]}, '
                           f'expected {expected}')


def _read_points(path: PathLike, topics: Sequence[str]) -> Iterator[tuple[str, _PointStamped]]:
    """Yield ``(topic, message)`` of PointStamped topics, checking their type."""
    for topic, msg in _read_messages(path, topics, IMAGE_POINT_TYPE):
        yield topic, cast(_PointStamped, msg)


def _stamp_ns(msg: _Stamped) -> int:
    return stamp_ns(msg.header.stamp)


def read_observations(path: PathLike, cameras: Sequence[str] | None = None
                      ) -> list[Observation]:
    """
    Read the image points of a bag as observations.

    :param path: the bag (directory, ``.mcap`` or ``.db3``)
    :param cameras: camera names to read (``/<camera>/ball/image_point`` each); all the
        bag has when None
    :return: the observations in log-time order (``fusion.fuse`` sorts by stamp itself)
    """
    if cameras is None:
        cameras = bag_cameras(path)
        if not cameras:
            raise BagError(f'{path}: no /<camera>/ball/image_point topic in the bag')
    cameras = list(cameras)
    by_topic = {image_point_topic(camera): camera for camera in cameras}
    _check_types(path, list(by_topic))
    observations = [Observation(by_topic[topic], _stamp_ns(msg), float(msg.point.x),
                                float(msg.point.y))
                    for topic, msg in _read_points(path, list(by_topic))]
    if not observations:
        raise BagError(f'{path}: no messages on {", ".join(by_topic)}')
    return observations


def read_positions(path: PathLike, topic: str = POSITION_TOPIC
                   ) -> list[tuple[int, float, float, float]]:
    """
    Read a PointStamped topic as positions.

    :param path: the bag
    :param topic: the topic (``/ball/position`` by default)
    :return: ``(stamp_ns, x, y, z)`` tuples in log-time order
    """
    _check_types(path, [topic])
    return [(_stamp_ns(msg), float(msg.point.x), float(msg.point.y), float(msg.point.z))
            for _, msg in _read_points(path, [topic])]


def read_images(path: PathLike, topic: str
                ) -> Iterator[tuple[int, str, np.ndarray | None, str | None]]:
    """
    Read an image topic as arrays, one message at a time (a bag of images can be large).

    :param path: the bag
    :param topic: a ``sensor_msgs/msg/Image`` topic, e.g. ``/camera1/image_raw``
    :return: an iterator of ``(stamp_ns, encoding, pixels, problem)`` in log-time order:
        ``pixels`` as :func:`~pseudo_stereo_ros.detection.image_array` returns them and
        ``problem`` None, or ``pixels`` None and ``problem`` saying why the image is unusable
        (an unsupported encoding, a buffer that does not fit its size): the caller skips it,
        as the detector node drops such an image
    :raises BagError: the topic is missing or not an Image, or the bag is damaged
    """
    _check_types(path, [topic], IMAGE_TYPE)
    for _, raw in _read_messages(path, [topic], IMAGE_TYPE):
        msg = cast(_Image, raw)
        try:
            pixels = image_array(msg.data, msg.height, msg.width, msg.step, msg.encoding)
        except EncodingError as err:
            yield _stamp_ns(msg), str(msg.encoding), None, str(err)
            continue
        yield _stamp_ns(msg), str(msg.encoding), pixels, None


def _header(stamp_ns: int, frame_id: str) -> Msg:
    types = typestore().types
    stamp = types['builtin_interfaces/msg/Time'](**stamp_fields(stamp_ns))
    return types['std_msgs/msg/Header'](stamp=stamp, frame_id=frame_id)


def point_message(stamp_ns: int, frame_id: str, x: float, y: float, z: float) -> Msg:
    """
    Return a rosbags ``geometry_msgs/msg/PointStamped`` for :func:`write_messages`.

    :param stamp_ns: header stamp [ns]
    :param frame_id: header frame
    :param x: point.x
    :param y: point.y
    :param z: point.z
    :return: the message object
    """
    types = typestore().types
    point = types['geometry_msgs/msg/Point'](x=float(x), y=float(y), z=float(z))
    return types[IMAGE_POINT_TYPE](header=_header(stamp_ns, frame_id), point=point)


def image_message(stamp_ns: int, frame_id: str, pixels: np.ndarray, encoding: str = 'bgr8'
                  ) -> Msg:
    """
    Return a rosbags ``sensor_msgs/msg/Image`` (rows unpadded) for :func:`write_messages`.

    :param stamp_ns: header stamp [ns] (the shutter time)
    :param frame_id: the camera's optical frame
    :param pixels: (H, W) or (H, W, C) uint8 in the encoding's channel order
    :param encoding: an encoding of :data:`~pseudo_stereo_ros.detection.ENCODING_CHANNELS`
    :return: the message object
    """
    pixels = np.ascontiguousarray(pixels, dtype=np.uint8)
    height, width = pixels.shape[:2]
    channels = 1 if pixels.ndim == 2 else pixels.shape[2]
    image_array(pixels.reshape(-1), height, width, width * channels, encoding)  # checks
    return typestore().types[IMAGE_TYPE](
        header=_header(stamp_ns, frame_id), height=height, width=width, encoding=encoding,
        is_bigendian=0, step=width * channels, data=pixels.reshape(-1))


def write_messages(path: PathLike, messages: Iterable[tuple[str, str, int, object]], *,
                   storage: str = 'mcap', compress: bool = False) -> int:
    """
    Write messages to a new bag.

    :param path: the bag directory to create (must not exist)
    :param messages: ``(topic, msgtype, log_time_ns, message)`` in log-time order, messages as
        built by :func:`point_message` and :func:`image_message` (any rosbags message object)
    :param storage: ``'mcap'`` or ``'sqlite3'``
    :param compress: zstd-compress the whole storage file (rosbag2 file compression); a bag
        of images with a static background shrinks a hundredfold
    :return: the number of messages written
    """
    if storage not in _STORAGE:
        raise BagError(f'{path}: unknown storage {storage!r} (known: {", ".join(_STORAGE)})')
    path = Path(path)
    if path.exists():
        raise BagError(f'{path}: exists already, not overwriting')
    store = typestore()
    count = 0
    try:
        bag = Writer(path, version=Writer.VERSION_LATEST, storage_plugin=_STORAGE[storage])
        if compress:
            bag.set_compression(CompressionMode.FILE, CompressionFormat.ZSTD)
        with bag:
            connections = {}
            for topic, msgtype, log_time, message in messages:
                if topic not in connections:
                    connections[topic] = bag.add_connection(topic, msgtype, typestore=store)
                bag.write(connections[topic], int(log_time),
                          store.serialize_cdr(message, msgtype))
                count += 1
    except (WriterError, OSError) as err:
        raise BagError(f'{path}: cannot write the bag ({_reason(err)})') from err
    return count


def check_bag_stamps(path: PathLike, stamps: Iterable[int]) -> None:
    """
    Check that stamps fit a bag message (0 to :data:`~pseudo_stereo_ros.stamps.BAG_STAMP_MAX_NS`).

    :param path: the bag to be written (for the message)
    :param stamps: the stamps [ns]
    :raises BagError: naming the first stamp that does not fit
    """
    for stamp in stamps:
        if not 0 <= stamp <= BAG_STAMP_MAX_NS:
            raise BagError(f'{path}: cannot write stamp {stamp} ns: a bag message holds 0 to '
                           f'{BAG_STAMP_MAX_NS} ns (Time.sec is an int32, log times unsigned)')


def write_points(path: PathLike, rows: Iterable[tuple[str, int, str, float, float, float]], *,
                 storage: str = 'mcap') -> int:
    """
    Write PointStamped messages to a new bag, log time = header stamp.

    :param path: the bag directory to create (must not exist)
    :param rows: ``(topic, stamp_ns, frame_id, x, y, z)``, written sorted by stamp
    :param storage: ``'mcap'`` or ``'sqlite3'``
    :return: the number of messages written
    :raises BagError: a stamp a message cannot hold (nothing is written), or a write error
    """
    rows = sorted(rows, key=lambda row: row[1])
    check_bag_stamps(path, (row[1] for row in rows))
    return write_messages(path, ((topic, IMAGE_POINT_TYPE, int(stamp),
                                  point_message(int(stamp), frame_id, x, y, z))
                                 for topic, stamp, frame_id, x, y, z in rows), storage=storage)


def write_observations(path: PathLike, observations: Iterable[Observation], *,
                       storage: str = 'mcap') -> int:
    """
    Write observations as ``/<camera>/ball/image_point`` topics (frame_id = camera name).

    :param path: the bag directory to create (must not exist)
    :param observations: the observations, any order
    :param storage: ``'mcap'`` or ``'sqlite3'``
    :return: the number of messages written
    """
    return write_points(path, ((image_point_topic(o.camera), o.stamp_ns, o.camera, o.u, o.v, 0.0)
                               for o in observations), storage=storage)


def write_estimates(path: PathLike, estimates: Iterable[Estimate], *,
                    topic: str = POSITION_TOPIC, frame_id: str = 'world',
                    storage: str = 'mcap') -> int:
    """
    Write estimates as PointStamped messages on ``/ball/position``.

    :param path: the bag directory to create (must not exist)
    :param estimates: the estimates; each message carries its shutter stamp
    :param topic: the topic name
    :param frame_id: the world frame
    :param storage: ``'mcap'`` or ``'sqlite3'``
    :return: the number of messages written
    """
    return write_points(path, ((topic, e.stamp_ns, frame_id, e.x, e.y, e.z) for e in estimates),
                        storage=storage)
