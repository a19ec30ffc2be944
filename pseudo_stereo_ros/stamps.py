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
Stamps: integer nanoseconds <-> the ``builtin_interfaces/msg/Time`` fields ``sec``, ``nanosec``.

The core keeps every stamp as integer nanoseconds; a message stamp is the
pair ``sec`` (int32), ``nanosec`` (uint32, ``0 <= nanosec < 10**9``).  This
module holds that arithmetic and field layout once, for the two places that
build messages: :mod:`~pseudo_stereo_ros.ros.messages` (rclpy messages) and
:mod:`~pseudo_stereo_ros.formats.bagio` (rosbags messages).  Both pass the fields to
their own ``Time`` class; stamps never go through float seconds (a stamp
near 1.7e18 ns loses ~200 ns as a float).  ROS-free: stdlib only.
"""

from __future__ import annotations

from typing import Protocol

__all__ = ['BAG_STAMP_MAX_NS', 'NS_PER_S', 'ns_to_sec_nanosec', 'sec_nanosec_to_ns',
           'seconds_to_ns', 'stamp_fields', 'stamp_ns']

#: Nanoseconds per second.
NS_PER_S = 1_000_000_000

#: Latest stamp a bag message can carry [ns]: ``Time.sec`` is an int32 (2038-01-19); a bag's
#: log time is unsigned, so the earliest is 0.
BAG_STAMP_MAX_NS = (2 ** 31 - 1) * NS_PER_S + NS_PER_S - 1


def seconds_to_ns(seconds: float) -> int:
    """
    Return a duration or time in seconds as integer nanoseconds (rounded to the nearest ns).

    :param seconds: finite seconds (a float carries ~0.1 us at epoch times; durations only)
    :return: the value [ns]
    """
    return int(round(seconds * NS_PER_S))


def ns_to_sec_nanosec(stamp_ns: int) -> tuple[int, int]:
    """
    Split a stamp into ``(sec, nanosec)``.

    :param stamp_ns: the stamp [ns] (negative stamps give a negative ``sec``)
    :return: ``(sec, nanosec)`` with ``0 <= nanosec < 10**9``
    """
    return divmod(int(stamp_ns), NS_PER_S)


def sec_nanosec_to_ns(sec: int, nanosec: int) -> int:
    """Return ``sec * 10**9 + nanosec`` as an integer stamp [ns]."""
    return int(sec) * NS_PER_S + int(nanosec)


def stamp_fields(stamp_ns: int) -> dict[str, int]:
    """
    Return the keyword arguments of a ``builtin_interfaces/msg/Time`` for a stamp.

    :param stamp_ns: the stamp [ns]
    :return: ``{'sec': ..., 'nanosec': ...}``, for ``Time(**stamp_fields(stamp_ns))`` of
        rclpy or of a rosbags typestore
    """
    sec, nanosec = ns_to_sec_nanosec(stamp_ns)
    return {'sec': sec, 'nanosec': nanosec}


class _Stamp(Protocol):
    """Anything with the fields of a ``builtin_interfaces/msg/Time`` (rclpy or rosbags)."""

    @property
    def sec(self) -> int: ...

    @property
    def nanosec(self) -> int: ...


def stamp_ns(stamp: _Stamp) -> int:
    """
    Return a ``builtin_interfaces/msg/Time`` as integer nanoseconds.

    :param stamp: the message stamp, e.g. ``msg.header.stamp``: rclpy or rosbags, anything
        with ``sec`` and ``nanosec``
    :return: the stamp [ns]
    """
    return sec_nanosec_to_ns(stamp.sec, stamp.nanosec)
