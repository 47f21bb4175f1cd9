"""The run loop: the one place where output records are observed, counted and written.

Every mode drives a `Run`: the offline pipeline (`run`, `play`, `test`)
hands it merged records, `check` hands it a recording's messages, the live
proxy hands it what it receives and publishes. The Run owns the oracles
(fault manager, assertions) and any other observers, the statistics, the
event channels and the sink, so all modes judge and count the same way.

    driver --(messages, fault events)--> Run --> observers (oracles first) --> sink
                                               <-- oracle events (assertions, fault manager) --
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from time import monotonic
from typing import TYPE_CHECKING, Protocol

from bagfault.engine.merge import EVENT_RANK
from bagfault.engine.oracles import Oracles
from bagfault.engine.result import RunResult, RunStats
from bagfault.units import NS

if TYPE_CHECKING:
    from collections.abc import Callable, Iterable, Mapping, Sequence
    from pathlib import Path

    from typing_extensions import Self

    from bagfault.engine.merge import Record
    from bagfault.engine.oracles import Schema
    from bagfault.engine.result import Mode
    from bagfault.events import Event, EventKind, FaultEvent
    from bagfault.io.mcap_writer import CopiedChunk
    from bagfault.io.types import Codec, TypeCatalog
    from bagfault.spec.model import Scenario

Data = bytes | memoryview


@dataclass(frozen=True)
class OutputChannel:
    """A channel of the output: the sink's id for it, its topic and type."""

    id: int
    topic: str
    msgtype: str


class Sink(Protocol):
    """Where records go: an MCAP file, live publishers, nothing."""

    def add_channel(self, topic: str, msgtype: str, schema_encoding: str, schema_text: str,
                    message_encoding: str = 'cdr', metadata: dict[str, str] | None = None) -> int:
        """Register a channel; return its id."""
        ...

    def write(self, channel_id: int, log_time: int, publish_time: int, data: Data) -> None:
        """Write one message."""
        ...


class Observer(Protocol):
    """Sees every output record and fault event in time order, just before it is written."""

    def start(self, origin: int) -> None:
        """Bag time zero is known."""
        ...

    def on_message(self, topic: str, time: int, data: Data) -> None:
        """An output message."""
        ...

    def on_event(self, event: FaultEvent) -> None:
        """A fault event."""
        ...

    def finish(self, time: int) -> None:
        """End of the output at bag time `time`."""
        ...


class NullSink:
    """A sink that writes nothing (`check`, a proxy without `--record`)."""

    def __init__(self) -> None:
        self._channels = 0

    def add_channel(self, topic: str, msgtype: str, schema_encoding: str, schema_text: str,
                    message_encoding: str = 'cdr', metadata: dict[str, str] | None = None) -> int:
        """A fresh id."""
        self._channels += 1
        return self._channels

    def write(self, channel_id: int, log_time: int, publish_time: int, data: Data) -> None:
        """Nothing."""


