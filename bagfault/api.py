"""Python API: what the command line, the pytest plugin and user code call.

Arguments in, the run loop called, a `RunResult` out:

    result = bagfault.api.run('scenario.yaml', ['my_bag'], 'out.mcap', seed=1)
    assert not result.failed

Every error is a `bagfault.errors.BagfaultError`. Live entry points
(`proxy`, `play`, `record`) need rclpy and stop when the `StopFlag` they
are given is set, or on SIGINT/SIGTERM in the main thread.
"""

from __future__ import annotations

import contextlib
import glob
import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from bagfault.engine.activation import Activation
from bagfault.engine.options import RunOptions
from bagfault.engine.result import RunResult
from bagfault.engine.stop import StopFlag
from bagfault.errors import BagfaultError, OutputError, Problem, ScenarioError, UsageError
from bagfault.io.outputs import PUBLISHED, PartialFile, Protected, check_derived, check_output, write_atomic
from bagfault.report.files import ReportPaths
from bagfault.scenario import Scenario, load_scenario
from bagfault.scenario.loader import build_scenario, read_scenario
from bagfault.spec.names import absolute_topic
from bagfault.spec.system import SystemUnderTest, ready_spec, system_from
from bagfault.spec.yamlnodes import format_path

if TYPE_CHECKING:
    from collections.abc import Collection, Mapping, Sequence

    from bagfault.campaign.model import Campaign
    from bagfault.campaign.runner import CampaignResult
    from bagfault.engine.offline import Progress
    from bagfault.engine.run import Observer
    from bagfault.explore import ExploreResult
    from bagfault.explore.draw import Strategy
    from bagfault.explore.shrink import ShrinkMode
    from bagfault.io.leading_copy import LeadingCopy
    from bagfault.io.recover import Recovered
    from bagfault.live.recorder import RecordResult
    from bagfault.live.viewing import OpenView
    from bagfault.progress import ExploreProgress, JobProgress
    from bagfault.spec.yamlnodes import PathKey

DEFAULT_SEED = 0
SEED_MAX = 2**64 - 1


def scenario_of(scenario: Scenario | str | Path, *, space: bool = False, mode: str = '',
                offers: Collection[str] = (), strict: bool = False) -> Scenario:
    """A loaded scenario, or the file loaded and validated; one with an `explore:` section only where `space`
    (its assertions name faults that only `bagfault explore` draws); injectors of the system or its clock only
    where the `mode` offers what they act on (`offers`: 'system', 'clock')."""
    loaded = scenario if isinstance(scenario, Scenario) else load_scenario(scenario, strict=strict)
    if loaded.explore is not None and not space:
        raise UsageError(f'{loaded.source or loaded.name}: has an explore: section, a fault space: '
                         f'`bagfault explore` searches it (run or test one of the scenarios it writes)')
    if mode:
        _check_offers(loaded, mode, offers)
    return loaded


def _check_offers(loaded: Scenario, mode: str, offers: Collection[str]) -> None:
    """UsageError for an injector of the system or its clock where the mode offers neither."""
    from bagfault.injectors.registry import get_injector_type  # noqa: PLC0415
    from bagfault.injectors.system import SystemInjector  # noqa: PLC0415

    for injector in loaded.injectors:
        cls = get_injector_type(injector.type)
        if cls is not None and issubclass(cls, SystemInjector) and cls.acts_on not in offers:
            raise UsageError(f'{loaded.source or loaded.name}: injector {injector.id!r} ({injector.type}) needs '
                             f'{cls.needs}; `{mode}` has none')


def _view(address: str | None) -> OpenView | None:
    """The Foxglove view's opener for `--foxglove ADDRESS` (the live commands and the closed loop receive it)."""
    if address is None:
        return None
    from bagfault.view.foxglove import opener  # noqa: PLC0415 - foxglove-sdk is an optional extra

    return opener(address)


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


