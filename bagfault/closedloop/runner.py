"""`bagfault test`: one closed-loop run (or several), from a free domain to a stopped system and a verdict.

    lease a ROS domain -> start the system (own process group, loopback DDS profile, use_sim_time)
    -> replay the bag through the scenario into a SystemLink (ready, /clock, the system heard)
    -> stop the system (SIGINT, SIGTERM, SIGKILL) -> verdicts, with `system_alive` first
"""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import TYPE_CHECKING

from bagfault.closedloop.domain import DomainLease
from bagfault.closedloop.isolation import PRESTART, CrowdedDomainError, DomainWatch
from bagfault.closedloop.link import SystemLink
from bagfault.closedloop.process import SystemProcess
from bagfault.closedloop.watchdog import SCRATCH_PREFIX, hold_scratch, sweep_scratch
from bagfault.engine.offline import finish, replay
from bagfault.engine.provenance import provenance, record_origin
from bagfault.engine.result import SystemReport
from bagfault.errors import ClosedLoopError
from bagfault.io.definitions import load_definitions
from bagfault.io.sources import InputSet
from bagfault.io.types import TypeCatalog
from bagfault.live import LOOPBACK_PROFILE
from bagfault.live.pacer import CLOCK_NOTE
from bagfault.live.recording import maybe_recording
from bagfault.live.runtime import ros_context
from bagfault.log import log
from bagfault.settings import users_environment
from bagfault.spec.system import command_line

if TYPE_CHECKING:
    from collections.abc import Sequence

    from bagfault.closedloop.isolation import Stranger
    from bagfault.engine.result import RunResult
    from bagfault.engine.run import Observer
    from bagfault.engine.stop import StopFlag
    from bagfault.live.viewing import OpenView
    from bagfault.spec.model import Scenario
    from bagfault.spec.system import SystemUnderTest

PROFILE_VARIABLE = 'FASTRTPS_DEFAULT_PROFILES_FILE'


def system_env(system: SystemUnderTest, domain: int) -> dict[str, str]:
    """The system's environment: ours, its `env`, its domain and the loopback discovery profile."""
    return {**users_environment(dict(os.environ)), 'PYTHONUNBUFFERED': '1', 'RCUTILS_COLORIZED_OUTPUT': '0',
            **system.env, 'ROS_DOMAIN_ID': str(domain), PROFILE_VARIABLE: str(LOOPBACK_PROFILE)}


ATTEMPTS = 3  # leased domains tried before giving up on finding one without other processes' nodes


def run_test(scenario: Scenario, inputs: Sequence[Path], output: Path | None, *, system: SystemUnderTest,
             seed: int, rate: float, logs: Path | None, stop: StopFlag, view: OpenView | None = None,
             observers: Sequence[Observer] = (), clock_check: bool = True, **lease: int) -> RunResult:
    """One closed-loop run; the recording (if `output`) is complete on return, the system stopped; `observers`
    see every record of the run, the system's messages among them (report collectors). The system starts at
    once on a leased domain while bagfault looks for other processes' nodes there (PRESTART: discovery takes
    ~0.2 s); should some show, the system is stopped and the run moves to another domain, ClosedLoopError
    naming them after ATTEMPTS (later ones void the run: DomainWatch). `clock_check` False: no hold of the
    clock at a rate other than 1 (see closedloop/clocks.py). `lease`: the ids to lease from."""
    crowded: dict[int, list[Stranger]] = {}
    for _ in range(ATTEMPTS):
        try:
            held = DomainLease(avoid=crowded, **lease)
        except ClosedLoopError:
            if not crowded:
                raise
            break
        with held:
            try:
                return _run_on(held, scenario, inputs, output, system=system, seed=seed, rate=rate, logs=logs,
                               stop=stop, view=view, observers=observers, clock_check=clock_check)
            except CrowdedDomainError as exc:
                crowded[exc.domain] = exc.found
                log.info(f'ROS domain {exc.domain} has nodes of other processes '
                         f'({", ".join(s.describe() for s in exc.found)}): the system is stopped and starts again '
                         'on another')
    said = '; '.join(f'{domain}: {", ".join(s.describe() for s in found)}' for domain, found in crowded.items())
    raise ClosedLoopError(f'no quiet ROS domain: other processes have nodes on each leased one ({said})')


