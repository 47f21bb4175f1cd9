"""Process faults carried out on the system under test when their events come due (the `process` injector).

A fault's `target` is resolved when it switches on: 'system' is every
process of the system's tree, {command: REGEX} those whose command line
matches, {node: NAME} the process whose DDS participant hosts that node
(Fast DDS writes the low 16 bits of the pid into every GUID: isolation.py).
`pause` sends SIGSTOP, and SIGCONT when the fault ends; `kill` sends its
signal and, with `restart`, starts each killed process whose parent was not
killed too (that parent starts the rest again) with its command line,
environment and working directory when the fault ends (at once when it has
no end); `cpu_limit` holds the processes to a fraction of a core, through
cgroup v2's cpu.max where this process may create a cgroup, else a
SIGSTOP/SIGCONT duty cycle. Each action returns a line for the fault
event's details, with the pids it hit; deaths bagfault caused are known, so
`system_alive` does not judge them as crashes.
"""

from __future__ import annotations

import contextlib
import os
import re
import signal
import subprocess
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from bagfault.closedloop.isolation import gid_pid16, pid16
from bagfault.closedloop.process import Launch, command_of, launch_of, processes

if TYPE_CHECKING:
    from bagfault.closedloop.process import SystemProcess
    from bagfault.events import FaultEvent
    from bagfault.spec.model import Scenario

DUTY_PERIOD = 0.1  # seconds of one SIGCONT/SIGSTOP cycle of the cpu_limit fallback
CGROUP_ROOT = Path('/sys/fs/cgroup')
CGROUP_PERIOD = 100_000  # µs, cpu.max's period
Throttle = Literal['cgroup v2 cpu.max', 'SIGSTOP/SIGCONT duty cycle']


def node_pids(listener: Any, name: str) -> set[int]:
    """The low 16 bits of the pids whose participants host node `name` (from its publishers on the graph)."""
    found: set[int] = set()
    topics = ['/rosout', '/parameter_events'] + [t for t, _ in listener.get_topic_names_and_types()]
    for topic in topics:
        for info in listener.get_publishers_info_by_topic(topic):
            if f'{info.node_namespace.rstrip("/")}/{info.node_name}' != name:
                continue
            low = gid_pid16(bytes(info.endpoint_gid))
            if low is not None:
                found.add(low)
        if found:
            return found
    return found


@dataclass
class Held:
    """What a switched-on fault did and must undo or finish when it ends."""

    pids: list[int]
    action: str
    launches: list[Launch] = field(default_factory=list)
    throttle: CpuLimit | None = None


class ProcessFaults:
    """Carries out the `process` faults of a scenario on one running system."""

    def __init__(self, scenario: Scenario, process: SystemProcess, listener: Any) -> None:
        self.targets = {i.id: i.options.get('target') for i in scenario.injectors if i.type == 'process'}
        self.scenario = scenario
        self.process = process
        self.listener = listener
        self.held: dict[str, Held] = {}
        self.caused: dict[int, int] = {}  # pid -> signal bagfault killed it with
        self.restarted: list[subprocess.Popen[bytes]] = []  # held so they are reaped with this run

    def act(self, event: FaultEvent) -> str:
        """Carry out a change of a process fault; what was done ('' for other faults or nothing to do)."""
        if event.injector_id not in self.targets or event.state not in ('active', 'inactive'):
            return ''
        if event.state == 'inactive':
            return self._end(event.fault_id)
        fault = self.scenario.fault(event.fault_id)
        assert fault is not None
        pids = self.resolve(self.targets[event.injector_id])
        if not pids:
            return f'no process of the system matches target {self._describe(self.targets[event.injector_id])}'
        config = fault.config
        has_end = fault.duration is not None or fault.repeat is not None or fault.probability_per_second is not None
        if config.get('pause'):
            _send(pids, signal.SIGSTOP)
            self.held[event.fault_id] = Held(pids, 'paused')
            return f'SIGSTOP to pid {_pids(pids)}'
        if config.get('kill'):
            number = signal.Signals[config.get('signal', 'SIGKILL')]
            killed = set(pids)
            parents = {p.pid: p.ppid for p in processes()}
            roots = [launch for pid in pids
                     if parents.get(pid) not in killed and (launch := launch_of(pid)) is not None]
            for pid in pids:
                self.caused[pid] = number
            _send(pids, number)
            said = f'{number.name} to pid {_pids(pids)}'
            if config.get('restart'):
                self.held[event.fault_id] = Held(pids, 'killed', roots)
                if not has_end:
                    return f'{said}; {self._end(event.fault_id)}'
            return said
        if float(config['cpu_limit']) >= 1.0:
            return 'cpu_limit 1.0: a whole core, no limit'
        throttle = CpuLimit(pids, float(config['cpu_limit']))
        self.held[event.fault_id] = Held(pids, 'limited', throttle=throttle)
        return f'at most {float(config["cpu_limit"]):g} of a core for pid {_pids(pids)} ({throttle.how})'

    def _end(self, fault_id: str) -> str:
        held = self.held.pop(fault_id, None)
        if held is None:
            return ''
        if held.action == 'paused':
            _send(held.pids, signal.SIGCONT)
            return f'SIGCONT to pid {_pids(held.pids)}'
        if held.throttle is not None:
            held.throttle.stop()
            return f'pid {_pids(held.pids)} free again'
        started, failed = [], []
        for launch in held.launches:
            try:
                started.append(self._restart(launch))
            except OSError as exc:
                failed.append(f'{" ".join(launch.argv)}: {exc.strerror or exc}')
        said = [f'restarted as pid {_pids(started)}'] if started else []
        return '; '.join([*said, *(f'could not restart {text}' for text in failed)]) or 'nothing to restart'

    def _restart(self, launch: Launch) -> int:
        """Start a killed process again (SystemProcess.start_again); its pid."""
        popen = self.process.start_again(launch)
        if launch.pid != self.process.pid:
            self.restarted.append(popen)
        return popen.pid

    def resolve(self, target: str | dict[str, str] | None) -> list[int]:
        """The live pids a target names now (sorted)."""
        return resolve_target(target, self.process, self.listener)

    @staticmethod
    def _describe(target: str | dict[str, str] | None) -> str:
        return str(target) if not isinstance(target, dict) else ', '.join(f'{k}: {v}' for k, v in target.items())

    def died_by_us(self, pid: int, returncode: int | None) -> bool:
        """True when the process `pid` ended after bagfault sent it a kill: by the signal, or on its own after
        handling it (a node stops cleanly on SIGINT or SIGTERM and exits with 0)."""
        return pid in self.caused and returncode is not None

    def close(self) -> None:
        """The end of the run: paused processes go on and throttles stop (the system is stopped next)."""
        for fault_id in list(self.held):
            held = self.held[fault_id]
            if held.action != 'killed':
                self._end(fault_id)