def _check_output(output: Path, what: str, inputs: Sequence[Path], scenario: Scenario | None, *,
                  force: bool = False, msg_paths: Sequence[str | Path] = ()) -> None:
    """Before anything runs: the output, and the black boxes named after it, replace nothing they must not."""
    protected = Protected.of(_protected(input=inputs, scenario=scenario.source if scenario is not None else None,
                                        **{'--msg-path': msg_paths}))
    check_output(output, what, protected, force=force)
    check_derived(output, f'{glob.escape(output.stem)}.blackbox.*.mcap', f'a black box of {output}', protected,
                  force=force)


def _protected(**paths: str | Path | Sequence[str | Path] | None) -> list[tuple[str, Path]]:
    """What reports must not replace: a command's inputs, scenario and main output (`name=path(s)`)."""
    out: list[tuple[str, Path]] = []
    for name, value in paths.items():
        if value is not None:
            out += [(f'the {name}', Path(p)) for p in ([value] if isinstance(value, (str, Path)) else value)]
    return out


def _source(scenario: Scenario | str | Path | None) -> Path | None:
    return scenario.source if isinstance(scenario, Scenario) else None if scenario is None else Path(scenario)


def _collectors(reports: ReportPaths | None, protected: list[tuple[str, Path]]) -> list[Observer]:
    """Before the run: the reports' paths checked against what the command reads and writes; the observers
    they need during it."""
    if reports is None:
        return []
    reports.check(protected)
    return reports.collectors()


def _reported(result: RunResult, reports: ReportPaths | None, collectors: Sequence[Observer]) -> RunResult:
    if reports is not None:
        reports.write(result, collectors)
    return result


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
    compression_level: int | None = None,
    batch: bool = True,
    progress: Progress | None = None,
    observers: Sequence[Observer] = (),
    salvage: bool = False,
    msg_paths: Sequence[str | Path] = (),
    chunk_copy: bool = True,
    force: bool = False,
    verify: bool = False,
    strict: bool = False,
    reports: ReportPaths | None = None,
) -> RunResult:
    """Inject the scenario's faults into the inputs and write the output MCAP (and the `reports` asked for).

    `observers` see every output record in time order (report collectors). Corruption the file formats
    detect (CRCs, record lengths, impossible rows) stops the run; with `salvage` what can be read is copied
    and every skipped part is a warning. With `chunk_copy` (a single MCAP input), chunks nothing touches
    are copied as they are (checked against their indexes, not decompressed; `verify` also decompresses
    and counts them on a second thread); False takes the reference path that decompresses and rewrites every
    chunk. An existing output (or black box) that bagfault did not write is refused unless `force`.
    `compression_level` applies to the chunks bagfault writes (copied chunks keep theirs); None: the MCAP C++
    writer's default (zstd 1, lz4 0). A scenario file is read once, with `strict` warnings as errors.

    The input's leading chunks start copying into the output as soon as the scenario's YAML is read, on a
    guess (`engine/lead.py`), beside the imports and the setup: this module imports the engine only then.
    """
    collectors = _collectors(reports, _protected(input=inputs, scenario=_source(scenario), output=output,
                                                 **{'--msg-path': msg_paths}))
    observers = [*observers, *collectors]
    document = scenario if isinstance(scenario, Scenario) else read_scenario(scenario)
    paths, out = _paths(inputs), Path(output)
    with contextlib.ExitStack() as stack:
        file, lead = _lead(document.located.data, paths, out, stack, start_offset=start_offset, activate=activate,
                           observers=observers, copying=chunk_copy and batch)
        from bagfault.engine.offline import run_to_file  # noqa: PLC0415 - after the leading copy started
        from bagfault.io.mcap_sink import check_level  # noqa: PLC0415

        built = document if isinstance(document, Scenario) else build_scenario(document, strict=strict)
        loaded = scenario_of(built, mode='run')
        if compression_level is not None:
            check_level(out, compression, compression_level)
        _check_output(out, 'output', paths, loaded, force=force, msg_paths=msg_paths)
        options = RunOptions(seed=seed_of(loaded, seed), activations=tuple(_activations(loaded, activate)),
                             start_offset=_seconds('--start', start_offset), compression=compression,
                             compression_level=compression_level, batch=batch, salvage=salvage,
                             msg_paths=tuple(Path(p) for p in msg_paths), chunk_copy=chunk_copy, verify=verify)
        if file is None:
            file = stack.enter_context(PartialFile(out))
        result = run_to_file(loaded, paths, file, options, progress=progress, observers=observers, lead=lead)
    return _reported(result, reports, collectors)


