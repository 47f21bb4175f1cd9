"""Python API: what the command line, the pytest plugin and user code call.

Arguments in, the run loop called, a `RunResult` out:

    result = bagfault.api.run('scenario.yaml', ['my_bag'], 'out.mcap', seed=1)
    assert not result.failed

Every error is a `bagfault.errors.BagfaultError`. Live entry points
(`proxy`, `play`, `record`) need rclpy and stop when the `StopFlag` they
are given is set, or on SIGINT/SIGTERM in the main thread.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

from bagfault.engine.offline import check_recording, run_to_file
from bagfault.engine.result import RunResult
from bagfault.engine.scheduler import Activation
from bagfault.engine.stop import StopFlag
from bagfault.errors import BagfaultError, ScenarioError, UsageError
from bagfault.io.outputs import check_output
from bagfault.scenario import Scenario, load_scenario

if TYPE_CHECKING:
    from collections.abc import Sequence

    from bagfault.engine.offline import Progress
    from bagfault.engine.run import Observer
    from bagfault.live.recorder import RecordResult

DEFAULT_SEED = 0
SEED_MAX = 2**64 - 1


def scenario_of(scenario: Scenario | str | Path) -> Scenario:
    """A loaded scenario, or the file loaded and validated."""
    return scenario if isinstance(scenario, Scenario) else load_scenario(scenario)


def seed_of(scenario: Scenario, seed: int | None) -> int:
    """The seed given, else the scenario's `seed`, else DEFAULT_SEED."""
    if seed is None:
        return scenario.seed if scenario.seed is not None else DEFAULT_SEED
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed <= SEED_MAX:
        raise UsageError(f'--seed {seed}: must be an integer from 0 to {SEED_MAX}')
    return seed


def _seconds(option: str, value: float) -> float:
    if not math.isfinite(value) or value < 0:
        raise UsageError(f'{option} {value}: must be a finite number of seconds, 0 or more')
    return float(value)


def _paths(inputs: Sequence[str | Path]) -> list[Path]:
    paths = [Path(p) for p in inputs]
    if not paths:
        raise UsageError('no input bag given')
    return paths


def _check_output(output: Path, what: str, inputs: Sequence[Path], scenario: Scenario | None) -> None:
    protected = [('the input', p) for p in inputs]
    if scenario is not None and scenario.source is not None:
        protected.append(('the scenario', scenario.source))
    check_output(output, what, protected)


def _activations(scenario: Scenario, texts: Sequence[str | Activation]) -> list[Activation]:
    out = []
    for text in texts:
        try:
            activation = text if isinstance(text, Activation) else Activation.parse(text)
        except ValueError as exc:
            raise UsageError(f'--activate {exc}') from None
        if scenario.fault(activation.fault_id) is None:
            known = ', '.join(f.id for f in scenario.faults) or 'none'
            raise UsageError(f'--activate {activation.fault_id}: no such fault in {scenario.name} (faults: {known})')
        out.append(activation)
    return out


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
    progress: Progress | None = None,
    observers: Sequence[Observer] = (),
    salvage: bool = False,
    msg_paths: Sequence[str | Path] = (),
) -> RunResult:
    """Inject the scenario's faults into the inputs and write the output MCAP.

    `observers` see every output record in time order (report collectors). Corruption the file formats
    detect (CRCs, record lengths, impossible rows) stops the run; with `salvage` what can be read is copied
    and every skipped part is a warning.
    """
    loaded = scenario_of(scenario)
    paths = _paths(inputs)
    out = Path(output)
    _check_output(out, 'output', paths, loaded)
    return run_to_file(loaded, paths, out, seed=seed_of(loaded, seed), activations=_activations(loaded, activate),
                       start_offset=_seconds('--start', start_offset), compression=compression, batch=batch,
                       progress=progress, observers=observers, salvage=salvage,
                       msg_paths=[Path(p) for p in msg_paths])


