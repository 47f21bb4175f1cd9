"""Python API: what the command line and the tests call.

    result = bagfault.api.run('scenario.yaml', ['my_bag'], 'out.mcap', seed=1)
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from bagfault import __version__
from bagfault.engine import EngineError
from bagfault.assertions.base import AssertionResult
from bagfault.assertions.runner import AssertionRunner
from bagfault.engine.pipeline import Observer, Pipeline, RunStats
from bagfault.engine.routing import build_routing
from bagfault.engine.scheduler import Activation
from bagfault.errors import BagfaultError
from bagfault.events import AssertionEvent, FaultEvent, ScenarioStatus
from bagfault.io import OutputError
from bagfault.io.mcap_sink import McapSink
from bagfault.io.sources import InputSet, fingerprint
from bagfault.scenario import load_scenario as load_scenario
from bagfault.io.types import TypeCatalog
from bagfault.scenario import Scenario

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

DEFAULT_SEED = 0


@dataclass
class RunResult:
    """Everything a run (or a check) produced besides the output file."""

    scenario: Scenario
    inputs: list[Path]
    output: Path | None
    seed: int
    stats: RunStats
    notes: list[str] = field(default_factory=list)
    assertions: list[AssertionResult] = field(default_factory=list)
    assertion_events: list[AssertionEvent | ScenarioStatus] = field(default_factory=list)
    mode: str = 'run'
    fault_manager: dict[str, Any] | None = None

    @property
    def failed(self) -> bool:
        """True when an assertion failed: exit code 1."""
        return any(r.state == 'failed' for r in self.assertions)


def _scenario(scenario: Scenario | str | Path) -> Scenario:
    return scenario if isinstance(scenario, Scenario) else load_scenario(scenario)


def _seed(scenario: Scenario, seed: int | None) -> int:
    """The --seed given, else the scenario's `seed`, else DEFAULT_SEED."""
    if seed is not None:
        return seed
    return scenario.seed if scenario.seed is not None else DEFAULT_SEED


def _check_paths(inputs: Sequence[Path], output: Path) -> None:
    out = output.resolve()
    for path in inputs:
        source = path.resolve()
        if out == source:
            raise OutputError(f'{output}: output path is the input {path}; choose another name')
        if source.is_dir() and source in out.parents:
            raise OutputError(f'{output}: output would be written inside the input bag {path}; choose another folder')


def _activations(scenario: Scenario, texts: Sequence[str | Activation]) -> list[Activation]:
    out = []
    for text in texts:
        try:
            activation = text if isinstance(text, Activation) else Activation.parse(text)
        except ValueError as exc:
            raise EngineError(f'--activate {exc}') from None
        if scenario.fault(activation.fault_id) is None:
            known = ', '.join(f.id for f in scenario.faults) or 'none'
            raise EngineError(f'--activate {activation.fault_id}: no such fault in {scenario.name} (faults: {known})')
        out.append(activation)
    return out


def provenance(scenario: Scenario, inputs: Sequence[Path], seed: int, activations: Sequence[Activation],
               start_offset: float) -> dict[str, str]:
    """The `bagfault` metadata record: enough to reproduce the run from its output."""
    return {
        'tool': 'bagfault',
        'version': __version__,
        'seed': str(seed),
        'scenario': scenario.name,
        'scenario_sha256': hashlib.sha256(scenario.text.encode()).hexdigest(),
        'inputs': json.dumps(
            [{'name': p.name, 'files': [f.__dict__ for f in fingerprint(p)]} for p in inputs], sort_keys=True
        ),
        'activate': json.dumps([a.__dict__ for a in activations], sort_keys=True),
        'start_offset': repr(float(start_offset)),
    }


def run(
    scenario: Scenario | str | Path,
    inputs: Sequence[str | Path],
    output: str | Path,
    *,
    seed: int | None = None,
    activate: Sequence[str | Activation] = (),
    start_offset: float = 0.0,
    compression: str = 'zstd',
    batch: bool = True,
    progress: Callable[[int, int], None] | None = None,
    observers: Sequence[Observer] = (),
) -> RunResult:
    """Inject the scenario's faults into the inputs and write the output MCAP.

    `observers` see every output record in time order (report collectors).
    """
    loaded = _scenario(scenario)
    paths = [Path(p) for p in inputs]
    out = Path(output)
    if not paths:
        raise EngineError('no input bag given')
    _check_paths(paths, out)
    activations = _activations(loaded, activate)
    used_seed = _seed(loaded, seed)

    input_set = InputSet(paths)
    if progress is not None and hasattr(progress, 'begin'):
        progress.begin(input_set.start_time, input_set.end_time, input_set.message_count)
    try:
        catalog = TypeCatalog(input_set.channels, input_set.ros_distro)
        sink = McapSink(out, compression=compression)
        try:
            sink.add_metadata('bagfault', provenance(loaded, paths, used_seed, activations, start_offset))
            sink.add_attachment(loaded.name, 'application/yaml', loaded.text.encode())
            routing, pipeline, oracles = wire(
                input_set, loaded, catalog, sink, seed=used_seed, blackbox_base=out, activations=activations,
                start_offset=start_offset, batch=batch, progress=progress, observers=observers,
            )
            stats = pipeline.run()
            stats.replaced_topics = routing.replaced
            sink.finish()
            oracles.publish()
        except BaseException:
            sink.abort()
            if 'oracles' in locals():
                oracles.discard()
            raise
    finally:
        input_set.close()
    notes = list(loaded.warnings) + routing.notes
    if stats.input_messages == 0:
        notes.append('the input holds no messages; the output has channels only')
    result = RunResult(loaded, paths, out, used_seed, stats, notes)
    oracles.fill(result)
    return result