def _lead(document: object, paths: Sequence[Path], out: Path, stack: contextlib.ExitStack[bool | None], *,
          start_offset: float, activate: Sequence[str | Activation], observers: Sequence[Observer],
          copying: bool) -> tuple[PartialFile | None, LeadingCopy | None]:
    """The output's partial file and a leading copy into it, started before anything heavy is imported; (None,
    None) when no copy is guessed useful, or the output or the options are wrong (said later, in their words)."""
    from bagfault.engine.lead import start_lead, wanted_topics  # noqa: PLC0415 - imports nothing heavy

    wanted = wanted_topics(observers)
    if not copying or wanted is None or not _one_file(paths) or not (math.isfinite(start_offset) and start_offset >= 0):
        return None, None
    try:
        activations = [a if isinstance(a, Activation) else Activation.parse(a) for a in activate]
        file = PartialFile(out)
    except (ValueError, OutputError):
        return None, None
    stack.callback(file.close)
    lead = start_lead(document, paths[0], file, start_offset=start_offset, activations=activations,
                      observed=sorted(wanted))
    if lead is not None:
        stack.callback(lead.close)
    return file, lead


def _one_file(paths: Sequence[Path]) -> bool:
    """One input, a file (a leading copy's case: an MCAP of its own)."""
    return len(paths) == 1 and paths[0].is_file()


def check(
    scenario: Scenario | str | Path,
    recording: str | Path,
    *,
    start_offset: float = 0.0,
    observers: Sequence[Observer] = (),
    progress: Progress | None = None,
    salvage: bool = False,
    msg_paths: Sequence[str | Path] = (),
    strict: bool = False,
    reports: ReportPaths | None = None,
) -> RunResult:
    """Evaluate the scenario's assertions (and fault manager) on an existing recording; inject nothing."""
    from bagfault.engine.offline import check_recording  # noqa: PLC0415

    collectors = _collectors(reports, _protected(recording=recording, scenario=_source(scenario),
                                                 **{'--msg-path': msg_paths}))
    result = check_recording(scenario_of(scenario, strict=strict), Path(recording),
                             start_offset=_seconds('--start', start_offset), observers=[*observers, *collectors],
                             progress=progress, salvage=salvage, msg_paths=[Path(p) for p in msg_paths])
    return _reported(result, reports, collectors)


