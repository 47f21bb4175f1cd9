"""`bagfault play`: a bag onto the live graph, through the scenario's faults, paced by bag time.

The offline pipeline runs unchanged (same routing, injectors, scheduler on
bag time, oracles); only its sink differs (`LiveSink`), so what is
published, and recorded with --record, is what `bagfault run` would write.
With --loop the bag starts again after its end, the timeline (and /clock)
continuing where the previous pass ended.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from bagfault.engine.pipeline import RunStats
from bagfault.io.live_sink import LiveSink, PlaybackStopped
from bagfault.io.sources import InputSet
from bagfault.io.types import TypeCatalog
from bagfault.live import LiveError
from bagfault.live.recording import Recording
from bagfault.live.runtime import StopFlag, ros_context

if TYPE_CHECKING:
    from pathlib import Path

    from bagfault.api import RunResult
    from bagfault.scenario.model import Scenario

SETTLE = 0.5  # seconds between creating publishers and the first message, for discovery


def run_play(
    scenario: Scenario,
    inputs: list[Path],
    *,
    seed: int,
    rate: float = 1.0,
    clock: bool = False,
    loop: bool = False,
    record: Path | None = None,
    delay: float = SETTLE,
    stop: StopFlag | None = None,
) -> RunResult:
    """Play until the end of the bag (or forever with `loop`) or a stop; the recording is complete on return."""
    import time  # noqa: PLC0415

    from rclpy.node import Node  # noqa: PLC0415

    from bagfault.api import RunResult, provenance, wire  # noqa: PLC0415

    if rate <= 0:
        raise LiveError(f'--rate {rate:g}: must be above 0')
    stop = stop or StopFlag()
    notes = list(scenario.warnings)
    total = RunStats()
    with ros_context(stop) as context:
        node = Node('bagfault_player', context=context)
        first = InputSet(inputs)
        catalog = TypeCatalog(first.channels, first.ros_distro)
        recording = Recording(record, catalog) if record is not None else None
        oracles = None
        try:
            if recording is not None:
                recording.add_metadata('bagfault', {**provenance(scenario, inputs, seed, (), 0.0), 'mode': 'play'})
                recording.add_attachment(scenario.name, 'application/yaml', scenario.text.encode())
            sink = LiveSink(node, rate=rate, clock=clock, stop=stop, recording=recording)
            passes = 0
            input_set: InputSet | None = first
            while True:
                assert input_set is not None
                routing, pipeline, oracles = wire(input_set, scenario, catalog, sink, seed=seed, blackbox_base=record)
                if passes == 0:
                    time.sleep(delay)
                stopped = False
                try:
                    stats = pipeline.run()
                except PlaybackStopped:
                    stopped = True
                    stats = pipeline.stats
                    end = stats.last_output_time if stats.last_output_time is not None else 0
                    for observer in pipeline.observers:
                        observer.finish(end)
                input_set.close()
                input_set = None
                passes += 1
                _add(total, stats)
                if stopped or not loop or stats.input_messages == 0:
                    break
                sink.offset += (stats.last_time or 0) - (stats.first_time or 0) + 1_000_000
                input_set = InputSet(inputs)
            if recording is not None:
                recording.finish()
            if oracles is not None:
                oracles.publish()
        except BaseException:
            if recording is not None:
                recording.abort()
            if oracles is not None:
                oracles.discard()
            raise
        finally:
            if input_set is not None:
                input_set.close()
            node.destroy_node()
    notes += routing.notes
    notes.append(f'published {sink.published} messages in {passes} pass{"es" if passes != 1 else ""}'
                 + (f' (stopped by {stop.reason})' if stop else ''))
    for topic, msgtype in sorted(sink.skipped.items()):
        notes.append(f'{topic} not published: {msgtype} has no Python bindings here (recorded only)')
    result = RunResult(scenario, list(inputs), record, seed, total, notes, mode='play')
    if oracles is not None:
        oracles.fill(result)
    return result


def _add(total: RunStats, stats: RunStats) -> None:
    """Fold one pass into the totals (first pass sets the origin)."""
    total.input_messages += stats.input_messages
    total.output_messages += stats.output_messages
    if total.first_time is None:
        total.first_time, total.origin = stats.first_time, stats.origin
    total.last_time = stats.last_time
    total.last_output_time = stats.last_output_time
    for topic, count in stats.per_topic_out.items():
        total.per_topic_out[topic] = total.per_topic_out.get(topic, 0) + count
    total.events.extend(stats.events)