def wire(
    inputs: InputSet,
    scenario: Scenario,
    catalog: TypeCatalog,
    sink: Any,
    *,
    seed: int,
    blackbox_base: Path | None,
    **options: Any,
) -> tuple[Any, Pipeline, Oracles]:
    """Routing, pipeline and oracles of one pass over the inputs into a sink (a file, or live topics)."""
    routing = build_routing(inputs, scenario, catalog, sink, scenario.name)
    pipeline = Pipeline(inputs, scenario, sink, catalog, routing.routes, routing.copies, seed=seed, **options)
    oracles = Oracles(scenario, routing.schemas, catalog, pipeline.write_event, blackbox_base=blackbox_base)
    pipeline.observers[:0] = oracles.observers
    for kind in oracles.event_kinds:
        pipeline.event_channel(kind)
    return routing, pipeline, oracles


class Oracles:
    """The observers that judge a run: fault manager first, then the assertion runner."""

    def __init__(self, scenario: Scenario, schemas: dict[str, tuple[str, str, str]], catalog: TypeCatalog,
                 emit: Callable[..., None], blackbox_base: Path | None = None) -> None:
        from bagfault.fault_manager.model import FaultManagerEvent  # noqa: PLC0415
        from bagfault.fault_manager.observer import FaultManagerObserver  # noqa: PLC0415

        kinds: list[Any] = [FaultEvent]
        self.fault_manager = None
        if scenario.fault_manager_config is not None:
            catalog.add_definition(FaultManagerEvent.msgtype, FaultManagerEvent.definition)
            self.fault_manager = FaultManagerObserver(scenario.fault_manager_config, scenario, schemas, catalog, emit,
                                                      blackbox_base)
            kinds.append(FaultManagerEvent)
        self.runner = None
        if scenario.assertions:
            kinds += [AssertionEvent, ScenarioStatus]
            for kind in kinds:
                catalog.add_definition(kind.msgtype, kind.definition)
            topics = {topic: entry[0] for topic, entry in schemas.items()}
            topics.update({kind.topic: kind.msgtype for kind in kinds})
            self.runner = AssertionRunner(scenario, topics, catalog, emit, self.fault_manager)
            if self.fault_manager is not None:
                self.fault_manager.status_listeners.append(self.runner.on_fault_status)
        self.event_kinds = [k for k in kinds if k not in (FaultEvent,)]
        self.observers: list[Observer] = [o for o in (self.fault_manager, self.runner) if o is not None]

    def publish(self) -> None:
        """The output is complete: black boxes take their names."""
        if self.fault_manager is not None:
            self.fault_manager.snapshots.publish()

    def discard(self) -> None:
        """The run failed: remove black boxes."""
        if self.fault_manager is not None:
            self.fault_manager.snapshots.discard()

    def fill(self, result: RunResult) -> None:
        """Copy verdicts into the result."""
        if self.runner is not None:
            result.assertions, result.assertion_events = self.runner.results, self.runner.events
        if self.fault_manager is not None:
            result.fault_manager = self.fault_manager.summary()