def proxy(
    scenario: Scenario | str | Path,
    *,
    record: str | Path | None = None,
    seed: int | None = None,
    use_sim_time: bool = False,
    stop: StopFlag | None = None,
    ros_args: Sequence[str] = (),
    foxglove: str | None = None,
    force: bool = False,
    strict: bool = False,
    reports: ReportPaths | None = None,
) -> RunResult:
    """Live proxy (`/x_raw` -> faults -> `/x`) until SIGINT/SIGTERM or `stop.set()`; needs rclpy.

    `ros_args` are what follows `--ros-args` on a ROS command line (remaps, `__node`, `__ns`, `-p`,
    `--params-file`): they apply to the proxy's node."""
    from bagfault.live import require_rclpy  # noqa: PLC0415 - rclpy is an optional extra

    require_rclpy()
    from bagfault.live.proxy import run_proxy  # noqa: PLC0415

    collectors = _collectors(reports, _protected(scenario=_source(scenario), recording=record))
    loaded = scenario_of(scenario, mode='proxy', strict=strict)
    out = Path(record) if record is not None else None
    if out is not None:
        _check_output(out, 'recording', [], loaded, force=force)
    result = run_proxy(loaded, seed=seed_of(loaded, seed), record=out, use_sim_time=use_sim_time,
                       stop=stop if stop is not None else StopFlag(), ros_args=list(ros_args), view=_view(foxglove))
    return _reported(result, reports, collectors)


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
    wait_for: Sequence[str] = (),
    remap: Sequence[str] = (),
    topics: Sequence[str] = (),
    start_offset: float = 0.0,
    clock_hz: float = 100.0,
    ros_args: Sequence[str] = (),
    foxglove: str | None = None,
    force: bool = False,
    strict: bool = False,
    reports: ReportPaths | None = None,
) -> RunResult:
    """Publish bags on their topics through the scenario's faults (a plain player without one); needs rclpy,
    but for `foxglove` ('HOST:PORT'), which shows the play in Foxglove with its faults as parameters and
    playback controls, with ROS if rclpy is installed and without it otherwise.

    `wait_for` topics (or ['all']) must have a subscriber before the first message (instead of `delay`);
    `remap` ('FROM:=TO') renames published topics, `topics` plays only those, `start_offset` skips the bag's
    first seconds, `clock_hz` is the /clock rate while waiting; `ros_args` apply to the player's node."""
    from bagfault.live import rclpy_available, require_rclpy  # noqa: PLC0415 - rclpy is an optional extra

    ros = rclpy_available()
    if foxglove is None:
        require_rclpy()
    from bagfault.live.player import run_play  # noqa: PLC0415

    collectors = _collectors(reports, _protected(input=inputs, scenario=_source(scenario), recording=record))
    loaded = (scenario_of(scenario, mode='play' if clock else 'play without --clock',
                          offers=('clock',) if clock else (), strict=strict)
              if scenario is not None else Scenario([], [], []))
    paths = _paths(inputs)
    _check_rate(rate)
    out = Path(record) if record is not None else None
    if out is not None:
        _check_output(out, 'recording', paths, loaded, force=force)
    if not (math.isfinite(clock_hz) and 0 < clock_hz <= 10_000):
        raise UsageError(f'--clock {clock_hz:g}: must be a rate in Hz above 0, at most 10000')
    result = run_play(loaded, paths, seed=seed_of(loaded, seed), rate=rate, clock=clock, loop=loop, record=out,
                      delay=_seconds('--delay', delay), stop=stop if stop is not None else StopFlag(),
                      wait_for=[t if t == 'all' else absolute_topic(t) for t in wait_for],
                      topics=[absolute_topic(t) for t in topics],
                      start_offset=_seconds('--start-offset', start_offset), clock_hz=clock_hz,
                      ros_args=[*_remap_args(remap), *ros_args], view=_view(foxglove), ros=ros)
    return _reported(result, reports, collectors)


def _check_rate(rate: float) -> None:
    if not (math.isfinite(rate) and rate > 0):
        raise UsageError(f'--rate {rate:g}: must be above 0')


def _check_workers(workers: int | None) -> None:
    if workers is not None and workers < 1:
        raise UsageError(f'--workers {workers}: must be 1 or more')


def _remap_args(remap: Sequence[str]) -> list[str]:
    """`--remap /FROM:=/TO` options as the node's ROS arguments (`-r FROM:=TO`)."""
    mapped = []
    for item in remap:
        source, sep, target = item.partition(':=')
        if not (sep and source.startswith('/') and target.startswith('/')):
            raise UsageError(f'--remap {item}: must be /FROM:=/TO')
        mapped += ['-r', f'{source}:={target}']
    return mapped


