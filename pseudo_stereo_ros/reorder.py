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
Put items from several sources back into stamp order, holding each for at most a window.

Each source (a camera's topic) delivers its own items in stamp order, but two
sources may arrive interleaved out of order when one path is slower.  An
item is released when it is safe (every source has delivered something at
or after its stamp, so nothing earlier can come) or when it has waited
``window_ns`` since it arrived; releases are in stamp order.  An item older
than one already released is passed through at once and counted as
``late`` (the consumer drops or handles it).  Arrival times come from the
caller's clock, so this is tested without a ROS graph.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable
import heapq
from typing import Any

__all__ = ['ReorderBuffer']


class ReorderBuffer:
    """
    A stamp-ordered buffer with a bounded hold time.

    :param window_ns: longest hold [ns] (arrival-clock time); 0 releases every item at once
    :param sources: names of the sources; with them an item is released early once every
        source has reached its stamp
    :param max_items: hold at most this many items; the oldest is released beyond that
    """

    def __init__(self, window_ns: int, *, sources: Iterable[str] | None = None,
                 max_items: int = 1000) -> None:
        if window_ns < 0:
            raise ValueError(f'window_ns must be >= 0, got {window_ns}')
        if max_items < 1:
            raise ValueError(f'max_items must be >= 1, got {max_items}')
        self.window_ns = int(window_ns)
        self.max_items = int(max_items)
        # source -> its newest stamp [ns] (None before its first item)
        self._latest: dict[str, int | None] = dict.fromkeys(sources or ())
        # (stamp [ns], arrival sequence, arrival time [ns], item)
        self._heap: list[tuple[int, int, int, Any]] = []
        self._sequence = 0
        self._released_ns: int | None = None
        #: Counts: ``items``, ``released``, ``late`` (older than a released item), ``overflow``.
        self.stats: Counter[str] = Counter()

    def __len__(self) -> int:
        """Return the number of items held."""
        return len(self._heap)

    def next_due_ns(self) -> int | None:
        """Return the arrival-clock time [ns] when the oldest held item is due, or None."""
        if not self._heap:
            return None
        return min(entry[2] for entry in self._heap) + self.window_ns

    def push(self, stamp_ns: int, source: str, item: Any, now_ns: int) -> list[Any]:
        """
        Add one item and return the items now released, in stamp order.

        :param stamp_ns: the item's stamp [ns]
        :param source: the source name
        :param item: anything
        :param now_ns: arrival time on the caller's clock [ns]
        :return: released items (possibly including this one)
        """
        self.stats['items'] += 1
        stamp_ns = int(stamp_ns)
        if source in self._latest or not self._latest:
            previous = self._latest.get(source)
            if previous is None or stamp_ns > previous:
                self._latest[source] = stamp_ns
        if self._released_ns is not None and stamp_ns < self._released_ns:
            self.stats['late'] += 1
            self.stats['released'] += 1
            return [item]
        if self.window_ns == 0 and not self._heap:
            self._released_ns = stamp_ns
            self.stats['released'] += 1
            return [item]
        heapq.heappush(self._heap, (stamp_ns, self._sequence, int(now_ns), item))
        self._sequence += 1
        return self.pop_due(now_ns)

    def pop_due(self, now_ns: int) -> list[Any]:
        """Return the items due at ``now_ns`` (arrival clock) or safe, in stamp order."""
        released: list[Any] = []
        heap = self._heap
        horizon = self._safe_horizon()
        while heap:
            stamp, _, arrival, item = heap[0]
            overflow = len(heap) > self.max_items
            if not (overflow or now_ns - arrival >= self.window_ns
                    or (horizon is not None and stamp <= horizon)):
                break
            if overflow:
                self.stats['overflow'] += 1
            heapq.heappop(heap)
            self._released_ns = stamp
            released.append(item)
        self.stats['released'] += len(released)
        return released

    def flush(self) -> list[Any]:
        """Release everything held, in stamp order."""
        released: list[Any] = []
        while self._heap:
            stamp, _, _, item = heapq.heappop(self._heap)
            self._released_ns = stamp
            released.append(item)
        self.stats['released'] += len(released)
        return released

    def _safe_horizon(self) -> int | None:
        """Return the stamp up to which every source has delivered, or None if one has not."""
        if len(self._latest) < 2:
            return None
        latest = [stamp for stamp in self._latest.values() if stamp is not None]
        if len(latest) < len(self._latest):
            return None
        return min(latest)