def check(
    scenario: Scenario | str | Path,
    recording: str | Path,
    *,
    start_offset: float = 0.0,
    observers: Sequence[Observer] = (),
    progress: Callable[[int, int], None] | None = None,
) -> RunResult:
    """Evaluate the scenario's assertions on an existing recording; inject nothing.

    Fault events recorded on /fault_injection/events drive `fault_event` and
    `during` conditions; bag time zero is the recording's first message.
    """
    loaded = _scenario(scenario)
    path = Path(recording)
    inputs = InputSet([path])
    if progress is not None and hasattr(progress, 'begin'):
        progress.begin(inputs.start_time, inputs.end_time, inputs.message_count)
    try:
        catalog = TypeCatalog(inputs.channels, inputs.ros_distro)
        topics = {c.topic: c.msgtype for c in inputs.channels}
        schemas = {c.topic: (c.msgtype, c.schema_encoding, c.schema_text) for c in inputs.channels}
        collected: list[Any] = []
        oracles = Oracles(loaded, schemas, catalog, collected.append)
        watchers: list[Observer] = [*oracles.observers, *observers]
        event_codec = catalog.codec(FaultEvent.msgtype) if FaultEvent.topic in topics else None
        stats = RunStats()
        for channel_index, log_time, _, data in inputs.messages():
            if stats.origin is None:
                stats.first_time, stats.origin = log_time, log_time + round(start_offset * 1e9)
                for watcher in watchers:
                    watcher.start(stats.origin)
            channel = inputs.channels[channel_index]
            stats.input_messages += 1
            stats.last_time = stats.last_output_time = log_time
            if channel.topic == FaultEvent.topic and event_codec is not None:
                message = event_codec.decode(data)
                event = FaultEvent(log_time, message.fault_id, message.injector_id, message.state, message.source,
                                   message.details)
                stats.events.append(event)
                for watcher in watchers:
                    watcher.on_event(event)
            for watcher in watchers:
                watcher.on_message(channel.topic, log_time, data)
            stats.per_topic_out[channel.topic] = stats.per_topic_out.get(channel.topic, 0) + 1
            if progress is not None and stats.input_messages % 4096 == 0:
                progress(stats.input_messages, log_time)
        for watcher in watchers:
            watcher.finish(stats.last_time if stats.last_time is not None else 0)
    finally:
        inputs.close()
    result = RunResult(loaded, [path], None, 0, stats, list(loaded.warnings), mode='check')
    oracles.fill(result)
    if stats.input_messages == 0:
        result.notes.append('the recording holds no messages')
    return result


def _record_path(record: str | Path | None) -> Path | None:
    if record is None:
        return None
    path = Path(record)
    if not path.parent.is_dir():
        raise OutputError(f'{path}: folder {path.parent} does not exist')
    return path


def proxy(
    scenario: Scenario | str | Path,
    *,
    record: str | Path | None = None,
    seed: int | None = None,
    use_sim_time: bool = False,
    stop: Any = None,
) -> RunResult:
    """Live proxy (`/x_raw` -> faults -> `/x`) until SIGINT/SIGTERM or `stop.set()`; needs rclpy."""
    from bagfault.live import require_rclpy  # noqa: PLC0415

    require_rclpy()
    from bagfault.live.proxy import run_proxy  # noqa: PLC0415

    loaded = _scenario(scenario)
    used_seed = _seed(loaded, seed)
    return run_proxy(loaded, seed=used_seed, record=_record_path(record), use_sim_time=use_sim_time, stop=stop)


def play(
    scenario: Scenario | str | Path | None,
    inputs: Sequence[str | Path],
    *,
    rate: float = 1.0,
    clock: bool = False,
    loop: bool = False,
    record: str | Path | None = None,
    seed: int | None = None,
    delay: float = 0.5,
    stop: Any = None,
) -> RunResult:
    """Publish bags on their topics through the scenario's faults (a plain player without one); needs rclpy."""
    from bagfault.live import require_rclpy  # noqa: PLC0415

    require_rclpy()
    from bagfault.live.player import run_play  # noqa: PLC0415

    loaded = _scenario(scenario) if scenario is not None else Scenario([], [], [])
    paths = [Path(p) for p in inputs]
    if not paths:
        raise EngineError('no input bag given')
    out = _record_path(record)
    if out is not None:
        _check_paths(paths, out)
    used_seed = _seed(loaded, seed)
    return run_play(loaded, paths, seed=used_seed, rate=rate, clock=clock, loop=loop, record=out, delay=delay,
                    stop=stop)


def record(
    topics: Sequence[str],
    output: str | Path,
    *,
    every: bool = False,
    duration: float | None = None,
    use_sim_time: bool = False,
    stop: Any = None,
) -> Any:
    """Record live topics (or all with `every`) into an MCAP; needs rclpy. Returns a RecordResult."""
    from bagfault.live import require_rclpy  # noqa: PLC0415

    require_rclpy()
    from bagfault.live.recorder import run_record  # noqa: PLC0415

    out = _record_path(output)
    assert out is not None
    if out.is_dir():
        raise OutputError(f'{out}: is a directory; give a file name such as out.mcap')
    if duration is not None and duration <= 0:
        raise EngineError(f'--duration {duration:g}: must be above 0')
    return run_record(list(topics), out, every=every, duration=duration, use_sim_time=use_sim_time, stop=stop)


def validate(paths: Sequence[str | Path]) -> list[Scenario]:
    """Load and validate scenario files; raise ScenarioError with every problem of all files."""
    from bagfault.scenario import ScenarioError  # noqa: PLC0415

    scenarios, problems = [], []
    for path in paths:
        try:
            scenarios.append(load_scenario(path))
        except ScenarioError as exc:
            problems.extend(exc.problems)
    if problems:
        raise ScenarioError(problems)
    return scenarios


__all__ = ['BagfaultError', 'RunResult', 'check', 'play', 'proxy', 'record', 'run', 'validate']
