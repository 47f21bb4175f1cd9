"""Chunk copy: the chunks of a single MCAP input that nothing can touch go to the output as they are.

A chunk is copied, compressed bytes, message indexes and all, when every
channel it holds messages of is passed through under its input id (a copied
topic, or the topic of an in-place injector, whose channel has a schema with its definition; its
metadata is kept as the input has it, rosbag2's QoS or not), no oracle or report needs to
see that topic, and no fault of that injector is active, holding messages,
or due to change before the chunk ends (followers of other faults counted).
Everything else takes the normal path, so the output's message stream is
the same as without chunk copy (`--no-chunk-copy`); fault events and
mutated messages are written in chunks of their own.
"""

from __future__ import annotations

from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor
from typing import TYPE_CHECKING

from bagfault.engine.lead import wanted_topics
from bagfault.errors import InputError
from bagfault.io.mcap_writer import CopiedChunk

if TYPE_CHECKING:
    from collections.abc import Sequence

    from bagfault.engine.pipeline import InjectorRuntime
    from bagfault.engine.routing import Routing
    from bagfault.engine.run import Observer
    from bagfault.engine.scheduler import FaultScheduler
    from bagfault.io.mcap_chunks import ChunkRef
    from bagfault.io.mcap_sink import McapSink
    from bagfault.io.mcap_source import McapSource
    from bagfault.io.sources import InputSet, ReadMark
    from bagfault.spec.model import Scenario

def chunk_copy_for(inputs: InputSet, *, verify: bool = False, mark: ReadMark | None = None) -> ChunkCopy | None:
    """A chunk copy plan when the inputs are one indexed MCAP file whose chunks follow each other in time;
    with `verify`, each copied chunk is also read again and checked on a second thread; `mark` is told how far
    the run has read."""
    from bagfault.io.mcap_source import McapSource  # noqa: PLC0415

    if len(inputs.parts) != 1 or not isinstance(inputs.parts[0], McapSource):
        return None
    source = inputs.parts[0]
    if source.channels != inputs.channels:
        return None
    refs = source.chunk_refs()
    if not refs or not any(ref.index_offsets for ref in refs):
        return None
    return ChunkCopy(source, refs, ChunkVerifier(source) if verify else None, mark)


class ChunkVerifier:
    """`--verify`: every copied chunk decompressed, CRC-checked and its records counted, on a second thread
    (zstd and crc32 release the GIL), so the copy does not wait for it; the first failure stops the run."""

    def __init__(self, source: McapSource) -> None:
        self.source = source
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix='bagfault-verify')
        self._pending: deque[Future[None]] = deque()
        self.verified = 0

    def submit(self, ref: ChunkRef) -> None:
        """Check this copied chunk; raise the failure of an earlier one as soon as it is known."""
        self._pending.append(self._pool.submit(self.source.verify_chunk, ref))
        while self._pending and self._pending[0].done():
            self._pending.popleft().result()
            self.verified += 1

    def wait(self) -> int:
        """Every check done (or its failure raised); how many chunks were verified."""
        while self._pending:
            self._pending.popleft().result()
            self.verified += 1
        return self.verified

    def close(self) -> None:
        """Stop checking (a failed run does not wait for the rest)."""
        self._pool.shutdown(wait=True, cancel_futures=True)


