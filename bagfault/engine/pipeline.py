"""The offline pipeline: route, inject, merge by time, and hand the records to the run loop.

    source -> router -- untouched topic ----------------------------> merge -> Run -> sink
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
from typing import TYPE_CHECKING

from bagfault.engine.activation import Activation
from bagfault.engine.fault_state import FaultState, inject
from bagfault.engine.merge import COPY_RANK, EVENT_RANK, TimeOrderedMerge
from bagfault.engine.scheduler import FaultScheduler, seconds_to_ns
from bagfault.events import FaultEvent
from bagfault.faults.active import ActiveFault
from bagfault.injectors.base import Injector, RawMessage
from bagfault.spec.model import describe_config_update
from bagfault.units import NS

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

    from bagfault.engine.chunk_copy import ChunkCopy
    from bagfault.engine.control import FaultChange, FaultControl
    from bagfault.engine.merge import Record
    from bagfault.engine.run import OutputChannel, Run
    from bagfault.io.channel import Data, InputMessage
    from bagfault.io.mcap_chunks import ChunkRef
    from bagfault.io.sources import InputSet
    from bagfault.spec.model import FaultSpec, InjectorSpec

BATCH = 4096  # messages per batch at most ...
BATCH_BYTES = 4 << 20  # ... and about this many bytes, so writing overlaps the next batch's injection


@dataclass(eq=False)
class InjectorRuntime:
    """An injector wired into the pipeline."""

    spec: InjectorSpec
    injector: Injector
    faults: list[FaultSpec]
    channel: OutputChannel
    rank: int
    active: list[ActiveFault] = field(default_factory=list)

    @property
    def msgtype(self) -> str:
        """The type of the messages it takes."""
        return self.channel.msgtype


class Pipeline:
    """Runs a scenario's faults over an input set and hands every output record to a Run."""

    def __init__(
        self,
        inputs: InputSet,
        run: Run,
        routes: dict[int, list[InjectorRuntime]],
        copies: dict[int, OutputChannel],
        state: FaultState,
        *,
        seed: int,
        activations: Sequence[Activation] = (),
        start_offset: float = 0.0,
        batch: bool = True,
        progress: Callable[[int, int], None] | None = None,
        control: FaultControl | None = None,
        chunks: ChunkCopy | None = None,
    ) -> None:
        self.inputs = inputs
        self.chunks = chunks  # chunk copy: untouched chunks of a single MCAP input written as they are
        self.control = control  # changes from outside (play with controls): applied message by message
        self.state = state  # the one fault state: the scheduler of this pass, config changes, injectors
        self.run = run
        self.scenario = run.scenario
        self.catalog = run.catalog
        self.routes = routes
        self.copies = copies
        self.seed = seed
        self.activations = activations
        self.start_offset = start_offset
        self.batch = batch
        self.progress = progress
        self.scheduler: FaultScheduler | None = None
        self._counter = itertools.count()
        self._merge = TimeOrderedMerge()
        self._runtimes = [runtime for runtimes in routes.values() for runtime in runtimes]
        self._roundtrips: dict[int, Callable[[Data], Data]] = {}

    def _refresh_active(self) -> None:
        assert self.scheduler is not None
        for runtime in self._runtimes:
            runtime.active = self.scheduler.active_of(runtime.faults)

    # -- main loop --------------------------------------------------------
    def process(self) -> None:
        """Process every input message, then end the run's output (a `Stopped` from the sink ends it early)."""
        if self.scenario.faults:
            self.run.event_channel(FaultEvent)
        if self.chunks is not None:
            self._process_chunks(self.chunks)
            return
        batches = _Batches(self._process)
        for item in self.inputs.messages():
            if self.scheduler is None:
                self._start(item[1])
            batches.add(item)
        batches.flush()
        self._flush_injectors()
        self.run.emit(self._merge.drain())

    def _process_chunks(self, chunks: ChunkCopy) -> None:
        """The chunk copy path, chunk by chunk: quiet chunks written as they are, the others' messages processed
        as in `process` (the pending batch first, so the fault state is current when a chunk is judged)."""
        self._start(next(ref.start for ref in chunks.refs if ref.index_offsets))
        assert self.scheduler is not None
        source = chunks.source
        topic_of = {cid: source.channels[source.channel_number(cid)].topic for cid in chunks.passthrough}
        self.run.stats.chunks = len(chunks.refs)
        batches = _Batches(self._process)
        for ref in chunks.refs:
            chunks.reading(ref)
            if chunks.candidate(ref):
                batches.flush()
                if self._copied(chunks, ref, topic_of):
                    continue
            for item in source.messages_of(ref, source.records_of(ref, source.read_record(ref))):
                batches.add(item)
        chunks.release()
        batches.flush()
        if chunks.verifier is not None:
            self.run.stats.chunks_verified = chunks.verifier.wait()
        self._flush_injectors()
        self.run.emit(self._merge.drain())

    def _copied(self, chunks: ChunkCopy, ref: ChunkRef, topic_of: dict[int, str]) -> bool:
        """Write a chunk as it is when no fault acts on it now and the merge holds nothing of its time; whether
        it was."""
        assert self.scheduler is not None
        if not chunks.quiet(ref, self.scheduler) or self._merge.holds(set(ref.channel_ids), ref.start, ref.end):
            return False
        chunk = chunks.copy_of(ref)
        self.run.read(sum(chunk.counts.values()), ref.end)
        self.run.copy_chunk(chunk, topic_of)
        self.run.stats.chunks_copied += 1
        if chunks.verifier is not None:
            chunks.verifier.submit(ref)
        if self.progress is not None:
            self.progress(self.run.stats.input_messages, ref.end)
        return True

    def _flush_injectors(self) -> None:
        """End of input: injectors release what they hold (reorder windows)."""
        last = self.run.stats.last_time
        if last is None:
            return
        records = [
            (m.log_time, m.order, runtime.rank, next(self._counter), runtime.channel, m.publish_time, m.data)
            for runtime in self._runtimes for m in runtime.injector.flush(last)
        ]
        if records:
            self.run.emit(self._merge.release(records, last, is_sorted=False))

    def _start(self, first_time: int) -> None:
        origin = self.run.begin(first_time, seconds_to_ns(self.start_offset))
        self.scheduler = FaultScheduler(self.scenario, origin, self.seed, self.activations)
        self.state.scheduler = self.scheduler
        self._refresh_active()

    def _process(self, batch: list[InputMessage], first_order: int) -> None:
        scheduler = self.scheduler
        assert scheduler is not None
        times = [item[1] for item in batch]
        self.run.read(len(batch), times[-1])
        start = 0
        control = self.control
        while start < len(batch):
            if control is not None:
                self._apply(control.take(), times[start], first_order + start)
            change = scheduler.next_time()
            if change is not None and change <= times[start]:
                events = scheduler.advance(times[start])
                self._refresh_active()
                order = first_order + start
                records: list[Record] = [(e.time, order, EVENT_RANK, next(self._counter), e) for e in events]
                self.run.emit(self._merge.release(records, times[start], is_sorted=True))
                continue
            stop = len(batch) if change is None else bisect_left(times, change, start)
            if control is not None:
                stop = start + 1  # a change asked meanwhile applies from the next message
            self._segment(batch, start, stop, first_order)
            start = stop
        if self.progress is not None:
            self.progress(self.run.stats.input_messages, times[-1])

    def _apply(self, changes: list[FaultChange], time: int, order: int) -> None:
        """Changes asked from outside, at bag time `time`: switches and config values, as `manual` events."""
        if not changes:
            return
        scheduler = self.scheduler
        assert scheduler is not None
        events: list[FaultEvent] = []
        held: list[Record] = []
        state = self.state
        for change in changes:
            if state.fault(change.fault_id) is None:
                continue
            if change.key is None:
                event = state.switch(change.fault_id, bool(change.value), time, 'manual')
                if event is not None:
                    events.append(event)
                continue
            events.append(self._reconfigure(change, time, held))
        self._refresh_active()
        records: list[Record] = [(e.time, order, EVENT_RANK, next(self._counter), e) for e in events]
        self.run.emit(self._merge.release(records + held, time, is_sorted=False))

    def _reconfigure(self, change: FaultChange, time: int, held: list[Record]) -> FaultEvent:
        """A config value changed from outside: its injector made anew with it (the old one's held messages
        added to `held`); the `config_updated` event."""
        assert change.key is not None
        state = self.state
        fault = state.configure(change.fault_id, change.key, change.value)
        for runtime in self._runtimes:
            if runtime.spec.id == fault.injector_id:  # a new injector takes the new config; the old hands over
                held += [(m.log_time, m.order, runtime.rank, next(self._counter), runtime.channel,
                          m.publish_time, m.data) for m in runtime.injector.flush(time)]
                runtime.faults = state.faults_of(runtime.spec.id)
                runtime.injector = state.injector(runtime.spec, runtime.msgtype, self.catalog)
        return FaultEvent(time, fault.id, fault.injector_id, 'config_updated', 'manual',
                          describe_config_update(change.key, fault.config_text[change.key]))

    def _segment(self, batch: list[InputMessage], start: int, stop: int, first_order: int) -> None:
        copies, routes, counter = self.copies, self.routes, self._counter
        records: list[Record] = []
        grouped: dict[InjectorRuntime, list[RawMessage]] = {}
        for position in range(start, stop):
            index, log_time, publish_time, data = batch[position]
            if not self.batch:
                data = self._roundtrip(index)(data)
            copy = copies.get(index)
            if copy is not None:
                records.append((log_time, first_order + position, COPY_RANK, next(counter), copy, publish_time, data))
            for runtime in routes.get(index, ()):
                grouped.setdefault(runtime, []).append(
                    RawMessage(log_time, publish_time, data, first_order + position)
                )
        is_sorted = True
        for runtime, messages in grouped.items():
            outputs = self._inject(runtime, messages)
            out_channel, rank = runtime.channel, runtime.rank
            records.extend(
                (m.log_time, m.order, rank, next(counter), out_channel, m.publish_time, m.data) for m in outputs
            )
            is_sorted = False
        horizon = batch[stop - 1][1]
        self.run.emit(self._merge.release(records, horizon, is_sorted=is_sorted))
        stats = self.run.stats
        stats.max_buffered = max(stats.max_buffered, len(self._merge))

    def _inject(self, runtime: InjectorRuntime, messages: list[RawMessage]) -> list[RawMessage]:
        """One injector's messages of a segment, through its active faults (the one injection step)."""
        return inject(runtime.injector, runtime.active, messages, batch=self.batch,
                      malformed=lambda message, reason: self._malformed(runtime, message, reason))

    def _malformed(self, runtime: InjectorRuntime, message: RawMessage, reason: str) -> str:
        """Count a message that could not take a fault; where it was."""
        topic = runtime.spec.input_topic or ''
        stats = self.run.stats
        stats.malformed[topic] = stats.malformed.get(topic, 0) + 1
        stats.malformed_first.setdefault(topic, (message.log_time, reason))
        return f'{topic}: message at {(message.log_time - (stats.origin or 0)) / NS:.3f} s'

    def _roundtrip(self, index: int) -> Callable[[Data], Data]:
        """Reference path: decode and re-encode a channel's messages (unchanged when undecodable)."""
        function = self._roundtrips.get(index)
        if function is None:
            codec = self.catalog.codec(self.inputs.channels[index].msgtype)
            if codec is None:
                function = _unchanged
            else:
                def function(data: Data) -> Data:
                    return codec.encode(codec.decode(data))
            self._roundtrips[index] = function
        return function


def _unchanged(data: Data) -> Data:
    return data


class _Batches:
    """Input messages handed on in batches of BATCH messages or BATCH_BYTES, numbered in input order."""

    def __init__(self, process: Callable[[list[InputMessage], int], None]) -> None:
        self.process = process
        self.items: list[InputMessage] = []
        self.size = 0
        self.order = 0

    def add(self, item: InputMessage) -> None:
        """One more message; a full batch goes on."""
        self.items.append(item)
        self.size += len(item[3])
        if len(self.items) >= BATCH or self.size >= BATCH_BYTES:
            self.flush()

    def flush(self) -> None:
        """Hand on what is pending (before a chunk is judged, and at the end)."""
        if self.items:
            self.process(self.items, self.order)
            self.order += len(self.items)
            self.items, self.size = [], 0
