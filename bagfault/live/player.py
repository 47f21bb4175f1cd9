"""`bagfault play`: a bag onto the live graph (and into Foxglove), through the scenario's faults, paced by bag time.

Each pass is the offline `replay` unchanged (same routing, injectors,
scheduler on bag time, oracles); only its sink differs (`LiveSink` with
ROS, a bare `Pacer` for `--foxglove` where rclpy is not installed), so what
is published, and recorded with --record, is what `bagfault run` would
write. With --loop the bag starts again after its end, the timeline (and
/clock) continuing where the previous pass ended; each pass's verdicts and
black boxes are its own. With --foxglove the faults are parameters of the
view (applied by the pipeline from the next message) and a seek starts a
new pass that skips to the requested time; at the end of the bag the view
stays until Ctrl-C, so a seek can play it again.
"""

from __future__ import annotations

import contextlib
from typing import TYPE_CHECKING, Any

from bagfault.engine.control import FaultControl
from bagfault.engine.offline import replay
from bagfault.engine.provenance import provenance, record_origin
from bagfault.engine.result import RunStats
from bagfault.errors import FieldValueError, LiveError
from bagfault.io.definitions import load_definitions
from bagfault.io.sources import InputSet
from bagfault.io.types import TypeCatalog
from bagfault.live.pacer import CLOCK_NOTE, SEEK, Pacer
from bagfault.live.recording import maybe_recording
from bagfault.log import log

if TYPE_CHECKING:
    from collections.abc import Iterator, Sequence
    from pathlib import Path

    from bagfault.engine.result import RunResult
    from bagfault.engine.run import Run
    from bagfault.engine.stop import StopFlag
    from bagfault.io.mcap_sink import McapSink
    from bagfault.live.params import FaultParameters
    from bagfault.live.viewing import LiveView, OpenView
    from bagfault.spec.model import Scenario

LOOP_GAP = 1_000_000  # ns between the end of a pass and the start of the next
ACK_WAIT = 5.0  # seconds after the last message for subscribers to acknowledge it (0.5 after a stop)


def run_play(
    scenario: Scenario,
    inputs: list[Path],
    *,
    seed: int,
    stop: StopFlag,
    rate: float = 1.0,
    clock: bool = False,
    loop: bool = False,
    record: Path | None = None,
    delay: float = 0.5,
    wait_for: Sequence[str] = (),
    topics: Sequence[str] = (),
    start_offset: float = 0.0,
    clock_hz: float = 100.0,
    ros_args: list[str] | None = None,
    view: OpenView | None = None,
    ros: bool = True,
) -> RunResult:
    """Play until the end of the bag (or forever with `loop`, or until a stop with a `view`); the recording
    is complete on return. `ros=False` plays into the Foxglove view only (no rclpy needed)."""
    total = RunStats()
    numbers: dict[str, int] = {}  # black box numbering continues across passes
    passes = 0
    last: Run | None = None
    first, end = _time_range(inputs)
    control = FaultControl(scenario) if view is not None or ros else None
    view_notes: list[str] = []
    metadata = {**provenance(scenario, inputs, seed, (), 0.0), 'mode': 'play'}
    with _node(ros, stop, ros_args, control) as (node, start_values), \
            maybe_recording(record, metadata, scenario, first) as recording, contextlib.ExitStack() as closing:
        sink = _sink(node, rate=rate, clock=clock, stop=stop, recording=recording, delay=delay,
                     wait_for=wait_for, clock_hz=clock_hz, topics=topics, start_offset=start_offset)
        shown: LiveView | None = None
        if view is not None:
            shown = view(scenario, controls=control, playback=sink, time_range=(first, end))
            closing.callback(shown.close)
            closing.callback(lambda: view_notes.extend(shown.notes() if shown is not None else ()))
            sink.view = shown
            log.info(f'Foxglove view on {shown.url} (open it in the Foxglove app: Open connection, '
                     'Foxglove WebSocket)')
        while True:
            if control is not None:  # -p values at the start of every pass, as manual switches
                for fault_id, key, value in start_values:
                    control.ask(fault_id, key, value)
            run, stopped = _pass(scenario, inputs, sink, seed=seed, record=record, numbers=numbers,
                                 control=control)
            last = run
            passes += 1
            total.add(run.stats)
            if sink.seeking():
                sink.restart(first)
                continue
            if stopped or run.stats.input_messages == 0:
                break
            if loop:
                sink.offset += (run.stats.last_time or 0) - (run.stats.first_time or 0) + LOOP_GAP
                continue
            if shown is None:
                break
            shown.ended(end)  # stay until Ctrl-C; a seek plays again
            while not stop.is_set() and not sink.seeking():
                stop.wait(0.05)
            if not sink.seeking():
                break
            sink.restart(first)
        ack_wait = ACK_WAIT / 10 if stop.is_set() else ACK_WAIT
        unacknowledged = sink.delivered(ack_wait)
        if recording is not None:
            record_origin(recording, total.origin)
            written = recording.written()  # what the file holds (--topics leaves the rest out)
            total.per_topic_out = written
            total.output_messages = sum(written.values())
            recording.finish()
    assert last is not None
    result = last.result('play', inputs, record, seed, total)
    result.notes.append(f'published {sink.published} messages in {passes} pass{"es" if passes != 1 else ""}'
                        + (f' (stopped by {stop.reason})' if stop.is_set() and stop.reason != SEEK else ''))
    if unacknowledged:
        result.notes.append(f'{", ".join(unacknowledged)}: not every subscriber acknowledged the last messages '
                            f'within {ack_wait:g} s (they may have missed them)')
    if passes > 1:
        result.notes.append(f'verdicts are those of the last pass ({passes} passes)')
    result.notes += view_notes
    if getattr(sink, 'clock_left_out', False):
        result.notes.append(CLOCK_NOTE)
    for topic, why in sorted(getattr(sink, 'skipped', {}).items()):
        result.notes.append(f'{topic} not published: {why} (recorded only)')
    if not ros:
        result.notes.append('played into the Foxglove view only (rclpy is not installed here)')
    return result


