"""Time-ordered merge of output records with a bounded buffer for delayed ones.

Records are tuples whose first fields are the sort key:
(time, order, rank, counter, payload...). `order` is the input position,
`rank` puts fault events (-1) before copies (0) before injector outputs
(1+), and `counter` makes every key unique. The buffer only ever holds
records later than the newest input time, so its size is bounded by
delay x rate, not by bag length.
"""

from __future__ import annotations

import heapq
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from collections.abc import Iterator

Record = tuple[Any, ...]
EVENT_RANK, COPY_RANK = -1, 0  # fault events before copied messages before injector outputs (ranks 1+)


class TimeOrderedMerge:
    """Releases records in key order once no later input can precede them."""

    def __init__(self) -> None:
        self._pending: list[Record] = []

    def __len__(self) -> int:
        return len(self._pending)

    def release(self, records: list[Record], horizon: int, *, is_sorted: bool) -> Iterator[Record]:
        """Add a segment's records; yield all records with time <= horizon, in order.

        Every record added later must have time >= horizon.
        """
        if not is_sorted:
            records.sort()
        pending = self._pending
        if records and records[-1][0] > horizon:
            cut = _first_after(records, horizon)
            for record in records[cut:]:
                heapq.heappush(pending, record)
            records = records[:cut]
        if not pending or pending[0][0] > horizon:
            yield from records
            return
        due = []
        while pending and pending[0][0] <= horizon:
            due.append(heapq.heappop(pending))
        yield from heapq.merge(records, due) if records else due

    def holds(self, channel_ids: set[int], start: int, end: int) -> bool:
        """True when a held record of one of these output channels falls in [start, end] (a delayed message that
        would interleave with a chunk there)."""
        return any(start <= r[0] <= end and r[2] != EVENT_RANK and r[4].id in channel_ids for r in self._pending)

    def drain(self) -> Iterator[Record]:
        """Everything left, in order (end of input)."""
        pending = self._pending
        while pending:
            yield heapq.heappop(pending)


def _first_after(records: list[Record], horizon: int) -> int:
    low, high = 0, len(records)
    while low < high:
        mid = (low + high) // 2
        if records[mid][0] <= horizon:
            low = mid + 1
        else:
            high = mid
    return low
