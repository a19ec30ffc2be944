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
(``sec * 10**9 + nanosec``) everywhere.

Everything that can go wrong with a bag a user hands in (no such file, not a
bag, truncated or corrupt, a missing topic, a topic of another type, no
messages) raises :class:`BagError` with a message naming the bag and the
reason.  This module imports rosbags only, never rclpy.
"""

import os
from pathlib import Path
import re
from typing import Dict, Iterable, Iterator, List, Optional, Sequence, Tuple, Union

from rosbags.rosbag2 import Reader, ReaderError, StoragePlugin, Writer, WriterError
from rosbags.typesys import get_typestore, Stores

from .fusion import Estimate, Observation

__all__ = [
    'BagError',
    'IMAGE_POINT_TYPE',
    'POSITION_TOPIC',
    'bag_cameras',
    'image_point_topic',
    'iter_raw',
    'read_observations',
    'read_positions',
    'write_estimates',
    'write_observations',
    'write_points',
]

PathLike = Union[str, os.PathLike]

#: Message type of image points and positions.
IMAGE_POINT_TYPE = 'geometry_msgs/msg/PointStamped'
#: Topic of the fused 3D positions.
POSITION_TOPIC = '/ball/position'

_IMAGE_POINT_RE = re.compile(r'^/([A-Za-z_][A-Za-z0-9_]*)/ball/image_point$')
_STORAGE = {'mcap': StoragePlugin.MCAP, 'sqlite3': StoragePlugin.SQLITE3}
# A damaged bag makes rosbags and the mcap / sqlite / CDR layers under it raise almost anything
# (ReaderError, struct.error, OverflowError, KeyError, UnicodeDecodeError, ...); reading is the
# only thing inside these handlers, so every such error means "this bag is damaged".
_READ_ERRORS = (ReaderError, Exception)

_typestore = None


class BagError(ValueError):
    """A bag cannot be read or written; the message names the bag and the reason."""


def typestore():
    """Return the shared ROS 2 Jazzy typestore of rosbags."""
    global _typestore
    if _typestore is None:
        _typestore = get_typestore(Stores.ROS2_JAZZY)
    return _typestore


def image_point_topic(camera: str) -> str:
    """Return the image point topic of a camera: ``/<camera>/ball/image_point``."""
    return f'/{camera}/ball/image_point'


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


def _topics(reader: Reader) -> Dict[str, str]:
    """Return topic -> message type (each topic once)."""
    return {connection.topic: connection.msgtype for connection in reader.connections}


def bag_cameras(path: PathLike) -> List[str]:
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


def iter_raw(path: PathLike, topics: Optional[Sequence[str]] = None
             ) -> Iterator[Tuple[str, str, int, bytes]]:
    """
    Iterate over the raw messages of a bag in log-time order.

    :param path: the bag
    :param topics: the topics to read (all when None); each must exist
    :return: an iterator of ``(topic, msgtype, log_time_ns, cdr_bytes)``
    """
    reader = _open(path)
    try:
        available = _topics(reader)
        if topics is None:
            connections = reader.connections
        else:
            missing = [topic for topic in topics if topic not in available]
            if missing:
                raise BagError(f'{path}: no topic {", ".join(missing)} (the bag has: '
                               f'{", ".join(sorted(available)) or "no topics"})')
            connections = [c for c in reader.connections if c.topic in set(topics)]
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


def _read_points(path: PathLike, topics: Sequence[str]) -> Iterator[Tuple[str, object]]:
    """Yield ``(topic, PointStamped)`` of the given topics, checking their type."""
    store = typestore()
    checked = set()
    for topic, msgtype, _, data in iter_raw(path, topics):
        if topic not in checked:
            if msgtype != IMAGE_POINT_TYPE:
                raise BagError(f'{path}: topic {topic} has type {msgtype}, '
                               f'expected {IMAGE_POINT_TYPE}')
            checked.add(topic)
        try:
            msg = store.deserialize_cdr(data, msgtype)
        except _READ_ERRORS as err:
            raise BagError(f'{path}: a message on {topic} does not decode '
                           f'({_reason(err)})') from err
        yield topic, msg


def _check_types(path: PathLike, topics: Sequence[str]) -> None:
    """Raise BagError when a topic is missing or not a PointStamped (before reading data)."""
    reader = _open(path)
    try:
        available = _topics(reader)
    finally:
        reader.close()
    for topic in topics:
        if topic not in available:
            raise BagError(f'{path}: no topic {topic} (the bag has: '
                           f'{", ".join(sorted(available)) or "no topics"})')
        if available[topic] != IMAGE_POINT_TYPE:
            raise BagError(f'{path}: topic {topic} has type {available[topic]}, '
                           f'expected {IMAGE_POINT_TYPE}')


def _stamp_ns(msg) -> int:
    return int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)


def read_observations(path: PathLike, cameras: Optional[Sequence[str]] = None
                      ) -> List[Observation]:
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


def read_positions(path: PathLike, topic: str = POSITION_TOPIC) -> List[Tuple[int, float,
                                                                              float, float]]:
    """
    Read a PointStamped topic as positions.

    :param path: the bag
    :param topic: the topic (``/ball/position`` by default)
    :return: ``(stamp_ns, x, y, z)`` tuples in log-time order
    """
    _check_types(path, [topic])
    return [(_stamp_ns(msg), float(msg.point.x), float(msg.point.y), float(msg.point.z))
            for _, msg in _read_points(path, [topic])]


def _point_stamped(stamp_ns: int, frame_id: str, x: float, y: float, z: float):
    store = typestore()
    types = store.types
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    stamp = types['builtin_interfaces/msg/Time'](sec=sec, nanosec=nanosec)
    header = types['std_msgs/msg/Header'](stamp=stamp, frame_id=frame_id)
    point = types['geometry_msgs/msg/Point'](x=float(x), y=float(y), z=float(z))
    return store.serialize_cdr(types[IMAGE_POINT_TYPE](header=header, point=point),
                               IMAGE_POINT_TYPE)


def write_points(path: PathLike, rows: Iterable[Tuple[str, int, str, float, float, float]], *,
                 storage: str = 'mcap') -> int:
    """
    Write PointStamped messages to a new bag, log time = header stamp.

    :param path: the bag directory to create (must not exist)
    :param rows: ``(topic, stamp_ns, frame_id, x, y, z)``, written sorted by stamp
    :param storage: ``'mcap'`` or ``'sqlite3'``
    :return: the number of messages written
    """
    if storage not in _STORAGE:
        raise BagError(f'{path}: unknown storage {storage!r} (known: {", ".join(_STORAGE)})')
    rows = sorted(rows, key=lambda row: row[1])
    path = Path(path)
    if path.exists():
        raise BagError(f'{path}: exists already, not overwriting')
    try:
        with Writer(path, version=Writer.VERSION_LATEST, storage_plugin=_STORAGE[storage]) as bag:
            connections = {}
            for topic, stamp, frame_id, x, y, z in rows:
                if topic not in connections:
                    connections[topic] = bag.add_connection(topic, IMAGE_POINT_TYPE,
                                                            typestore=typestore())
                bag.write(connections[topic], int(stamp),
                          _point_stamped(int(stamp), frame_id, x, y, z))
    except (WriterError, OSError) as err:
        raise BagError(f'{path}: cannot write the bag ({_reason(err)})') from err
    return len(rows)


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