def _run_on(lease: DomainLease, scenario: Scenario, inputs: Sequence[Path], output: Path | None, *,
            system: SystemUnderTest, seed: int, rate: float, logs: Path | None, stop: StopFlag,
            view: OpenView | None, observers: Sequence[Observer], clock_check: bool) -> RunResult:
    """`run_test` on one leased domain (CrowdedDomainError when other processes show nodes there at first)."""
    from rclpy.executors import SingleThreadedExecutor  # noqa: PLC0415
    from rclpy.node import Node  # noqa: PLC0415

    os.environ[PROFILE_VARIABLE] = str(LOOPBACK_PROFILE)  # our participant discovers over loopback too
    view_notes: list[str] = []
    with ros_context(stop, domain_id=lease.domain) as context, \
            tempfile.TemporaryDirectory(prefix=SCRATCH_PREFIX) as scratch, InputSet(inputs) as input_set, \
            contextlib.ExitStack() as closing:  # closed in the reverse order
        quiet_until = time.monotonic() + PRESTART  # this process's participant looks from now on
        sweep_scratch(str(Path(scratch).parent))  # what a killed run's watchdog could not remove
        closing.callback(os.close, hold_scratch(scratch))
        folder = logs if logs is not None else Path(scratch)
        command = command_line(system, sys.executable)
        report = SystemReport(command=command, domain_id=lease.domain, logs=logs)
        inputs = list(inputs)
        catalog = TypeCatalog(input_set.channels, input_set.ros_distro, load_definitions(scenario.msg_paths))
        metadata = {**provenance(scenario, inputs, seed, (), 0.0), 'mode': 'test', 'command': ' '.join(command)}
        recording = closing.enter_context(maybe_recording(output, metadata, scenario, input_set.start_time or 0))
        node = Node('bagfault_test_player', context=context)
        closing.callback(node.destroy_node)
        listener = Node('bagfault_test_listener', context=context)
        closing.callback(listener.destroy_node)
        executor = SingleThreadedExecutor(context=context)  # hands message info over: what was lost is counted
        closing.callback(executor.shutdown)
        executor.add_node(listener)
        shown = None
        if view is not None:
            shown = view(scenario)  # read-only: a test's faults are its scenario's
            closing.callback(shown.close)
            closing.callback(lambda: view_notes.extend(shown.notes() if shown is not None else ()))
            log.info(f'Foxglove view on {shown.url}')
        process = SystemProcess(command, env=system_env(system, lease.domain), cwd=system.cwd,
                                shell=system.shell, logs=folder, scratch=None if logs is not None else Path(scratch))
        closing.callback(_stopped, process, system, report)
        log.debug(f'system under test starting on ROS domain {lease.domain}')

        def announce() -> None:  # once the domain is the run's alone: a watcher who attaches now is not a stranger
            log.info(f'system under test started on ROS domain {lease.domain}; to watch it: '
                     f'ROS_DOMAIN_ID={lease.domain} FASTRTPS_DEFAULT_PROFILES_FILE={LOOPBACK_PROFILE}')

        watch = DomainWatch(listener, lease.domain, os.getpid(), process.pids, process.pid, quiet_until=quiet_until,
                            on_quiet=announce)
        link = SystemLink(node, listener, executor, system=system, process=process, scenario=scenario,
                          catalog=catalog, rate=rate, stop=stop, recording=recording, watch=watch, seed=seed,
                          clock_check=clock_check)
        closing.callback(link.close)
        link.view = shown
        run, stopped = replay(input_set, scenario, catalog, link, seed=seed, blackbox_base=output, hooks=link,
                              observers=observers, withheld=frozenset(system.publishes))
        with run:  # its black boxes are dropped unless the recording is complete
            if stopped:
                raise ClosedLoopError(f'stopped by {stop.reason or "a signal"} before the end of the bag; '
                                      'nothing judged', tail=process.tail())
            if recording is not None:
                record_origin(recording, run.stats.origin)
                finish(recording, run)
            else:
                run.close(ok=True)
    result = run.result('test', inputs, output, seed)
    result.notes += view_notes + link.notes
    if link.held:
        result.notes.append(f'bagfault stood still {link.held:.2f} s of wall time in all (a busy machine): the '
                            'clock held meanwhile, and the bag went on from there')
    for described in link.watch.listeners.values() if link.watch is not None else ():
        result.notes.append(f'on ROS domain {lease.domain} too, not part of the system: {described}')
    if run.stats.input_messages == 0:
        result.notes.append('the input holds no messages: nothing was played to the system under test')
    if link.alive_result is not None:
        result.assertions.insert(0, link.alive_result)
    _said_in_the_tail(result, run.stats.last_time, system.tail)
    report.ready_seconds = link.ready_seconds
    report.played = dict(link.published_per_topic)
    report.heard = dict(link.heard)
    report.lost = link.lost()
    if report.lost:
        lost = ', '.join(f'{count} of {topic}' for topic, count in report.lost.items())
        result.warnings.append(f"the system's messages were lost before bagfault heard them ({lost}): verdicts on "
                               'those topics judged fewer messages than it sent (a machine too busy?)')
    report.unwatched = list(link.unwatched)
    result.system = report
    result.warnings += link.clocks.warnings()
    for topic in link.unwatched:
        result.warnings.append(f'{topic}: asserted, but the system under test never advertised it and the '
                               'scenario does not give its message_type; not heard')
    if link.clock_left_out:
        result.notes.append(CLOCK_NOTE)
    for topic, why in sorted(link.skipped.items()):
        result.notes.append(f'{topic} not published: {why} (recorded only)')
    return result


def _said_in_the_tail(result: RunResult, last: int | None, tail: float) -> None:
    """A failure decided after the bag's last message, in the tail while the clock runs on, says so: the system
    may rightly be reacting to the end of the data (a watchdog shorter than the tail)."""
    if last is None or tail <= 0:
        return
    for assertion in result.assertions:
        if assertion.state == 'failed' and assertion.time is not None and assertion.time > last:
            assertion.message += (f' (after the bag ended: the system reacting to the end of the data? `tail` is '
                                  f'{tail:g} s)')


def _stopped(process: SystemProcess, system: SystemUnderTest, report: SystemReport) -> None:
    """Stop the system and note how; its output tail goes into the report."""
    report.ending = process.stop(system.stop_timeout)
    report.signals = list(process.sent)
    report.returncode = process.returncode
    report.tail = process.tail()
    report.leftovers = sorted(process.leftovers())