def record(
    topics: Sequence[str],
    output: str | Path,
    *,
    every: bool = False,
    duration: float | None = None,
    use_sim_time: bool = False,
    stop: StopFlag | None = None,
    ros_args: Sequence[str] = (),
    force: bool = False,
) -> RecordResult:
    """Record live topics (or all with `every`) into an MCAP until `duration`, a signal or `stop.set()`."""
    from bagfault.live import require_rclpy  # noqa: PLC0415 - rclpy is an optional extra

    require_rclpy()
    from bagfault.live.recorder import run_record  # noqa: PLC0415

    out = Path(output)
    _check_output(out, 'output', [], None, force=force)
    if duration is not None and not (math.isfinite(duration) and duration > 0):
        raise UsageError(f'--duration {duration:g}: must be above 0')
    if not topics and not every:
        raise UsageError('record: give topics to record or --all')
    return run_record(list(topics), out, every=every, duration=duration, use_sim_time=use_sim_time,
                      stop=stop if stop is not None else StopFlag(), ros_args=list(ros_args))


def test(
    scenario: Scenario | str | Path,
    inputs: Sequence[str | Path] = (),
    output: str | Path | None = None,
    *,
    system: Mapping[str, object] | None = None,
    seed: int | None = None,
    rate: float = 1.0,
    repeat: int = 1,
    keep_logs: str | Path | None = None,
    stop: StopFlag | None = None,
    foxglove: str | None = None,
    force: bool = False,
    observers: Sequence[Observer] = (),
    strict: bool = False,
    reports: ReportPaths | None = None,
    clock_check: bool = True,
) -> RunResult:
    """Closed loop: start the scenario's system under test on a private ROS domain, play the inputs (default:
    the scenario's `bags`) into it through the faults on sim time, record it, judge it, stop it; needs rclpy.

    `system` holds `system_under_test` keys that replace the scenario's (`env` is added to). With `repeat`
    above 1 the loop runs that many times and the result holds each run in `repeats` and pass rates in its
    assertions; `observers` (report collectors) see the first run. At a `rate` other than 1 the sim clock stands
    still for a second before the first record, to find what the system publishes on wall time; `clock_check`
    False leaves that out (an exploration's runs after its baseline, which looked). Exit code semantics:
    `result.failed` is 1; a BagfaultError (could not run) is 2.
    """
    from bagfault.live import require_rclpy  # noqa: PLC0415 - rclpy is an optional extra

    require_rclpy()
    from bagfault.closedloop.repeat import fold  # noqa: PLC0415
    from bagfault.closedloop.runner import run_test  # noqa: PLC0415

    collectors = _collectors(reports, _protected(input=inputs, scenario=_source(scenario), output=output))
    observers = [*observers, *collectors]
    loaded = scenario_of(scenario, mode='test', offers=('system', 'clock'), strict=strict)
    paths = [Path(p) for p in inputs] or list(loaded.bags)
    if not paths:
        raise UsageError(f'{loaded.name}: no bag given, and the scenario names none under `bags:`')
    under_test = system_of(loaded, system or {})
    _check_rate(rate)
    if isinstance(repeat, bool) or not isinstance(repeat, int) or not 1 <= repeat <= 1000:
        raise UsageError(f'--repeat {repeat}: must be a whole number from 1 to 1000')
    outputs = _run_outputs(output, repeat)
    for path in outputs:
        if path is not None:
            _check_output(path, 'recording', paths, loaded, force=force)
    logs = Path(keep_logs) if keep_logs is not None else None
    flag = stop if stop is not None else StopFlag()
    results = []
    for number, path in enumerate(outputs, 1):
        folder = logs if logs is None or repeat == 1 else logs / f'run{number}'
        results.append(run_test(loaded, paths, path, system=under_test, seed=seed_of(loaded, seed), rate=rate,
                                logs=folder, stop=flag, view=_view(foxglove),
                                observers=observers if number == 1 else (), clock_check=clock_check))
    return _reported(results[0] if repeat == 1 else fold(results), reports, collectors)


def _run_outputs(output: str | Path | None, repeat: int) -> list[Path | None]:
    """Each run's recording: the output, or with `repeat` above 1 OUT.runN.mcap; None where none is kept."""
    if output is None:
        return [None] * repeat
    out = Path(output)
    if repeat == 1:
        return [out]
    return [out.with_name(f'{out.stem}.run{n}{out.suffix}') for n in range(1, repeat + 1)]


