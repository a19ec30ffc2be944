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
A rosbag2 mcap bag that is complete on disk after every checkpoint.

A killed recorder loses only what came after its last checkpoint.
rosbags' Writer keeps the current 1 MiB chunk in memory and writes the
mcap summary and ``metadata.yaml`` only on close: a recorder killed with
``kill -9`` (or by the OOM killer) left a 0-byte mcap and no metadata, and
nothing could be read back.  This writer
produces the same files (one ``<name>.mcap`` per bag directory, rosbag2
metadata version 9, uncompressed chunks with message indexes, as rosbags
writes them), but :meth:`CheckpointBagWriter.checkpoint` turns what was
written so far into a complete file:

* the messages since the last checkpoint become one chunk with its message
  indexes, followed by the summary (schemas, channels, chunk indexes,
  statistics) and the footer, all in **one** ``pwrite`` at the end of the
  previous chunk, over the previous checkpoint's summary.  The new bytes are
  never shorter than the summary they replace (the summary only grows; it
  is padded when it would not), so between two system calls the file is
  always a complete mcap: the previous checkpoint's or the new one's;
* ``metadata.yaml`` is then replaced atomically (written aside, renamed).

A killed process loses the messages after its last checkpoint.  A torn
write by a power cut is not covered (no fsync).  The core
of the package: no rclpy.
"""

from __future__ import annotations

import os
from pathlib import Path
import struct
from typing import Any

import yaml

from .bagio import typestore
from ..errors import BagError

__all__ = ['CheckpointBagWriter']

_MAGIC = b'\x89MCAP0\r\n'
_PROFILE = 'ros2'
_LIBRARY = 'pseudo_stereo_ros checkpoint_bag'
_VERSION = 9
#: rosbags starts a new chunk after 1 MiB; so does this writer (and at every checkpoint).
CHUNK_BYTES = 1 << 20


def _string(text: str) -> bytes:
    data = text.encode('utf-8')
    return struct.pack('<I', len(data)) + data


def _record(opcode: int, content: bytes) -> bytes:
    return struct.pack('<BQ', opcode, len(content)) + content


class _Connection:
    __slots__ = ('id', 'topic', 'msgtype', 'digest', 'count')

    def __init__(self, connection_id: int, topic: str, msgtype: str, digest: str):
        self.id, self.topic, self.msgtype, self.digest = connection_id, topic, msgtype, digest
        self.count = 0


class CheckpointBagWriter:
    """
    Write a rosbag2 mcap bag that is complete on disk after each :meth:`checkpoint`.

    :param path: the bag directory to create (must not exist)
    """

    def __init__(self, path: str | os.PathLike[str]):
        self.path = Path(path)
        self.mcap_path = self.path / f'{self.path.name}.mcap'
        self._fd: int | None = None
        self._schemas: dict[str, int] = {}       # msgtype -> schema id
        self._schema_records: list[bytes] = []
        self._channel_records: list[bytes] = []
        self._connections: list[_Connection] = []
        self._chunk = bytearray()                 # records of the open chunk
        self._chunk_index: dict[int, list[tuple[int, int]]] = {}  # channel -> [(log time, offset)]
        self._chunk_times: tuple[int, int] | None = None  # (first, last) log time of the chunk
        self._chunk_indexes: list[bytes] = []     # ChunkIndex records of the written chunks
        self._data_end = 0                        # where the summary of the last checkpoint starts
        self._tail_length = 0                     # its length, up to the closing magic
        self._start_ns: int | None = None
        self._end_ns: int | None = None
        #: Messages written, in total; checkpoints made.
        self.message_count = 0
        self.checkpoints = 0

    # -- writing ----------------------------------------------------------------------------------

    def create(self) -> None:
        """
        Create the bag directory and a complete, empty bag.

        :raises BagError: the directory exists or cannot be created
        """
        try:
            self.path.mkdir(parents=True, exist_ok=False)
        except FileExistsError:
            raise BagError(f'{self.path}: exists already, not overwriting') from None
        except OSError as err:
            raise BagError(f'{self.path}: cannot create the bag ({err.strerror})') from err
        try:
            self._fd = os.open(self.mcap_path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
            head = _MAGIC + _record(0x01, _string(_PROFILE) + _string(_LIBRARY))
            os.write(self._fd, head)
        except OSError as err:
            raise BagError(f'{self.mcap_path}: cannot write ({err.strerror})') from err
        self._data_end = len(head)
        self.checkpoint(force=True)

    def add_connection(self, topic: str, msgtype: str) -> int:
        """
        Add a topic (CDR-serialized messages of a ROS 2 Jazzy type).

        :param topic: the topic name
        :param msgtype: the type, e.g. ``geometry_msgs/msg/PointStamped``
        :return: the connection id for :meth:`write`
        :raises BagError: the type is unknown to rosbags' Jazzy typestore
        """
        store = typestore()
        if msgtype not in store.types:
            raise BagError(f'{self.path}: {topic}: type {msgtype} is not a ROS 2 Jazzy type')
        if msgtype not in self._schemas:
            schema_id = len(self._schemas) + 1
            msgdef, _ = store.generate_msgdef(msgtype, ros_version=2)
            encoding = 'ros2idl' if msgdef.startswith('=' * 80 + '\nIDL: ') else 'ros2msg'
            record = _record(0x03, struct.pack('<H', schema_id) + _string(msgtype)
                             + _string(encoding) + _string(msgdef))
            self._schemas[msgtype] = schema_id
            self._schema_records.append(record)
            self._chunk += record
        connection = _Connection(len(self._connections) + 1, topic, msgtype,
                                 store.hash_rihs01(msgtype))
        metadata = _string('offered_qos_profiles') + _string('')
        record = _record(0x04, struct.pack('<HH', connection.id, self._schemas[msgtype])
                         + _string(topic) + _string('cdr')
                         + struct.pack('<I', len(metadata)) + metadata)
        self._connections.append(connection)
        self._channel_records.append(record)
        self._chunk += record
        return connection.id

    def write(self, connection_id: int, log_time_ns: int, data: bytes) -> None:
        """
        Append one serialized message (in memory until the next checkpoint or full chunk).

        :param connection_id: from :meth:`add_connection`
        :param log_time_ns: the receive time [ns]
        :param data: the CDR bytes
        """
        connection = self._connections[connection_id - 1]
        self._chunk_index.setdefault(connection_id, []).append((log_time_ns, len(self._chunk)))
        header = struct.pack('<BQHIQQ', 0x05, 22 + len(data), connection_id, 0,
                             log_time_ns, log_time_ns)
        self._chunk += header
        self._chunk += data
        times = self._chunk_times
        self._chunk_times = ((log_time_ns, log_time_ns) if times is None else
                             (min(times[0], log_time_ns), max(times[1], log_time_ns)))
        connection.count += 1
        self.message_count += 1
        if len(self._chunk) > CHUNK_BYTES:
            self.checkpoint()

    def checkpoint(self, *, force: bool = False) -> bool:
        """
        Make the files on disk a complete bag of everything written so far.

        :param force: write the summary and metadata even when nothing changed
        :return: True when something was written
        :raises BagError: the file cannot be written (disk full, ...)
        """
        if self._fd is None:
            return False
        if not self._chunk and not force:
            return False
        # (A chunk may hold only schemas and channels: readers need them before any message.)
        chunk = self._close_chunk() if self._chunk else b''
        tail = self._tail(self._data_end + len(chunk))
        shortfall = self._tail_length - len(chunk) - len(tail)
        if shortfall > 0:
            tail = self._tail(self._data_end + len(chunk), pad=shortfall)
        try:
            os.pwrite(self._fd, chunk + tail, self._data_end)
        except OSError as err:
            raise BagError(f'{self.mcap_path}: cannot write ({err.strerror})') from err
        self._data_end += len(chunk)
        self._tail_length = len(tail)
        self._write_metadata()
        self.checkpoints += 1
        return True

    def close(self) -> None:
        """Write the last checkpoint and close the file (idempotent)."""
        if self._fd is None:
            return
        try:
            self.checkpoint(force=True)
        finally:
            os.close(self._fd)
            self._fd = None

    @property
    def counts(self) -> dict[str, int]:
        """Return messages written per topic."""
        return {c.topic: c.count for c in self._connections}

    # -- the mcap records -------------------------------------------------------------------------

    def _close_chunk(self) -> bytes:
        """Return the open chunk as a Chunk record and its MessageIndex records; start anew."""
        records = bytes(self._chunk)
        start, end = self._chunk_times or (0, 0)
        chunk = _record(0x06, struct.pack('<QQQI', start, end, len(records), 0)
                        + _string('') + struct.pack('<Q', len(records)) + records)
        chunk_start = self._data_end
        indexes, offsets = b'', []
        for channel_id, entries in self._chunk_index.items():
            offsets.append((channel_id, chunk_start + len(chunk) + len(indexes)))
            body = b''.join(struct.pack('<QQ', t, o) for t, o in entries)
            indexes += _record(0x07, struct.pack('<HI', channel_id, len(body)) + body)
        offset_map = b''.join(struct.pack('<HQ', c, o) for c, o in offsets)
        self._chunk_indexes.append(_record(
            0x08, struct.pack('<QQQQ', start, end, chunk_start, len(chunk))
            + struct.pack('<I', len(offset_map)) + offset_map
            + struct.pack('<Q', len(indexes)) + _string('')
            + struct.pack('<QQ', len(records), len(records))))
        if self._chunk_times is not None:
            self._start_ns = start if self._start_ns is None else min(self._start_ns, start)
            self._end_ns = end if self._end_ns is None else max(self._end_ns, end)
        self._chunk = bytearray()
        self._chunk_index = {}
        self._chunk_times = None
        return chunk + indexes

    def _tail(self, offset: int, pad: int = 0) -> bytes:
        """Return Metadata, DataEnd, the summary and the footer, starting at ``offset``."""
        information = yaml.safe_dump(self._information(), default_flow_style=False)
        information += ' ' * pad
        metadata_map = _string('serialized_metadata') + _string(information)
        metadata = _record(0x0C, _string('rosbag2') + struct.pack('<I', len(metadata_map))
                           + metadata_map)
        data_end = _record(0x0F, struct.pack('<I', 0))
        summary_start = offset + len(metadata) + len(data_end)
        schemas = b''.join(self._schema_records)
        channels = b''.join(self._channel_records)
        chunk_indexes = b''.join(self._chunk_indexes)
        metadata_index = _record(0x0D, struct.pack('<QQ', offset, len(metadata))
                                 + _string('rosbag2'))
        counts = b''.join(struct.pack('<HQ', c.id, c.count) for c in self._connections)
        start, end = (self._start_ns or 0), (self._end_ns or 0)
        statistics = _record(0x0B, struct.pack(
            '<QHIIIIQQI', self.message_count, len(self._schema_records),
            len(self._channel_records), 0, 1, len(self._chunk_indexes), start, end,
            len(counts)) + counts)
        groups: list[bytes] = []
        position = summary_start
        for opcode, block in ((0x03, schemas), (0x04, channels), (0x08, chunk_indexes),
                              (0x0D, metadata_index), (0x0B, statistics)):
            if block:
                groups.append(_record(0x0E, struct.pack('<BQQ', opcode, position, len(block))))
            position += len(block)
        summary = schemas + channels + chunk_indexes + metadata_index + statistics
        offsets = b''.join(groups)
        footer = _record(0x02, struct.pack('<QQI', summary_start,
                                           summary_start + len(summary), 0))
        return metadata + data_end + summary + offsets + footer + _MAGIC

    # -- metadata.yaml ----------------------------------------------------------------------------

    def _information(self) -> dict[str, Any]:
        start = self._start_ns or 0
        duration = (self._end_ns - start) if self._end_ns is not None else 0
        return {
            'version': _VERSION,
            'storage_identifier': 'mcap',
            'relative_file_paths': [self.mcap_path.name],
            'duration': {'nanoseconds': duration},
            'starting_time': {'nanoseconds_since_epoch': start},
            'message_count': self.message_count,
            'topics_with_message_count': [
                {'topic_metadata': {'name': c.topic, 'type': c.msgtype,
                                    'serialization_format': 'cdr', 'offered_qos_profiles': [],
                                    'type_description_hash': c.digest},
                 'message_count': c.count}
                for c in self._connections],
            'compression_format': '',
            'compression_mode': '',
            'files': [{'path': self.mcap_path.name,
                       'starting_time': {'nanoseconds_since_epoch': start},
                       'duration': {'nanoseconds': duration},
                       'message_count': self.message_count}],
            'custom_data': None,
            'ros_distro': 'jazzy',
        }

    def _write_metadata(self) -> None:
        text = yaml.safe_dump({'rosbag2_bagfile_information': self._information()},
                              default_flow_style=False)
        target = self.path / 'metadata.yaml'
        aside = self.path / 'metadata.yaml.tmp'
        try:
            aside.write_text(text, encoding='utf-8')
            os.replace(aside, target)
        except OSError as err:
            raise BagError(f'{target}: cannot write ({err.strerror})') from err
