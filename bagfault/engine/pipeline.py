"""The offline pipeline: route, inject, merge by time, write.

    source -> router -- untouched topic ----------------------------> merge -> sink
                     -- injector topic -> injector (active faults) -> merge
    scheduler (bag time) -> fault events ------------------------------> merge

Messages of topics without an active fault are copied as raw bytes. The
input is cut into segments at every fault change, so within a segment the
set of active faults is fixed and an injector can treat the segment's
messages as one batch.

`batch=False` selects the simple reference path that the fast paths are
tested against: every decodable message is decoded and re-encoded, and
faults are applied one message at a time.
"""

from __future__ import annotations

import itertools
from bisect import bisect_left
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

from bagfault.engine.merge import TimeOrderedMerge
from bagfault.engine.scheduler import Activation, FaultScheduler, seconds_to_ns
from bagfault.events import Event, FaultEvent
from bagfault.injectors.base import ActiveFault, Injector, RawMessage

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

    from bagfault.io.sources import InputSet
    from bagfault.io.types import TypeCatalog
    from bagfault.scenario.model import FaultSpec, InjectorSpec, Scenario

BATCH = 4096  # messages per batch at most ...
BATCH_BYTES = 4 << 20  # ... and about this many bytes, so writing overlaps the next batch's injection
EVENT_RANK, COPY_RANK = -1, 0


@dataclass(frozen=True)
class OutputChannel:
    """A channel of the output file."""

    id: int
    topic: str
    msgtype: str


class Sink(Protocol):
    """Where records go (an MCAP file, live publishers, ...)."""

    def add_channel(
        self,
        topic: str,
        msgtype: str,
        schema_encoding: str,
        schema_text: str,
        message_encoding: str = 'cdr',
        metadata: dict[str, str] | None = None,
    ) -> int:
        """Register a channel; return its id."""
        ...

    def write(self, channel_id: int, log_time: int, publish_time: int, data: bytes | memoryview) -> None:
        """Write one message."""
        ...


class Observer(Protocol):
    """Sees every output record and event in time order, just before it is written."""

    def start(self, origin: int) -> None:
        """Bag time zero is known."""
        ...

    def on_message(self, topic: str, time: int, data: bytes | memoryview) -> None:
        """An output message."""
        ...

    def on_event(self, event: FaultEvent) -> None:
        """A fault event."""
        ...

    def finish(self, time: int) -> None:
        """End of the output at bag time `time`."""
        ...


@dataclass(eq=False)
class InjectorRuntime:
    """An injector wired into the pipeline."""

    spec: InjectorSpec
    injector: Injector
    faults: list[FaultSpec]
    channel: OutputChannel
    rank: int
    active: list[ActiveFault] = field(default_factory=list)


@dataclass
class RunStats:
    """What a run did, for the summary and the report."""

    input_messages: int = 0
    output_messages: int = 0
    first_time: int | None = None
    last_time: int | None = None
    origin: int | None = None
    per_topic_out: dict[str, int] = field(default_factory=dict)
    events: list[FaultEvent] = field(default_factory=list)
    replaced_topics: list[str] = field(default_factory=list)
    max_buffered: int = 0
    last_output_time: int | None = None