def system_of(scenario: Scenario, overrides: Mapping[str, object]) -> SystemUnderTest:
    """The scenario's `system_under_test` with `overrides` in place of its keys (a `ready` condition also in the
    command line's text form, `publisher:/t@5`); ScenarioError if unusable."""
    overrides = _ready_read(overrides)
    problems: list[Problem] = []
    name = str(scenario.source or scenario.name)

    def problem(path: PathKey, message: str) -> None:
        problems.append(Problem(name, 'command line' if overrides else scenario.located.where(path),
                                format_path(path), message))

    base = scenario.source.parent if scenario.source is not None else None
    node = scenario.located.data.get('system_under_test') if isinstance(scenario.located.data, dict) else None
    system = system_from(node, overrides, problem, base)
    if problems or system is None:
        raise ScenarioError(problems)
    if 'cwd' in overrides and isinstance(overrides['cwd'], str):
        system.cwd = Path(overrides['cwd'])  # relative to where the command runs, not to the scenario
    return system


def _ready_read(overrides: Mapping[str, object]) -> Mapping[str, object]:
    """The overrides with `ready` conditions given in the command line's text form read into mappings."""
    ready = overrides.get('ready')
    if not isinstance(ready, list):
        return overrides
    return {**overrides, 'ready': [ready_spec(r) if isinstance(r, str) else r for r in ready]}


def recover(recording: str | Path, output: str | Path | None = None, *, force: bool = False) -> Recovered:
    """A live recording cut short by a kill made a valid MCAP: `recording` is the partial file or the name
    that was requested (its `.NAME.*.partial` is found); `output` defaults to that requested name."""
    from bagfault.io.recover import partial_of, requested_name  # noqa: PLC0415
    from bagfault.io.recover import recover as copy_readable  # noqa: PLC0415

    source = partial_of(Path(recording))
    out = Path(output) if output is not None else requested_name(source)
    check_output(out, 'output', [('the recording', source)], force=force)
    return copy_readable(source, out)


def campaign(file: str | Path | Campaign, directory: str | Path, *, workers: int | None = None,
             ray: str | None = None, resume: bool = False, progress: JobProgress | None = None,
             force: bool = False) -> CampaignResult:
    """Run a campaign file's jobs (bag x sweep point x seed, and the search) on a local pool of `workers`
    processes (default: one per core) or, with `ray` ('' for a local instance, or a cluster address), as Ray
    tasks; results, tables and report in `directory` (a folder, or a bucket prefix such as 's3://bucket/run1')."""
    from bagfault.campaign.loader import load_campaign  # noqa: PLC0415
    from bagfault.campaign.runner import TABLES, run_campaign  # noqa: PLC0415
    from bagfault.io.objects import is_remote, staged_folder  # noqa: PLC0415

    _check_workers(workers)
    loaded = file if not isinstance(file, (str, Path)) else load_campaign(file)
    if is_remote(str(directory)):  # a bucket prefix: written here, uploaded at the end (and on a stop)
        with staged_folder(str(directory), resume=resume, guarded=TABLES) as staged:
            try:
                return run_campaign(loaded, staged.path, job=job, workers=workers, ray=ray, resume=resume,
                                    progress=progress, force=force,  # the prefix's tables came with their marks
                                    kept_elsewhere=staged.outputs)
            except OutputError as exc:  # named as the user knows it: the object in the bucket
                raise OutputError(str(exc).replace(str(staged.path), str(directory).rstrip('/'))) from None
    return run_campaign(loaded, Path(directory), job=job, workers=workers, ray=ray, resume=resume,
                        progress=progress, force=force)