class Run:
    """One pass of a scenario into a sink: oracles and observers, statistics, event channels."""

    def __init__(
        self,
        scenario: Scenario,
        sink: Sink,
        catalog: TypeCatalog,
        schemas: Mapping[str, Schema],
        *,
        observers: Sequence[Observer] = (),
        blackbox_base: Path | None = None,
        blackbox_numbers: dict[str, int] | None = None,
    ) -> None:
        self.scenario = scenario
        self.sink = sink
        self.catalog = catalog
        self.wall_start = monotonic()
        self.stats = RunStats()
        self.notes: list[str] = []
        self.warnings: list[str] = []
        self.oracles = Oracles(scenario, schemas, catalog, self.write_event, blackbox_base, blackbox_numbers)
        self.observers: list[Observer] = [*self.oracles.observers, *observers]
        self.gate: Callable[[int], None] | None = None  # called before each merged record is judged (live passes)
        # carries a fault's change out on a running system and its clock; what it did (live passes)
        self.act: Callable[[FaultEvent], str] | None = None
        self.event_listeners: list[Callable[[Event, bytes], None]] = []  # every event written, encoded (live)
        self._events: dict[str, tuple[OutputChannel, Codec]] = {}
        self._topics: dict[str, OutputChannel] = {}
        self._closed = False
        for kind in self.oracles.event_kinds:  # (their definitions were added first: one build for every codec)
            self.event_channel(kind)

    # -- channels -----------------------------------------------------------------------
    def channel(self, topic: str, msgtype: str, metadata: dict[str, str] | None = None) -> OutputChannel:
        """The output channel of a topic, registered with the catalog's schema on first use (live modes)."""
        found = self._topics.get(topic)
        if found is None:
            encoding, text = self.catalog.schema(msgtype)
            found = OutputChannel(self.sink.add_channel(topic, msgtype, encoding, text, 'cdr', metadata), topic,
                                  msgtype)
            self._topics[topic] = found
        return found

    def event_channel(self, kind: EventKind) -> tuple[OutputChannel, Codec]:
        """Output channel and codec of an event type, registered on first use."""
        entry = self._events.get(kind.msgtype)
        if entry is None:
            if not self.catalog.defines(kind.msgtype):  # a bag written by bagfault carries the definition
                self.catalog.add_definition(kind.msgtype, kind.definition)
            codec = self.catalog.codec(kind.msgtype)
            assert codec is not None
            channel_id = self.sink.add_channel(kind.topic, kind.msgtype, 'ros2msg', kind.definition)
            entry = (OutputChannel(channel_id, kind.topic, kind.msgtype), codec)
            self._events[kind.msgtype] = entry
            self._topics.setdefault(kind.topic, entry[0])
        return entry

    # -- time -----------------------------------------------------------------------------
    def begin(self, first_time: int, start_offset: int = 0) -> int:
        """The first message is at `first_time`; bag time zero is `start_offset` ns later. Returns zero."""
        origin = first_time + start_offset
        self.stats.first_time, self.stats.origin = first_time, origin
        for observer in self.observers:
            observer.start(origin)
        return origin

    @property
    def started(self) -> bool:
        """True after `begin`."""
        return self.stats.origin is not None

    def read(self, count: int, last_time: int) -> None:
        """`count` input messages were read, the last at `last_time`."""
        self.stats.input_messages += count
        self.stats.last_time = last_time

    def end(self, time: int | None = None) -> None:
        """End of the output at `time` (default: the last output record): pending verdicts are decided."""
        if time is None:
            time = self.stats.last_output_time if self.stats.last_output_time is not None else 0
        for observer in self.observers:
            observer.finish(time)

    # -- records ----------------------------------------------------------------------------
    def message(self, channel: OutputChannel, time: int, publish_time: int, data: Data) -> None:
        """One output message: observed, written, counted."""
        for observer in self.observers:
            observer.on_message(channel.topic, time, data)
        self.sink.write(channel.id, time, publish_time, data)
        stats = self.stats
        stats.output_messages += 1
        stats.last_output_time = time
        stats.per_topic_out[channel.topic] = stats.per_topic_out.get(channel.topic, 0) + 1

    def copy_chunk(self, chunk: CopiedChunk, topic_of: Mapping[int, str]) -> None:
        """An input chunk written as it is (chunk copy): counted as the messages it holds; nobody observes it."""
        self.sink.copy_chunk(chunk)  # type: ignore[attr-defined]  # only an McapSink is given chunks
        stats = self.stats
        for channel_id, count in chunk.counts.items():
            topic = topic_of[channel_id]
            stats.per_topic_out[topic] = stats.per_topic_out.get(topic, 0) + count
            stats.output_messages += count
        if chunk.counts:
            stats.last_output_time = max(stats.last_output_time or chunk.end, chunk.end)

    def event(self, event: FaultEvent, *, write: bool = True) -> None:
        """A fault changed state: carried out on the system (`act`, whose account joins the details), observed,
        kept, and written (unless it was read from a recording)."""
        if self.act is not None:
            said = self.act(event)
            if said:
                event = replace(event, details=f'{event.details}; {said}' if event.details else said)
        for observer in self.observers:
            observer.on_event(event)
        self.stats.events.append(event)
        if write:
            self.write_event(event)

    def emit(self, records: Iterable[Record]) -> None:
        """Merged pipeline records in order (the offline hot path of `event` and `message`)."""
        observers, write, stats, gate = self.observers, self.sink.write, self.stats, self.gate
        per_topic = stats.per_topic_out
        time = None
        for record in records:
            time = record[0]
            if gate is not None:
                gate(time)
            if record[2] == EVENT_RANK:
                self.event(record[4])
                continue
            channel, publish_time, data = record[4], record[5], record[6]
            for observer in observers:
                observer.on_message(channel.topic, time, data)
            write(channel.id, time, publish_time, data)
            stats.output_messages += 1
            per_topic[channel.topic] = per_topic.get(channel.topic, 0) + 1
        if time is not None:
            stats.last_output_time = time

    def write_event(self, event: Event) -> None:
        """Encode and write an event record (fault, assertion, scenario status, fault manager) at its time."""
        channel, codec = self.event_channel(event)
        data = codec.encode(event.to_message(codec.store))
        self.sink.write(channel.id, event.time, event.time, data)
        for listener in self.event_listeners:
            listener(event, data)
        stats = self.stats
        stats.output_messages += 1
        stats.per_topic_out[channel.topic] = stats.per_topic_out.get(channel.topic, 0) + 1

    # -- end --------------------------------------------------------------------------------
    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        """A run not closed by the end of the `with` was abandoned: its black boxes are removed."""
        if not self._closed:
            self.close(ok=False)

    def close(self, *, ok: bool) -> None:
        """The output was completed (black boxes take their names) or abandoned (they are removed)."""
        self._closed = True
        if ok:
            self.oracles.publish()
        else:
            self.oracles.discard()

    def result(self, mode: Mode, inputs: Sequence[Path], output: Path | None, seed: int,
               stats: RunStats | None = None) -> RunResult:
        """The verdicts, fault table and notes of this pass (with `stats` of several passes if given)."""
        stats = stats or self.stats
        notes = list(self.notes)
        for topic, count in sorted(stats.malformed.items()):
            time, reason = stats.malformed_first[topic]
            seconds = (time - (stats.origin or time)) / NS
            notes.append(f'{count} message{"s" if count != 1 else ""} on {topic} could not take a fault and followed '
                         f'on_malformed (first at {seconds:.3f} s: {reason})')
        result = RunResult(self.scenario, list(inputs), output, seed, stats, notes,
                           [*self.scenario.warnings, *self.warnings], mode=mode,
                           wall_seconds=monotonic() - self.wall_start)
        self.oracles.fill(result)
        return result