def resolve_target(target: str | dict[str, str] | None, process: SystemProcess, listener: Any) -> list[int]:
    """The live pids of the system a target names now (sorted): 'system' all, {command} by command line,
    {node} the process hosting the node."""
    alive = {p.pid for p in processes() if p.state != 'Z'}
    tree = [pid for pid in sorted(process.pids() - {os.getpid()}) if pid in alive]
    if not isinstance(target, dict):
        return tree
    if 'command' in target:
        pattern = re.compile(target['command'])
        return [pid for pid in tree if pattern.search(command_of(pid))]
    lows = node_pids(listener, target['node'])
    return [pid for pid in tree if pid16(pid) in lows]


def _pids(pids: list[int]) -> str:
    return ', '.join(str(p) for p in pids)


def _send(pids: list[int], number: int) -> None:
    for pid in pids:
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.kill(pid, number)


def writable_cgroup() -> Path | None:
    """A cgroup v2 folder below this process's own where a child with the cpu controller can be made, or None
    (cgroup v1, a read-only mount, no delegation)."""
    try:
        lines = Path('/proc/self/cgroup').read_text().splitlines()
    except OSError:
        return None
    unified = [line[3:] for line in lines if line.startswith('0::')]
    if len(lines) != 1 or not unified:
        return None  # v1 or hybrid: cpu.max is v2's
    own = CGROUP_ROOT / unified[0].lstrip('/')
    try:
        controllers = (own / 'cgroup.controllers').read_text().split()
    except OSError:
        return None
    if 'cpu' not in controllers or not os.access(own, os.W_OK):
        return None
    return own


class CpuLimit:
    """Processes held to `share` of one core until `stop`: cgroup v2 cpu.max where possible, else a duty cycle."""

    def __init__(self, pids: list[int], share: float) -> None:
        self.pids = pids
        self.share = share
        self._done = threading.Event()
        self._group: Path | None = None
        self._thread: threading.Thread | None = None
        self.how: Throttle = 'SIGSTOP/SIGCONT duty cycle'
        parent = writable_cgroup()
        if parent is not None and self._enter(parent):
            self.how = 'cgroup v2 cpu.max'
            return
        self._thread = threading.Thread(target=self._cycle, name='bagfault-cpu-limit', daemon=True)
        self._thread.start()

    def _enter(self, parent: Path) -> bool:
        group = parent / f'bagfault-limit-{os.getpid()}-{id(self)}'
        try:
            group.mkdir()
            (group / 'cpu.max').write_text(f'{round(self.share * CGROUP_PERIOD)} {CGROUP_PERIOD}\n')
            for pid in self.pids:
                (group / 'cgroup.procs').write_text(f'{pid}\n')
        except OSError:
            self._leave(group, parent)
            return False
        self._group = group
        return True

    def _leave(self, group: Path, parent: Path) -> None:
        with contextlib.suppress(OSError):
            for pid in (group / 'cgroup.procs').read_text().split():
                with contextlib.suppress(OSError):
                    (parent / 'cgroup.procs').write_text(f'{pid}\n')
        with contextlib.suppress(OSError):
            group.rmdir()

    def _cycle(self) -> None:
        running = DUTY_PERIOD * self.share
        while not self._done.is_set():
            _send(self.pids, signal.SIGCONT)
            if self._done.wait(running):
                break
            _send(self.pids, signal.SIGSTOP)
            if self._done.wait(DUTY_PERIOD - running):
                break
        _send(self.pids, signal.SIGCONT)

    def stop(self) -> None:
        """Free the processes (SIGCONT, or back into the parent cgroup)."""
        self._done.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        if self._group is not None:
            self._leave(self._group, self._group.parent)
            self._group = None
