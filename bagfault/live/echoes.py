"""What bagfault published on topics it also listens to, so its own messages are told from another node's.

rclpy's message info carries no publisher id, so a subscriber on a topic
bagfault plays hears bagfault's messages too. Each message published there
is noted with its bytes; the listener drops a message whose bytes are
noted (once per note) and hands on the rest, which another node sent.
Notes not heard back within `KEEP` seconds (published before the listener
matched) are forgotten. For a latched (transient local) topic the last
messages a late subscriber receives from history are noted when listening
starts.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from dataclasses import dataclass

KEEP = 10.0  # seconds a published message may take to come back to the listener


@dataclass(slots=True)
class _Note:
    """One published message not yet heard back (`data` None once heard back: its bytes are let go)."""

    time: float
    data: bytes | None


class OwnEchoes:
    """Notes of bagfault's own messages per topic; `take` is called from the listener's thread."""

    def __init__(self, keep: float = KEEP) -> None:
        self.keep = keep
        self._lock = threading.Lock()
        self._notes: dict[str, dict[bytes, deque[_Note]]] = {}  # topic -> bytes -> its notes, oldest first
        self._order: dict[str, deque[_Note]] = {}  # topic -> every note, oldest first

    def listen(self, topic: str, history: list[bytes] | tuple[bytes, ...] = ()) -> None:
        """Start noting `topic`; `history` is what a new subscriber receives from the publisher's cache."""
        with self._lock:
            self._notes.setdefault(topic, {})
            self._order.setdefault(topic, deque())
        for data in history:
            self.sent(topic, data)

    def __bool__(self) -> bool:
        """True once a topic is listened to."""
        return bool(self._notes)

    def __contains__(self, topic: object) -> bool:
        """True for a topic listened to (its messages are noted)."""
        return topic in self._notes

    def sent(self, topic: str, data: bytes) -> None:
        """bagfault published `data` on `topic` (ignored for topics not listened to)."""
        notes = self._notes.get(topic)
        if notes is None:
            return
        note = _Note(time.monotonic(), data)
        with self._lock:
            order = self._order[topic]
            self._expire(notes, order, note.time)
            notes.setdefault(data, deque()).append(note)
            order.append(note)

    def take(self, topic: str, data: bytes) -> bool:
        """True when `data` on `topic` is bagfault's own message coming back (its oldest note is used up)."""
        notes = self._notes.get(topic)
        if notes is None:
            return False
        with self._lock:
            self._expire(notes, self._order[topic], time.monotonic())
            waiting = notes.get(data)
            if not waiting:
                return False
            waiting.popleft().data = None
            if not waiting:
                del notes[data]
            return True

    def _expire(self, notes: dict[bytes, deque[_Note]], order: deque[_Note], now: float) -> None:
        """Forget notes older than `keep` that were not heard back (published before the listener matched)."""
        while order and now - order[0].time > self.keep:
            note = order.popleft()
            if note.data is not None:  # still waiting: the oldest of its bytes
                waiting = notes[note.data]
                waiting.popleft()
                if not waiting:
                    del notes[note.data]
