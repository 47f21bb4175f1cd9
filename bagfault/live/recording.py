"""The MCAP a live mode writes: topics registered when first seen, events as typed messages.

Same conventions as an offline output (profile ros2, schemas, the event
channels of ros2_fault_injection, temporary file renamed at the end), so
`bagfault check` and every MCAP tool read it.
"""

from __future__ import annotations

import threading
from typing import TYPE_CHECKING

from bagfault.io.mcap_sink import McapSink

if TYPE_CHECKING:
    from pathlib import Path

    from bagfault.events import Event
    from bagfault.io.types import TypeCatalog


class Recording:
    """Thread-safe writer of one live recording."""

    def __init__(self, path: Path, catalog: TypeCatalog) -> None:
        self.path = path
        self.catalog = catalog
        self.sink = McapSink(path)
        self.counts: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._lock = threading.Lock()
        self.closed = False

    def channel(self, topic: str, msgtype: str, metadata: dict[str, str] | None = None) -> int:
        """Register a topic (once) with the schema the type catalog knows."""
        with self._lock:
            found = self._channels.get(topic)
            if found is None:
                encoding, text = self.catalog.schema(msgtype)
                found = self.sink.add_channel(topic, msgtype, encoding, text, 'cdr', metadata)
                self._channels[topic] = found
            return found

    def write(self, topic: str, msgtype: str, time: int, data: bytes | memoryview) -> None:
        """Append one message received or sent at ROS time `time` (ns)."""
        channel = self._channels.get(topic)
        if channel is None:
            channel = self.channel(topic, msgtype)
        with self._lock:
            if self.closed:
                return
            self.sink.write(channel, time, time, data)
            self.counts[topic] = self.counts.get(topic, 0) + 1

    def write_event(self, event: Event) -> None:
        """Encode an event record with its ros2msg definition and append it."""
        codec = self.catalog.codec(event.msgtype)
        if codec is None:  # adding a definition rebuilds the type store: only when it is missing
            self.catalog.add_definition(event.msgtype, event.definition)
            codec = self.catalog.codec(event.msgtype)
        assert codec is not None
        self.write(event.topic, event.msgtype, event.time, codec.encode(event.to_message(codec.store)))

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        """A metadata record (provenance)."""
        with self._lock:
            self.sink.add_metadata(name, data)

    def add_attachment(self, name: str, media_type: str, data: bytes) -> None:
        """An attachment (the scenario file)."""
        with self._lock:
            self.sink.add_attachment(name, media_type, data)

    def finish(self) -> None:
        """Complete the file and give it its name."""
        with self._lock:
            if not self.closed:
                self.closed = True
                self.sink.finish()

    def abort(self) -> None:
        """Drop the partial file."""
        with self._lock:
            if not self.closed:
                self.closed = True
                self.sink.abort()