def explore(space: Scenario | str | Path, inputs: Sequence[str | Path] = (), directory: str | Path = 'explore',
            *, budget: int | None = None, seed: int | None = None, workers: int | None = None,
            ray: str | None = None, rate: float = 1.0, resume: bool = False, force: bool = False,
            save_failures: str | Path | None = None, progress: ExploreProgress | None = None,
            search: Strategy = 'guided', shrink: ShrinkMode = 'full') -> ExploreResult:
    """Search the scenario's `explore:` fault space for failures, shrink each to its minimal cause, replay it;
    `bagfault run` offline, `bagfault test` with a `system_under_test` (at `rate`). Runs go to a local pool of
    `workers` (default one per core) or, with `ray` ('' for a local instance, or an address), to Ray; results in
    `directory` (explore.json, report.html, failures/). `search='uniform'` with `shrink='halving'`, and
    `shrink='faults'`, are the benchmark's comparisons (uniform draws and no margins; ddmin over the faults only)."""
    from bagfault.explore import ExploreOptions  # noqa: PLC0415
    from bagfault.explore import explore as run_explore  # noqa: PLC0415

    loaded = scenario_of(space, space=True)
    if loaded.explore is None:
        raise UsageError(f'{loaded.source or loaded.name}: no explore: section (the fault space to search)')
    paths = [Path(p) for p in inputs] or list(loaded.bags)
    _check_workers(workers)
    if budget is not None and (isinstance(budget, bool) or not 1 <= budget <= 100_000):
        raise UsageError(f'--budget {budget}: must be a whole number from 1 to 100000')
    _check_rate(rate)
    options = ExploreOptions(budget=budget, seed=None if seed is None else seed_of(loaded, seed), workers=workers,
                             ray=ray, rate=rate, resume=resume, force=force,
                             save_failures=Path(save_failures) if save_failures is not None else None,
                             search=search, shrink=shrink)
    if loaded.system is not None:
        from bagfault.live import require_rclpy  # noqa: PLC0415 - rclpy is an optional extra

        require_rclpy()
        system_of(loaded, {})
    return run_explore(loaded, paths, Path(directory), options, progress, job=job)


def job(spec: dict[str, Any]) -> dict[str, Any]:
    """One job of a campaign or an exploration, in the process its engine made for it: `run` or `test` as the
    spec says, its result as a row (`campaign/job.py`). The engines are handed this function, so the job calls
    the API as the command line does and nothing below the API imports it."""
    from bagfault.campaign.job import run_job  # noqa: PLC0415

    return run_job(spec, run, test)


def schema(type_name: str | None = None, *, as_json: bool = False, json_schema_of: str | None = None) -> str:
    """`bagfault schema`: every section, injector type and assertion type (or one type's keys, as text or
    JSON), or with `json_schema_of` ('scenario', 'campaign', ...) a JSON Schema for editors."""
    import json  # noqa: PLC0415

    from bagfault.report import schema as text  # noqa: PLC0415

    if json_schema_of:
        return json.dumps(text.json_schema(json_schema_of), indent=2, sort_keys=True)
    if type_name or as_json:
        return text.render_schema(type_name, as_json=as_json)
    return '\n\n'.join([text.render_sections(), "Injector types (each fault's config keys are its injector type's):",
                        text.render_schema(), 'Assertion types:', text.render_assertions()])


def info(inputs: Sequence[str | Path]) -> str:
    """`bagfault info`: what each input holds (format, topics, types, counts, time span), as text."""
    from bagfault.report.info import render_info  # noqa: PLC0415

    return render_info([Path(p) for p in inputs])


@dataclass(frozen=True)
class LatencyOutcome:
    """What `bagfault latency` says: its text, warnings, and whether it is usable (exit 0) or not (2)."""

    text: str
    warnings: tuple[str, ...] = ()
    usable: bool = True


