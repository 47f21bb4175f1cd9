"""Freeze frames and black boxes, captured when a fault is confirmed.

A freeze frame is the latest message of each selected topic at the
confirmation (decoded, as JSON in the report). A black box is every message
of those topics from `duration_sec` before to `duration_after_sec` after,
written as its own small MCAP beside the output. Only the selected topics
are buffered, and only for `duration_sec`, so memory stays bounded.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from bagfault.io.mcap_sink import McapSink
from bagfault.units import NS

if TYPE_CHECKING:
    from bagfault.fault_manager.config import Snapshots
    from bagfault.io.types import TypeCatalog

ARRAY_LIMIT = 32


def to_plain(value: Any) -> Any:
    """A decoded message as JSON-ready data (long arrays shortened)."""
    if isinstance(value, np.ndarray):
        items = value.tolist()
        if len(items) > ARRAY_LIMIT:
            return {'length': len(items), 'first': items[:ARRAY_LIMIT]}
        return items
    if isinstance(value, (list, tuple)):
        return [to_plain(v) for v in value[:ARRAY_LIMIT]]
    if hasattr(value, '__dataclass_fields__'):
        return {k: to_plain(getattr(value, k)) for k in value.__dataclass_fields__ if k != '__msgtype__'}
    return _plain_float(value) if isinstance(value, float) else value


def _plain_float(value: float) -> float | str:
    """nan and infinities as text (JSON has no such numbers), other floats as they are."""
    if value != value:
        return 'nan'
    if value in (float('inf'), float('-inf')):
        return str(value)
    return value


@dataclass
class Capture:
    """One confirmation's snapshot."""

    code: str
    time: int
    topics: tuple[str, ...]
    freeze_frame: dict[str, Any]
    messages: list[tuple[str, int, int, bytes]] = field(default_factory=list)
    end: int = 0
    path: Path | None = None
    sink: McapSink | None = None


class SnapshotRecorder:
    """Buffers the selected topics and cuts snapshots on confirmation."""

    def __init__(
        self,
        config: Snapshots,
        topics: dict[str, tuple[str, str, str]],
        catalog: TypeCatalog,
        blackbox_base: Path | None,
        numbers: dict[str, int] | None = None,
    ) -> None:
        self.config = config
        self.channels = topics  # topic -> (msgtype, schema encoding, schema text)
        self.catalog = catalog
        self.blackbox_base = blackbox_base
        self.topics = config.all_topics() & set(topics) if config.enabled else set()
        self.window = round(config.duration_sec * NS)
        self.buffers: dict[str, deque[tuple[int, int, bytes]]] = {t: deque() for t in self.topics}
        self.latest: dict[str, tuple[int, bytes]] = {}
        self.open: list[Capture] = []
        self.captures: list[Capture] = []
        self._last_capture: dict[str, int] = {}
        self._numbers: dict[str, int] = numbers if numbers is not None else {}  # shared by the passes of a loop

    def on_message(self, topic: str, time: int, publish_time: int, data: bytes | memoryview) -> None:
        """Buffer one message of a selected topic; close captures that are over."""
        if self.open:
            self._close_before(time)
        if topic not in self.topics:
            return
        raw = bytes(data)
        self.latest[topic] = (time, raw)
        buffer = self.buffers[topic]
        buffer.append((time, publish_time, raw))
        while buffer and buffer[0][0] < time - self.window:
            buffer.popleft()
        for capture in self.open:
            if topic in capture.topics and time <= capture.end:
                capture.messages.append((topic, time, publish_time, raw))

    def on_confirmed(self, code: str, time: int) -> None:
        """A fault was confirmed at `time`: freeze frame now, black box until time + after."""
        if not self.config.enabled:
            return
        topics = tuple(t for t in self.config.topics_for(code) if t in self.topics)
        if not self.config.topics_for(code):
            return  # explicit empty list: this code opts out
        last = self._last_capture.get(code)
        if last is not None and time - last < round(self.config.recapture_cooldown_sec * NS):
            return
        self._last_capture[code] = time
        capture = Capture(code, time, topics, self._freeze_frame(topics),
                          end=time + round(self.config.duration_after_sec * NS))
        for topic in topics:
            capture.messages += [(topic, t, p, d) for t, p, d in self.buffers[topic] if t >= time - self.window]
        self.captures.append(capture)
        self.open.append(capture)

    def _freeze_frame(self, topics: tuple[str, ...]) -> dict[str, Any]:
        """The latest message of each topic that has one, decoded to plain data (None where no type decodes it)."""
        frame = {}
        for topic in topics:
            if topic in self.latest:
                stamp, raw = self.latest[topic]
                codec = self.catalog.codec(self.channels[topic][0])
                frame[topic] = {'log_time_ns': stamp, 'message': to_plain(codec.decode(raw)) if codec else None}
        return frame

    def forget(self, codes: tuple[str, ...]) -> None:
        """ClearFault: these codes may be captured again at once (medkit evicts their cooldown)."""
        for code in codes:
            self._last_capture.pop(code, None)

    def _close_before(self, time: int) -> None:
        done = [c for c in self.open if c.end < time]
        for capture in done:
            self.open.remove(capture)
            self._write(capture)

    def finish(self) -> None:
        """End of the bag: close every open capture (cut short)."""
        for capture in self.open:
            self._write(capture)
        self.open = []

    def _write(self, capture: Capture) -> None:
        if self.blackbox_base is None or not capture.topics:
            return
        number = self._numbers.get(capture.code, 0) + 1
        self._numbers[capture.code] = number
        path = self.blackbox_base.parent / f'{self.blackbox_base.stem}.blackbox.{capture.code}.{number}.mcap'
        sink = McapSink(path)
        channels = {}
        for topic in capture.topics:
            msgtype, encoding, text = self.channels[topic]
            channels[topic] = sink.add_channel(topic, msgtype, encoding, text)
        for topic, time, publish_time, data in sorted(capture.messages, key=lambda m: m[1]):
            sink.write(channels[topic], time, publish_time, data)
        sink.close_unpublished()
        capture.path, capture.sink = path, sink

    def publish(self) -> None:
        """The main output succeeded: move black boxes to their names."""
        for capture in self.captures:
            if capture.sink is not None:
                capture.sink.publish()

    def discard(self) -> None:
        """The run failed: remove black boxes."""
        for capture in self.captures:
            if capture.sink is not None:
                capture.sink.abort()