class Pipeline:
    """Runs a scenario over an input set into a sink."""

    def __init__(
        self,
        inputs: InputSet,
        scenario: Scenario,
        sink: Sink,
        catalog: TypeCatalog,
        routes: dict[int, list[InjectorRuntime]],
        copies: dict[int, OutputChannel],
        *,
        seed: int,
        activations: Sequence[Activation] = (),
        start_offset: float = 0.0,
        batch: bool = True,
        observers: Sequence[Observer] = (),
        progress: Callable[[int, int], None] | None = None,
    ) -> None:
        self.inputs = inputs
        self.scenario = scenario
        self.sink = sink
        self.catalog = catalog
        self.routes = routes
        self.copies = copies
        self.seed = seed
        self.activations = activations
        self.start_offset = start_offset
        self.batch = batch
        self.observers = list(observers)
        self.progress = progress
        self.stats = RunStats()
        self.scheduler: FaultScheduler | None = None
        self._counter = itertools.count()
        self._merge = TimeOrderedMerge()
        self._event_channels: dict[str, tuple[OutputChannel, Any]] = {}
        self._runtimes = [runtime for runtimes in routes.values() for runtime in runtimes]
        self._roundtrips: dict[int, Callable[[bytes | memoryview], bytes | memoryview]] = {}

    # -- events -----------------------------------------------------------
    def event_channel(self, kind: type[Event]) -> tuple[OutputChannel, Any]:
        """Output channel and codec of an event type, registered on first use."""
        entry = self._event_channels.get(kind.msgtype)
        if entry is None:
            self.catalog.add_definition(kind.msgtype, kind.definition)
            channel_id = self.sink.add_channel(kind.topic, kind.msgtype, 'ros2msg', kind.definition)
            entry = (OutputChannel(channel_id, kind.topic, kind.msgtype), self.catalog.codec(kind.msgtype))
            self._event_channels[kind.msgtype] = entry
        return entry

    def write_event(self, event: Event) -> None:
        """Encode and write an event record at its own time."""
        channel, codec = self.event_channel(type(event))
        self.sink.write(channel.id, event.time, event.time, codec.encode(event.to_message(codec.store)))
        self.stats.output_messages += 1
        per_topic = self.stats.per_topic_out
        per_topic[channel.topic] = per_topic.get(channel.topic, 0) + 1

    def _refresh_active(self) -> None:
        assert self.scheduler is not None
        for runtime in self._runtimes:
            runtime.active = self.scheduler.active_of(runtime.faults)

    # -- main loop --------------------------------------------------------
    def run(self) -> RunStats:
        """Process every input message; return statistics."""
        if self.scenario.faults:
            self.event_channel(FaultEvent)
        batch: list[tuple[int, int, int, bytes | memoryview]] = []
        order = size = 0
        for item in self.inputs.messages():
            if self.scheduler is None:
                self._start(item[1])
            batch.append(item)
            size += len(item[3])
            if len(batch) >= BATCH or size >= BATCH_BYTES:
                self._process(batch, order)
                order += len(batch)
                batch = []
                size = 0
        if batch:
            self._process(batch, order)
        self._flush_injectors()
        self._emit(self._merge.drain())
        end = self.stats.last_output_time
        for observer in self.observers:
            observer.finish(end if end is not None else 0)
        return self.stats

    def _flush_injectors(self) -> None:
        """End of input: injectors release what they hold (reorder windows)."""
        last = self.stats.last_time
        if last is None:
            return
        records = [
            (m.log_time, m.order, runtime.rank, next(self._counter), runtime.channel, m.publish_time, m.data)
            for runtime in self._runtimes for m in runtime.injector.flush(last)
        ]
        if records:
            self._emit(self._merge.release(records, last, is_sorted=False))

    def _start(self, first_time: int) -> None:
        origin = first_time + seconds_to_ns(self.start_offset)
        self.stats.first_time = first_time
        self.stats.origin = origin
        self.scheduler = FaultScheduler(self.scenario, origin, self.seed, self.activations)
        self._refresh_active()
        for observer in self.observers:
            observer.start(origin)

    def _process(self, batch: list[tuple[int, int, int, bytes | memoryview]], first_order: int) -> None:
        scheduler = self.scheduler
        assert scheduler is not None
        times = [item[1] for item in batch]
        self.stats.input_messages += len(batch)
        self.stats.last_time = times[-1]
        start = 0
        while start < len(batch):
            change = scheduler.next_time()
            if change is not None and change <= times[start]:
                events = scheduler.advance(times[start])
                self._refresh_active()
                order = first_order + start
                records = [
                    (e.time, order, EVENT_RANK, next(self._counter), e) for e in events
                ]
                self.stats.events.extend(events)
                self._emit(self._merge.release(records, times[start], is_sorted=True))
                continue
            stop = len(batch) if change is None else bisect_left(times, change, start)
            self._segment(batch, start, stop, first_order)
            start = stop
        if self.progress is not None:
            self.progress(self.stats.input_messages, times[-1])

    def _segment(
        self,
        batch: list[tuple[int, int, int, bytes | memoryview]],
        start: int,
        stop: int,
        first_order: int,
    ) -> None:
        copies, routes, counter = self.copies, self.routes, self._counter
        records: list[tuple[Any, ...]] = []
        grouped: dict[InjectorRuntime, list[RawMessage]] = {}
        for index in range(start, stop):
            channel, log_time, publish_time, data = batch[index]
            if not self.batch:
                data = self._roundtrip(channel)(data)
            copy = copies.get(channel)
            if copy is not None:
                records.append((log_time, first_order + index, COPY_RANK, next(counter), copy, publish_time, data))
            for runtime in routes.get(channel, ()):
                grouped.setdefault(runtime, []).append(
                    RawMessage(log_time, publish_time, data, first_order + index)
                )
        is_sorted = True
        for runtime, messages in grouped.items():
            injector = runtime.injector
            if not runtime.active and not injector.busy:
                outputs = messages
                if injector.tracks_history:
                    injector.watch(messages)
            elif self.batch:
                outputs = injector.process_batch(messages, runtime.active)
            else:
                outputs = [out for m in messages for out in injector.process(m, runtime.active)]
            out_channel, rank = runtime.channel, runtime.rank
            records.extend(
                (m.log_time, m.order, rank, next(counter), out_channel, m.publish_time, m.data) for m in outputs
            )
            is_sorted = False
        horizon = batch[stop - 1][1]
        self._emit(self._merge.release(records, horizon, is_sorted=is_sorted))
        if len(self._merge) > self.stats.max_buffered:
            self.stats.max_buffered = len(self._merge)

    def _roundtrip(self, channel: int) -> Callable[[bytes | memoryview], bytes | memoryview]:
        """Reference path: decode and re-encode a channel's messages (unchanged when undecodable)."""
        function = self._roundtrips.get(channel)
        if function is None:
            codec = self.catalog.codec(self.inputs.channels[channel].msgtype)
            function = (lambda data: data) if codec is None else (lambda data: codec.encode(codec.decode(data)))
            self._roundtrips[channel] = function
        return function

    def _emit(self, records: Any) -> None:
        write, observers, stats = self.sink.write, self.observers, self.stats
        per_topic = stats.per_topic_out
        time = None
        for record in records:
            time = record[0]
            if record[2] == EVENT_RANK:
                for observer in observers:
                    observer.on_event(record[4])
                self.write_event(record[4])
                continue
            _, _, _, _, channel, publish_time, data = record
            for observer in observers:
                observer.on_message(channel.topic, time, data)
            write(channel.id, time, publish_time, data)
            stats.output_messages += 1
            per_topic[channel.topic] = per_topic.get(channel.topic, 0) + 1
        if time is not None:
            stats.last_output_time = time
