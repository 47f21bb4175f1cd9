"""Delayed messages of the live proxy: each published when the ROS clock reaches its due time."""

from __future__ import annotations

import heapq
import itertools
import threading
import time
from typing import TYPE_CHECKING

from bagfault.units import NS

if TYPE_CHECKING:
    from collections.abc import Callable

    from bagfault.live.session import LiveTopic


class DelayLine:
    """Holds delayed messages and publishes each when the ROS clock reaches its due time."""

    def __init__(self, clock: Callable[[], int], publish: Callable[[LiveTopic, bytes], None]) -> None:
        self.clock = clock
        self.publish = publish
        self._heap: list[tuple[int, int, LiveTopic, bytes]] = []
        self._last: dict[int, int] = {}  # topic -> due time of its last queued message
        self._counter = itertools.count()
        self._condition = threading.Condition()
        self._stopped = False
        self._thread = threading.Thread(target=self._run, name='bagfault-delay', daemon=True)
        self._thread.start()

    def put(self, due: int, topic: LiveTopic, data: bytes) -> None:
        """Publish `data` on the topic's output at ROS time `due` (ns), never before what the topic queued earlier
        (first in, first out per topic, as the anchor's delay queue: a shrinking delay keeps the order)."""
        with self._condition:
            due = max(due, self._last.get(id(topic), due))
            self._last[id(topic)] = due
            heapq.heappush(self._heap, (due, next(self._counter), topic, data))
            self._condition.notify()

    def _run(self) -> None:
        while True:
            with self._condition:
                while not self._heap and not self._stopped:
                    self._condition.wait()
                if self._stopped:
                    return
                wait = (self._heap[0][0] - self.clock()) / NS
                if wait > 0:
                    self._condition.wait(min(wait, 0.05))  # re-read the clock: sim time may jump
                    continue
                _, _, topic, data = heapq.heappop(self._heap)
            self.publish(topic, data)
            with self._condition:
                self._condition.notify_all()  # a draining stop waits for the heap to empty

    def stop(self, drain: float = 0.0) -> int:
        """Stop: wait up to `drain` seconds (wall time) for waiting messages to fall due, then publish what is
        still waiting at once, in order (nothing is lost). Returns how many went out before their time."""
        deadline = time.monotonic() + drain
        with self._condition:
            while self._heap and time.monotonic() < deadline:
                self._condition.wait(0.01)
            self._stopped = True
            left = [heapq.heappop(self._heap) for _ in range(len(self._heap))]
            self._condition.notify()
        self._thread.join(timeout=2.0)
        for _, _, topic, data in left:
            self.publish(topic, data)
        return len(left)
