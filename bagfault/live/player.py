"""`bagfault play`: a bag onto the live graph, through the scenario's faults, paced by bag time.

Each pass is the offline `replay` unchanged (same routing, injectors,
scheduler on bag time, oracles); only its sink differs (`LiveSink`), so what
is published, and recorded with --record, is what `bagfault run` would
write. With --loop the bag starts again after its end, the timeline (and
/clock) continuing where the previous pass ended; each pass's verdicts and
black boxes are its own.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from bagfault.engine.offline import replay
from bagfault.engine.provenance import ORIGIN_RECORD, origin_metadata, provenance
from bagfault.engine.result import RunStats
from bagfault.io.definitions import load_definitions
from bagfault.io.mcap_sink import LIVE_FLUSH, McapSink
from bagfault.io.sources import InputSet
from bagfault.io.types import TypeCatalog
from bagfault.live.ros import make_node
from bagfault.live.runtime import ros_context
from bagfault.live.sink import LiveSink

if TYPE_CHECKING:
    from collections.abc import Sequence
    from pathlib import Path

    from bagfault.engine.result import RunResult
    from bagfault.engine.run import Run
    from bagfault.engine.stop import StopFlag
    from bagfault.scenario.model import Scenario

LOOP_GAP = 1_000_000  # ns between the end of a pass and the start of the next


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
) -> RunResult:
    """Play until the end of the bag (or forever with `loop`) or a stop; the recording is complete on return."""
    total = RunStats()
    numbers: dict[str, int] = {}  # black box numbering continues across passes
    passes = 0
    last: Run | None = None
    with ros_context(stop) as context:
        node = make_node('bagfault_player', context, ros_args)
        recording = (McapSink(record, ros_distro=_distro(inputs), flush_every=LIVE_FLUSH)
                     if record is not None else None)
        try:
            if recording is not None:
                recording.add_metadata('bagfault', {**provenance(scenario, inputs, seed, (), 0.0), 'mode': 'play'})
                recording.add_attachment(scenario.name, 'application/yaml', scenario.text.encode())
            sink = LiveSink(node, rate=rate, clock=clock, stop=stop, recording=recording, settle=delay,
                            wait_for=wait_for, clock_hz=clock_hz, topics=topics, skip=start_offset)
            while True:
                run, stopped = _pass(scenario, inputs, sink, seed=seed, record=record, numbers=numbers)
                last = run
                passes += 1
                total.add(run.stats)
                if stopped or not loop or run.stats.input_messages == 0:
                    break
                sink.offset += (run.stats.last_time or 0) - (run.stats.first_time or 0) + LOOP_GAP
            if recording is not None:
                origin = origin_metadata(total.origin)
                if origin is not None:
                    recording.add_metadata(ORIGIN_RECORD, origin)
                recording.finish()
        except BaseException:
            if recording is not None:
                recording.abort()
            raise
        finally:
            node.destroy_node()
    assert last is not None
    result = last.result('play', inputs, record, seed, total)
    result.notes.append(f'published {sink.published} messages in {passes} pass{"es" if passes != 1 else ""}'
                        + (f' (stopped by {stop.reason})' if stop.is_set() else ''))
    if loop and passes > 1:
        result.notes.append(f'verdicts are those of the last pass ({passes} passes)')
    for topic, msgtype in sorted(sink.skipped.items()):
        result.notes.append(f'{topic} not published: {msgtype} has no Python bindings here (recorded only)')
    return result


def _pass(scenario: Scenario, inputs: list[Path], sink: LiveSink, *, seed: int, record: Path | None,
          numbers: dict[str, int]) -> tuple[Run, bool]:
    """One pass over the bag; its black boxes are named before the next pass begins."""
    input_set = InputSet(inputs)
    try:
        catalog = TypeCatalog(input_set.channels, input_set.ros_distro, load_definitions(scenario.msg_paths))
        run, stopped = replay(input_set, scenario, catalog, sink, seed=seed, blackbox_base=record,
                              blackbox_numbers=numbers, hooks=sink)
    finally:
        input_set.close()
    run.close(ok=True)
    return run, stopped


def _distro(inputs: list[Path]) -> str:
    """The distro whose definitions the recording will carry (that of the bag, as offline)."""
    input_set = InputSet(inputs)
    try:
        return TypeCatalog(input_set.channels, input_set.ros_distro).distro
    finally:
        input_set.close()