@contextlib.contextmanager
def _node(ros: bool, stop: StopFlag, ros_args: list[str] | None,
          control: FaultControl | None) -> Iterator[tuple[Any, list[tuple[str, str | None, Any]]]]:
    """The player's node on a fresh rclpy context (None without ROS: signals still stop the play), spun on a
    thread of its own so its parameter services answer: every fault's `<fault>.active` and `<fault>.<key>`,
    changed through `control`; with the values given by `-p` (checked, unknown names refused)."""
    if not ros:
        with _signals(stop):
            yield None, []
        return
    import threading  # noqa: PLC0415

    from rclpy.executors import SingleThreadedExecutor  # noqa: PLC0415

    from bagfault.live.params import ControlledFaults, FaultParameters  # noqa: PLC0415
    from bagfault.live.ros import make_node  # noqa: PLC0415
    from bagfault.live.runtime import ros_context  # noqa: PLC0415

    assert control is not None
    with ros_context(stop) as context:
        node = make_node('bagfault_player', context, ros_args, allow_undeclared_parameters=True)
        executor = SingleThreadedExecutor(context=context)  # (the events executor deadlocks with publishers
        # the main thread creates while it spins)
        thread: threading.Thread | None = None
        try:
            start = _start_values(FaultParameters(node, ControlledFaults(control), lambda _topic, _data: None))
            executor.add_node(node)
            thread = threading.Thread(target=executor.spin, name='bagfault-player-parameters', daemon=True)
            thread.start()
            yield node, start
        finally:
            executor.shutdown()
            if thread is not None:
                thread.join(timeout=5)
            node.destroy_node()


def _start_values(parameters: FaultParameters) -> list[tuple[str, str | None, Any]]:
    """The `-p` values as (fault, key or None for `active`, value), each checked by the scenario schema
    (unknown names were refused when the parameters were declared); LiveError naming a refused one."""
    start: list[tuple[str, str | None, Any]] = []
    for value in parameters.overrides:
        declared = parameters.parameters[value.name]
        try:
            checked = parameters.session.state.check(declared.fault_id, declared.key, value.value)
        except FieldValueError as exc:
            raise LiveError(f'--ros-args -p {value.name}: {exc}') from None
        start.append((declared.fault_id, declared.key, checked))
    return start


@contextlib.contextmanager
def _signals(stop: StopFlag) -> Iterator[None]:
    """SIGINT, SIGTERM and SIGHUP set `stop` (as `ros_context` does), in the main thread."""
    import signal  # noqa: PLC0415
    import threading  # noqa: PLC0415

    previous = {}
    if threading.current_thread() is threading.main_thread():
        for number in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
            previous[number] = signal.signal(number, lambda n, _f: stop.set(signal.Signals(n).name))
    try:
        yield
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)


def _sink(node: Any, *, rate: float, clock: bool, stop: StopFlag, recording: McapSink | None, delay: float,
          wait_for: Sequence[str], clock_hz: float, topics: Sequence[str], start_offset: float) -> Pacer:
    """A LiveSink on the node, or a bare Pacer without ROS."""
    if node is None:
        return Pacer(rate=rate, stop=stop, recording=recording, topics=topics, skip=start_offset,
                     clock_hz=clock_hz)
    from bagfault.live.sink import LiveSink  # noqa: PLC0415

    return LiveSink(node, rate=rate, clock=clock, stop=stop, recording=recording, settle=delay, wait_for=wait_for,
                    clock_hz=clock_hz, topics=topics, skip=start_offset)


def _pass(scenario: Scenario, inputs: list[Path], sink: Pacer, *, seed: int, record: Path | None,
          numbers: dict[str, int], control: FaultControl | None) -> tuple[Run, bool]:
    """One pass over the bag; its black boxes are named before the next pass begins."""
    with InputSet(inputs) as input_set:
        catalog = TypeCatalog(input_set.channels, input_set.ros_distro, load_definitions(scenario.msg_paths))
        run, stopped = replay(input_set, scenario, catalog, sink, seed=seed, blackbox_base=record,
                              blackbox_numbers=numbers, hooks=sink, control=control)
    run.close(ok=True)
    return run, stopped


def _time_range(inputs: list[Path]) -> tuple[int, int]:
    """The bag's first and last log times."""
    with InputSet(inputs) as input_set:
        return input_set.start_time or 0, input_set.end_time or 0