def check(
    scenario: Scenario | str | Path,
    recording: str | Path,
    *,
    start_offset: float = 0.0,
    observers: Sequence[Observer] = (),
    progress: Progress | None = None,
    salvage: bool = False,
    msg_paths: Sequence[str | Path] = (),
) -> RunResult:
    """Evaluate the scenario's assertions (and fault manager) on an existing recording; inject nothing."""
    return check_recording(scenario_of(scenario), Path(recording), start_offset=_seconds('--start', start_offset),
                           observers=observers, progress=progress, salvage=salvage,
                           msg_paths=[Path(p) for p in msg_paths])


def proxy(
    scenario: Scenario | str | Path,
    *,
    record: str | Path | None = None,
    seed: int | None = None,
    use_sim_time: bool = False,
    stop: StopFlag | None = None,
) -> RunResult:
    """Live proxy (`/x_raw` -> faults -> `/x`) until SIGINT/SIGTERM or `stop.set()`; needs rclpy."""
    from bagfault.live import require_rclpy  # noqa: PLC0415 - rclpy is an optional extra

    require_rclpy()
    from bagfault.live.proxy import run_proxy  # noqa: PLC0415

    loaded = scenario_of(scenario)
    out = Path(record) if record is not None else None
    if out is not None:
        _check_output(out, 'recording', [], loaded)
    return run_proxy(loaded, seed=seed_of(loaded, seed), record=out, use_sim_time=use_sim_time,
                     stop=stop if stop is not None else StopFlag())


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
    stop: StopFlag | None = None,
) -> RunResult:
    """Publish bags on their topics through the scenario's faults (a plain player without one); needs rclpy."""
    from bagfault.live import require_rclpy  # noqa: PLC0415 - rclpy is an optional extra

    require_rclpy()
    from bagfault.live.player import run_play  # noqa: PLC0415

    loaded = scenario_of(scenario) if scenario is not None else Scenario([], [], [])
    paths = _paths(inputs)
    if not (math.isfinite(rate) and rate > 0):
        raise UsageError(f'--rate {rate:g}: must be above 0')
    out = Path(record) if record is not None else None
    if out is not None:
        _check_output(out, 'recording', paths, loaded)
    return run_play(loaded, paths, seed=seed_of(loaded, seed), rate=rate, clock=clock, loop=loop, record=out,
                    delay=_seconds('--delay', delay), stop=stop if stop is not None else StopFlag())


def record(
    topics: Sequence[str],
    output: str | Path,
    *,
    every: bool = False,
    duration: float | None = None,
    use_sim_time: bool = False,
    stop: StopFlag | None = None,
) -> RecordResult:
    """Record live topics (or all with `every`) into an MCAP until `duration`, a signal or `stop.set()`."""
    from bagfault.live import require_rclpy  # noqa: PLC0415 - rclpy is an optional extra

    require_rclpy()
    from bagfault.live.recorder import run_record  # noqa: PLC0415

    out = Path(output)
    _check_output(out, 'output', [], None)
    if duration is not None and not (math.isfinite(duration) and duration > 0):
        raise UsageError(f'--duration {duration:g}: must be above 0')
    if not topics and not every:
        raise UsageError('record: give topics to record or --all')
    return run_record(list(topics), out, every=every, duration=duration, use_sim_time=use_sim_time,
                      stop=stop if stop is not None else StopFlag())


def validate(paths: Sequence[str | Path], *, strict: bool = False) -> list[Scenario]:
    """Load and validate scenario files; raise ScenarioError with every problem of all files."""
    scenarios, problems = [], []
    for path in paths:
        try:
            scenarios.append(load_scenario(path, strict=strict))
        except ScenarioError as exc:
            problems.extend(exc.problems)
    if problems:
        raise ScenarioError(problems)
    return scenarios


__all__ = ['BagfaultError', 'RunResult', 'StopFlag', 'check', 'load_scenario', 'play', 'proxy', 'record', 'run',
           'validate']
