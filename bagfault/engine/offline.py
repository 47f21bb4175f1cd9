"""Drivers of the run loop over bags: a bag through a scenario into any sink, a recording judged, a file run.

`replay` is what `run`, `play` and `test` share: inputs -> routing ->
pipeline -> Run (oracles) -> sink. `check_recording` feeds a recording's
messages to the same Run with nothing injected. `run_to_file` wraps
`replay` with the output MCAP, its provenance and an all-or-nothing finish.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from functools import partial
from typing import TYPE_CHECKING, Protocol, cast

from bagfault.engine.chunk_copy import ChunkCopy, chunk_copy_for
from bagfault.engine.fault_state import FaultState
from bagfault.engine.pipeline import Pipeline
from bagfault.engine.provenance import provenance
from bagfault.engine.routing import build_routing
from bagfault.engine.run import NullSink, Observer, OutputChannel, Run
from bagfault.engine.scheduler import seconds_to_ns
from bagfault.engine.stop import Stopped
from bagfault.errors import InputError
from bagfault.events import FaultEvent
from bagfault.io.definitions import load_definitions
from bagfault.io.mcap_sink import McapSink
from bagfault.io.sources import InputSet, ReadMark
from bagfault.io.types import TypeCatalog

if TYPE_CHECKING:
    from collections.abc import Mapping, Sequence
    from pathlib import Path

    from bagfault.engine.activation import Activation
    from bagfault.engine.control import FaultControl
    from bagfault.engine.options import RunOptions
    from bagfault.engine.oracles import Schema
    from bagfault.engine.result import RunResult
    from bagfault.engine.routing import Routing
    from bagfault.engine.run import Sink
    from bagfault.io.leading_copy import LeadingCopy
    from bagfault.io.outputs import PartialFile
    from bagfault.spec.model import Scenario

Progress = Callable[[int, int], None]
EMPTY_INPUT = 'the input holds no messages; the output has channels only'


def begin_progress(progress: Progress | None, inputs: InputSet) -> None:
    """Tell a progress display what the whole job is, when it wants to know."""
    begin = getattr(progress, 'begin', None)
    if begin is not None:
        begin(inputs.start_time, inputs.end_time, inputs.message_count)


def input_warnings(inputs: InputSet) -> list[str]:
    """What the readers worked around, and what salvage could not read."""
    return [*inputs.warnings, *(f'salvage skipped {loss}' for loss in inputs.losses)]


class PassHooks(Protocol):
    """What a live pass adds to the loop (`play`, `test`): waiting for the graph, pacing, outside messages."""

    def prepare(self, routing: Routing) -> Mapping[str, Schema]:
        """Publishers exist (routing registered them): wait for the graph; return topics that will come from
        outside the bag (a system under test) and that the oracles must be able to decode."""
        ...

    def begin(self, run: Run) -> None:
        """The run loop exists; outside messages go into it from here on."""
        ...

    def gate(self, time: int) -> None:
        """Before a record at bag time `time` is judged: wait for its wall time, hand over what came before it."""
        ...

    def finish(self, run: Run) -> None:
        """After the last record, before the verdicts (a tail of outside messages)."""
        ...

    def act(self, event: FaultEvent) -> str:
        """A fault changed state: carry out what it does to the system or its clock; what was done ('' nothing)."""
        ...


def replay(
    inputs: InputSet,
    scenario: Scenario,
    catalog: TypeCatalog,
    sink: Sink,
    *,
    seed: int,
    activations: Sequence[Activation] = (),
    start_offset: float = 0.0,
    batch: bool = True,
    progress: Progress | None = None,
    observers: Sequence[Observer] = (),
    blackbox_base: Path | None = None,
    blackbox_numbers: dict[str, int] | None = None,
    hooks: PassHooks | None = None,
    control: FaultControl | None = None,
    chunks: ChunkCopy | None = None,
    withheld: frozenset[str] = frozenset(),
) -> tuple[Run, bool]:
    """One pass of the inputs through the scenario into `sink`; (the run, True if a Stopped ended it early);
    topics in `withheld` are not played (the closed loop's system publishes them).

    On an error the run's black boxes are removed; on success the caller
    closes the run once its own output is complete.
    """
    keep = None if chunks is None else partial(chunks.keep, cast('McapSink', sink))
    state = control.state if control is not None else FaultState(scenario)  # a control's lasts across passes
    routing = build_routing(inputs, scenario, catalog, sink, keep, state, withheld)
    stopped = False
    try:
        outside = hooks.prepare(routing) if hooks is not None else {}
    except Stopped:
        stopped, outside = True, {}
    run = Run(scenario, sink, catalog, {**routing.schemas, **outside}, observers=observers,
              blackbox_base=blackbox_base, blackbox_numbers=blackbox_numbers)
    run.notes += routing.notes
    run.warnings += routing.warnings
    run.stats.replaced_topics = list(routing.replaced)
    if chunks is not None:
        chunks.wire(routing, run.observers, scenario)
    if chunks is not None and not chunks.passthrough:
        chunks.release()  # every message decoded in the usual order: nothing to keep pace with
        chunks = None
    pipeline = Pipeline(inputs, run, routing.routes, routing.copies, state, seed=seed, activations=activations,
                        start_offset=start_offset, batch=batch, progress=progress, control=control, chunks=chunks)
    if hooks is not None:
        hooks.begin(run)
        run.gate = hooks.gate
        run.act = hooks.act
    try:
        try:
            if not stopped:
                pipeline.process()
                if hooks is not None:
                    hooks.finish(run)
        except Stopped:
            stopped = True
        run.end()
    except BaseException:
        run.close(ok=False)
        raise
    run.warnings += input_warnings(inputs)
    return run, stopped


def run_to_file(
    scenario: Scenario,
    paths: Sequence[Path],
    output: PartialFile,
    options: RunOptions,
    *,
    progress: Progress | None = None,
    observers: Sequence[Observer] = (),
    lead: LeadingCopy | None = None,
) -> RunResult:
    """Inject the scenario's faults into the inputs and write the output MCAP into `output`, published when
    complete (all or nothing); with `options.chunk_copy`, the untouched chunks of a single MCAP input are
    copied as they are (and with `verify` read again, decompressed and checked on a second thread), the leading
    ones by `lead`, which the caller started into `output` before its setup (`engine/lead.py`)."""
    copying = options.chunk_copy and options.batch and len(paths) == 1 and paths[0].is_file()
    seed, activations, start_offset = options.seed, options.activations, options.start_offset
    definitions = load_definitions([*options.msg_paths, *scenario.msg_paths])
    stop = threading.Event()
    mark = ReadMark() if copying else None  # the hash follows the chunk copy's reading: the input is read once
    hashing = ThreadPoolExecutor(max_workers=1, thread_name_prefix='bagfault-hash')
    try:  # the inputs' digests on the second core from the start, beside the setup, the run and the copy
        origin = hashing.submit(provenance, scenario, paths, seed, activations, start_offset, stop, mark)
        with lead.opening() if lead is not None else contextlib.nullcontext():
            inputs = InputSet(paths, salvage=options.salvage)
        with inputs:
            begin_progress(progress, inputs)
            catalog = TypeCatalog(inputs.channels, inputs.ros_distro, definitions)
            chunks = chunk_copy_for(inputs, verify=options.verify, mark=mark) if copying else None
            if chunks is None and mark is not None:
                mark.release()
            if chunks is None and lead is not None:
                lead.close()  # nothing is copied as it is: the guess was wrong, what it copied goes
                output.clear()
                lead = None
            if lead is not None and mark is not None:
                lead.pace(mark)  # the hash follows what the leading copy has read, not what the run took from it
            with McapSink(output.path, compression=options.compression, level=options.compression_level,
                          ros_distro=inputs.ros_distro or '', output=output, lead=lead) as sink:
                with chunks if chunks is not None else contextlib.nullcontext():
                    if chunks is not None:
                        chunks.reserve(sink)
                    run, _ = replay(inputs, scenario, catalog, sink, seed=seed, activations=activations,
                                    start_offset=start_offset, batch=options.batch, progress=progress,
                                    observers=observers, blackbox_base=output.path, chunks=chunks)
                with run:
                    check_declared(inputs, run, paths, salvage=options.salvage)
                    sink.flush()  # the copied chunks go to the file while the hash completes, not after it
                    sink.add_attachment(scenario.name, 'application/yaml', scenario.text.encode(),
                                        inputs.start_time or 0)
                    sink.add_metadata('bagfault', origin.result())
                    finish(sink, run)
    finally:
        if mark is not None:
            mark.release()
        stop.set()  # a failed run does not wait for the hash of a large input
        hashing.shutdown(wait=True, cancel_futures=True)
    if run.stats.input_messages == 0:
        run.notes.append(EMPTY_INPUT)
    return run.result('run', paths, output.path, seed)


def check_declared(inputs: InputSet, run: Run, paths: Sequence[Path], *, salvage: bool) -> None:
    """The messages read against what the inputs declare (MCAP statistics, ROS 1 index records, rosbag2's
    metadata.yaml, the rows of a sqlite3 file). Fewer read means part of an input was never read (a chunk left
    out of the index, a record that swallowed the next, a truncated file): an error, or with `salvage` a
    warning saying how many are missing. More read than declared loses nothing (a recorder that died before
    it wrote its final counts): a warning. With `salvage`, how many messages were not kept is always said: the
    difference, or that it is not known (damaged parts skipped where the input declares no count, or a count
    its messages outgrew)."""
    declared, read = inputs.message_count, run.stats.input_messages
    names = ', '.join(str(p) for p in paths)
    if salvage and inputs.losses and (declared is None or read >= declared):
        known = 'the input declares no count' if declared is None else f'the input declares {declared}'
        run.warnings.append(f'{names}: --salvage skipped {len(inputs.losses)} damaged part'
                            f'{"s" if len(inputs.losses) > 1 else ""}; how many messages they held is not known '
                            f'({known}; {read} were read and are in the output)')
    if declared is None or declared == read:
        return
    text = f'{names}: the input declares {declared} messages and {read} were read'
    if read > declared:
        run.warnings.append(f'{text}: its counts are older than its messages (a recording cut short); every '
                            'message read is in the output')
    elif not salvage:
        raise InputError(f'{text}: part of it was not read (damaged or left out of its index); --salvage writes '
                         'what can be read and says what is missing')
    else:
        run.warnings.append(f'{text}: {declared - read} missing (--salvage)')


def finish(sink: McapSink, run: Run) -> None:
    """Complete the output file, then give the run's black boxes their names (inside `with run`, which removes
    them if the file cannot be completed)."""
    sink.finish()
    run.close(ok=True)


def check_recording(
    scenario: Scenario,
    path: Path,
    *,
    start_offset: float = 0.0,
    observers: Sequence[Observer] = (),
    progress: Progress | None = None,
    salvage: bool = False,
    msg_paths: Sequence[Path] = (),
) -> RunResult:
    """Judge a recording with the scenario's assertions and fault manager; inject nothing.

    Fault events recorded on /fault_injection/events drive `fault_event`
    assertions, `during` windows and reports; bag time zero is where the
    live run that made the recording put it (its `bagfault.origin`
    metadata), else the recording's first message, plus `start_offset`.
    """
    definitions = load_definitions([*msg_paths, *scenario.msg_paths])
    with InputSet([path], salvage=salvage) as inputs:
        begin_progress(progress, inputs)
        catalog = TypeCatalog(inputs.channels, inputs.ros_distro, definitions)
        schemas = {c.topic: (c.msgtype, c.schema_encoding, c.schema_text) for c in inputs.channels}
        sink = NullSink()
        run = Run(scenario, sink, catalog, schemas, observers=observers)
        channels = [OutputChannel(sink.add_channel(c.topic, c.msgtype, '', ''), c.topic, c.msgtype)
                    for c in inputs.channels]
        event_codec = catalog.codec(FaultEvent.msgtype) if FaultEvent.topic in schemas else None
        recorded = next((getattr(s, 'recorded_origin', None) for s in inputs.parts), None)
        for index, log_time, publish_time, data in inputs.messages():
            if not run.started:
                zero = (recorded - log_time) if recorded is not None else 0
                run.begin(log_time, zero + seconds_to_ns(start_offset))
            run.read(1, log_time)
            channel = channels[index]
            if event_codec is not None and channel.topic == FaultEvent.topic:
                run.event(FaultEvent.from_message(log_time, event_codec.decode(data)), write=False)
            run.message(channel, log_time, publish_time, data)
            if progress is not None and run.stats.input_messages % 4096 == 0:
                progress(run.stats.input_messages, log_time)
        run.end(run.stats.last_time if run.stats.last_time is not None else 0)
        run.warnings += input_warnings(inputs)
        check_declared(inputs, run, [path], salvage=salvage)
    run.close(ok=True)
    if run.stats.input_messages == 0:
        run.notes.append('the recording holds no messages')
    return run.result('check', [path], None, 0)
