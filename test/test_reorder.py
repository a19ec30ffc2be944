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

"""Tests of the ReorderBuffer with mock stamps and a mock arrival clock (no ROS graph)."""

from pseudo_stereo_ros.reorder import ReorderBuffer
import pytest

MS = 1_000_000


def test_window_zero_passes_everything_through_at_once():
    buffer = ReorderBuffer(0, sources=['a', 'b'])
    assert buffer.push(10, 'a', 'a10', now_ns=0) == ['a10']
    assert buffer.push(5, 'b', 'b5', now_ns=0) == ['b5']  # late: passed on, counted
    assert buffer.stats['late'] == 1
    assert len(buffer) == 0


def test_out_of_order_topics_are_released_in_stamp_order():
    buffer = ReorderBuffer(5 * MS, sources=['a', 'b'])
    # b's point of stamp 10 ms arrives before a's point of stamp 0 (a slower detector).
    assert buffer.push(10 * MS, 'b', 'b10', now_ns=0) == []
    # a's 0 ms is safe at once: b is past it and a delivers in order.
    assert buffer.push(0, 'a', 'a0', now_ns=1 * MS) == ['a0']
    assert buffer.pop_due(4 * MS) == []
    # a delivers 20 ms: both sources are past 10 ms, so b's 10 is safe without waiting.
    assert buffer.push(20 * MS, 'a', 'a20', now_ns=2 * MS) == ['b10']
    assert buffer.pop_due(6 * MS) == []
    assert buffer.pop_due(7 * MS) == ['a20']
    assert buffer.stats['late'] == 0


def test_hold_is_bounded_by_the_window():
    buffer = ReorderBuffer(3 * MS, sources=['a', 'b'])
    buffer.push(100 * MS, 'a', 'x', now_ns=50 * MS)
    assert buffer.next_due_ns() == 53 * MS
    assert buffer.pop_due(53 * MS - 1) == []
    assert buffer.pop_due(53 * MS) == ['x']
    # An item older than one released comes out at once and is counted.
    assert buffer.push(90 * MS, 'b', 'old', now_ns=54 * MS) == ['old']
    assert buffer.stats['late'] == 1


@pytest.mark.parametrize('window_ms', [0, 2, 50])
def test_burst_keeps_every_item_once_in_order(window_ms):
    buffer = ReorderBuffer(window_ms * MS, sources=['a', 'b'], max_items=1000)
    out = []
    stamps = [(s, 'a') for s in range(0, 300, 10)] + [(s, 'b') for s in range(5, 300, 10)]
    # Each source in order, the two interleaved in blocks of three: one burst at one instant.
    order = []
    a_items = [x for x in stamps if x[1] == 'a']
    b_items = [x for x in stamps if x[1] == 'b']
    while a_items or b_items:
        order += a_items[:3] + b_items[:3]
        a_items, b_items = a_items[3:], b_items[3:]
    for stamp, source in order:
        out += buffer.push(stamp * MS, source, stamp, now_ns=0)
    out += buffer.flush()
    assert sorted(out) == sorted(s for s, _ in stamps)
    if window_ms >= 2:
        assert out == sorted(out)


def test_overflow_releases_the_oldest():
    buffer = ReorderBuffer(10 ** 12, sources=['a', 'b'], max_items=3)
    out = []
    for stamp in range(5):
        out += buffer.push(stamp, 'a', stamp, now_ns=0)
    assert out == [0, 1]
    assert buffer.stats['overflow'] == 2


def test_invalid_window():
    with pytest.raises(ValueError, match='window_ns'):
        ReorderBuffer(-1)