class ChunkCopy:
    """Which chunks of one MCAP input are copied as they are; built before routing, completed after it."""

    def __init__(self, source: McapSource, refs: list[ChunkRef], verifier: ChunkVerifier | None = None,
                 mark: ReadMark | None = None) -> None:
        self.source = source
        self.refs = refs
        self.verifier = verifier
        self.mark = mark
        self._numbers = {cid: source.channel_number(cid) for cid in source.channel_records}
        self._ids = {number: cid for cid, number in self._numbers.items()}
        self.kept: set[int] = set()  # input channel numbers registered under their input id
        self.passthrough: set[int] = set()  # input channel ids whose messages may be copied
        self.in_place: dict[int, InjectorRuntime] = {}  # input channel id -> its in-place injector
        self.relevant: dict[int, set[str]] = {}  # input channel id -> faults (and their leaders) of that injector

    def __enter__(self) -> ChunkCopy:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()
        if self.verifier is not None:
            self.verifier.close()

    def reading(self, ref: ChunkRef) -> None:
        """The run reads this chunk and its message indexes now (copied or decoded)."""
        if self.mark is not None:
            self.mark.advance(ref.offset + ref.length + ref.index_length)

    def release(self) -> None:
        """The run reads no more chunks in file order."""
        if self.mark is not None:
            self.mark.release()

    def reserve(self, sink: McapSink) -> None:
        """New output channels and schemas are numbered above the input's."""
        sink.reserve(max(self.source.schema_records, default=0), max(self.source.channel_records, default=0))

    def keep(self, sink: McapSink, number: int) -> int | None:
        """Routing's hook: the input channel `number` goes out under its input id and bytes (None: not here)."""
        channel_id = self._ids.get(number)
        if channel_id is None:
            return None
        record = self.source.channel_records[channel_id]
        schema = self.source.schema_records.get(record.schema_id)
        if schema is None or not schema.data:
            return None  # the normal path completes its definition as the ros2 profile requires
        # kept as the input has it: a channel without rosbag2's QoS (the plain mcap writer's, Foxglove's,
        # converters') stays without it, and `ros2 bag` uses its defaults for it, as it does for the input
        self.kept.add(number)
        return sink.keep_channel(schema, record, self.source.channels[number].msgtype)

    def wire(self, routing: Routing, observers: Sequence[Observer], scenario: Scenario) -> None:
        """After routing: the channels whose chunks can be copied, and the faults that can touch them."""
        observed = wanted_topics(observers)
        if observed is None:
            return
        for channel_id, number in self._numbers.items():
            channel = self.source.channels[number]
            runtimes = routing.routes.get(number, [])
            if number not in self.kept or channel.topic in observed:
                continue
            if number in routing.copies:
                if not runtimes:
                    self.passthrough.add(channel_id)
                continue
            if len(runtimes) == 1 and runtimes[0].channel.id == channel_id and \
                    not runtimes[0].injector.tracks_history:
                self.passthrough.add(channel_id)
                self.in_place[channel_id] = runtimes[0]
                self.relevant[channel_id] = _with_leaders(scenario, {f.id for f in runtimes[0].faults})

    def candidate(self, ref: ChunkRef) -> bool:
        """Every channel of the chunk passes through (the question that needs no fault state); a chunk without
        message indexes (an empty map: the writer indexed nothing) is read, as what it holds is not known."""
        return bool(ref.index_offsets) and all(cid in self.passthrough for cid in ref.channel_ids)

    def copy_of(self, ref: ChunkRef) -> CopiedChunk:
        """The chunk to write as it is, with its message indexes: where they are, what they hold."""
        source = self.source
        first = ref.offset + ref.length
        if ref.index_offsets and min(ref.index_offsets.values()) != first:
            raise InputError(f'{source.path}: the message indexes of the chunk at offset {ref.offset} are not where '
                             'its index says')
        return CopiedChunk(source.fileno(), ref.offset, ref.length, ref.index_length,
                           {cid: at - first for cid, at in ref.index_offsets.items()}, source.counts_of(ref),
                           ref.start, ref.end, ref.compression, ref.compressed_size, ref.uncompressed_size)

    def quiet(self, ref: ChunkRef, scheduler: FaultScheduler) -> bool:
        """The exact answer, with every message before the chunk processed: nothing touches it."""
        for cid in ref.channel_ids:
            runtime = self.in_place.get(cid)
            if runtime is None:
                continue
            if runtime.active or runtime.injector.busy:
                return False
            due = scheduler.next_change_of(self.relevant[cid])
            if due is not None and due <= ref.end:
                return False
        return True


def _with_leaders(scenario: Scenario, faults: set[str]) -> set[str]:
    """The faults and, transitively, the faults they follow (`after:`), whose changes schedule theirs."""
    found, todo = set(faults), list(faults)
    while todo:
        fault = scenario.fault(todo.pop())
        leader = fault.after.fault if fault is not None and fault.after is not None else None
        if leader is not None and leader not in found:
            found.add(leader)
            todo.append(leader)
    return found