def latency(architecture: str | Path, bags: Sequence[str | Path] = (), *, path: str | None = None,
            stamp_origin: bool = False, json: str | Path | None = None, html: str | Path | None = None,
            force: bool = False) -> LatencyOutcome:
    """CARET path latency of a CARET architecture file's paths measured on `bags` (reports to `json`, `html`);
    with no bags, the architecture file validated (its paths listed, unusable ones said)."""
    import json as json_module  # noqa: PLC0415

    from bagfault.latency.architecture import load_architecture  # noqa: PLC0415
    from bagfault.latency.measure import measure  # noqa: PLC0415
    from bagfault.report.latency import render_html, render_text, render_validation  # noqa: PLC0415

    if not bags:
        loaded = load_architecture(architecture)
        usable = all(p.usable for p in loaded.paths.values()) and not loaded.dropped
        return LatencyOutcome(render_validation(loaded), tuple(loaded.warnings), usable)
    inputs = [Path(b) for b in bags]
    for option, report in (('--json', json), ('--html', html)):
        if report is not None:
            check_output(Path(report), f'{option} report', _protected(architecture=architecture, input=inputs),
                         force=force)
    measured = measure(architecture, inputs, path=path, stamp_origin=stamp_origin)
    if json is not None:
        write_atomic(Path(json), json_module.dumps(measured.to_dict(), indent=1, sort_keys=True) + '\n', 'json')
    if html is not None:
        write_atomic(Path(html), render_html(measured), 'html')
    return LatencyOutcome(render_text(measured))


def demo(directory: str | Path) -> RunResult:
    """`bagfault demo`: a synthetic bag and its scenario written in `directory`, run, with its markdown and HTML
    reports beside them (demo_report.md, demo_report.html)."""
    from bagfault import demo as files  # noqa: PLC0415

    folder = Path(directory)
    try:
        bag, scenario = files.prepare(folder)
    except OSError as exc:
        raise OutputError(f'{folder}: cannot write the demo files: {exc.strerror}') from None
    return run(scenario, [bag], folder / 'demo_output.mcap',
               reports=ReportPaths(markdown=folder / 'demo_report.md', html=folder / 'demo_report.html'))


def campaign_plan(file: str | Path) -> str:
    """`bagfault campaign --dry-run`: the jobs a campaign file makes, summed up, without running any."""
    from bagfault.campaign.loader import load_campaign  # noqa: PLC0415
    from bagfault.campaign.plan import make_plan  # noqa: PLC0415

    return make_plan(load_campaign(file)).summary()


def print_summary(result: RunResult) -> None:
    """The terminal summary of a run: inputs, output, fault timeline, notes, one line per assertion, the verdict
    (warnings on stderr)."""
    from bagfault.report.summary import print_run_summary  # noqa: PLC0415

    print_run_summary(result)


def junit_error(path: Path, scenario: str, reason: str, seconds: float, *, extended: bool = False,
                protected: Sequence[tuple[str, Path]] = ()) -> None:
    """A JUnit file that says why a command could not run (exit 2), so CI shows the reason; nothing when that
    path is itself the problem or names anything in `protected`."""
    from bagfault.report.junit import render_error  # noqa: PLC0415

    try:
        check_output(path, '--junit report', protected)
        write_atomic(path, render_error(scenario, reason, seconds, extended=extended), 'xml')
    except BagfaultError:
        return


def published() -> list[Path]:
    """Every file this process has put under its final name so far, in order (what a stopped command says)."""
    return list(PUBLISHED)


def validate(paths: Sequence[str | Path], *, strict: bool = False) -> list[Scenario]:
    """Load and validate scenario files; raise ScenarioError with every problem of all files."""
    scenarios, problems = [], []
    warnings: list[Problem | str] = []
    for path in paths:
        try:
            scenarios.append(load_scenario(path, strict=strict))
        except ScenarioError as exc:
            problems.extend(exc.problems)
            warnings.extend(exc.warnings)
    if problems:  # every error and every warning of every file, together
        raise ScenarioError(problems, [*warnings, *(w for s in scenarios for w in s.warnings)])
    return scenarios


__all__ = [
    'BagfaultError',
    'LatencyOutcome',
    'ReportPaths',
    'RunOptions',
    'RunResult',
    'StopFlag',
    'campaign',
    'campaign_plan',
    'check',
    'demo',
    'explore',
    'info',
    'job',
    'junit_error',
    'latency',
    'load_scenario',
    'play',
    'print_summary',
    'proxy',
    'published',
    'record',
    'recover',
    'run',
    'schema',
    'test',
    'validate',
]
