"""The system under test as a process group: started with its own env and logs, stopped with nothing left.

It is started in a new session (its own process group). Stopping sends
SIGINT, then SIGTERM, then SIGKILL, `stop_timeout` apart, to the group and
to every descendant that left it (a daemonised child); `leftovers` lists
whatever still runs, which a test can assert is empty. A process seen
during the run is known by its pid and start time, so a pid the kernel hands
to another program after ours ended is never signalled.
"""

from __future__ import annotations

import contextlib
import os
import secrets
import signal
import subprocess
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Literal

from bagfault.closedloop.watchdog import MARK, marked
from bagfault.errors import ClosedLoopError

Ending = Literal['running', 'exited', 'SIGINT', 'SIGTERM', 'SIGKILL']
TAIL_LINES = 20


@dataclass(frozen=True)
class ProcessStat:
    """One line of /proc/PID/stat: what is needed to find a process's group and parent, and to tell it from a
    later process with the same pid (its start time in clock ticks since boot)."""

    pid: int
    ppid: int
    pgid: int
    state: str
    start: int


def processes() -> list[ProcessStat]:
    """Every process visible in /proc (zombies included: they are reaped by their parent)."""
    found = []
    for entry in os.scandir('/proc'):
        if not entry.name.isdigit():
            continue
        try:
            text = Path(entry.path, 'stat').read_text()
        except OSError:
            continue
        fields = text[text.rfind(')') + 2:].split()  # the command name may hold spaces and parentheses
        found.append(ProcessStat(int(entry.name), int(fields[1]), int(fields[2]), fields[0], int(fields[19])))
    return found


@dataclass(frozen=True)
class Launch:
    """How to start a process again: what it ran, where, with which environment."""

    argv: list[str]
    env: dict[str, str]
    cwd: str
    pid: int


def launch_of(pid: int) -> Launch | None:
    """A running process's command line, environment and working directory (None once it is gone)."""
    try:
        argv = Path(f'/proc/{pid}/cmdline').read_bytes().split(b'\0')[:-1]
        environ = Path(f'/proc/{pid}/environ').read_bytes().split(b'\0')
        cwd = os.readlink(f'/proc/{pid}/cwd')
    except OSError:
        return None
    env = dict(item.decode(errors='surrogateescape').split('=', 1) for item in environ if b'=' in item)
    return Launch([a.decode(errors='surrogateescape') for a in argv], env, cwd, pid)


def command_of(pid: int) -> str:
    """A process's command line as one string ('' once it is gone)."""
    try:
        return Path(f'/proc/{pid}/cmdline').read_bytes().rstrip(b'\0').replace(b'\0', b' ').decode(errors='replace')
    except OSError:
        return ''


def describe_exit(code: int | None) -> str:
    """'code 3' or 'signal SIGSEGV' for a Popen return code."""
    if code is None:
        return 'no exit code'
    if code < 0:
        try:
            return f'signal {signal.Signals(-code).name}'
        except ValueError:
            return f'signal {-code}'
    return f'code {code}'


def family(leader: int, known: dict[int, int]) -> dict[int, int]:
    """Live processes (pid -> start time) of the group `leader` leads, the `known` ones still running as the same
    process, and every descendant of those. The kernel reuses neither a group id while the group has members
    nor, then, the leader's pid; so a live process with the leader's pid and another start time means the group
    of that id is a new one, not the system's."""
    table = {p.pid: p for p in processes() if p.state != 'Z'}
    members = {pid for pid, start in known.items() if pid in table and table[pid].start == start}
    if not (leader in table and leader in known and table[leader].start != known[leader]):
        members |= {p.pid for p in table.values() if p.pgid == leader}
    children: dict[int, list[int]] = {}
    for p in table.values():
        children.setdefault(p.ppid, []).append(p.pid)
    todo = list(members)
    while todo:
        for child in children.get(todo.pop(), []):
            if child not in members:
                members.add(child)
                todo.append(child)
    return {pid: table[pid].start for pid in members}


@contextlib.contextmanager
def _interruptible_children() -> Iterator[None]:
    """A process started with SIGINT ignored (a shell's background job, nohup) passes that on to the system, which
    SIGINT could then never stop. While it starts, SIGINT has a handler here (doing nothing, as ignoring did),
    and exec gives the child the default action for a handled signal."""
    if threading.current_thread() is not threading.main_thread() or signal.getsignal(signal.SIGINT) != signal.SIG_IGN:
        yield
        return
    signal.signal(signal.SIGINT, lambda _number, _frame: None)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, signal.SIG_IGN)


def _watchdog(leader: int, start: int, token: str, scratch: Path | None) -> subprocess.Popen[bytes] | None:
    """The watchdog of closedloop/watchdog.py for a system's session, which also removes `scratch` (None if it
    cannot start: then only a live bagfault stops the system)."""
    import sys  # noqa: PLC0415

    extra = [str(scratch)] if scratch is not None else []
    try:
        return subprocess.Popen([sys.executable, '-m', 'bagfault.closedloop.watchdog', str(leader), str(start), token,
                                 *extra],
                                stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                start_new_session=True, close_fds=True)
    except OSError:
        return None


def _new_log(path: Path) -> IO[bytes]:
    """An empty log file, opened for appending (O_APPEND: each write lands at the end, whoever wrote before)."""
    path.write_bytes(b'')
    return path.open('ab')


class SystemProcess:
    """A running system under test with its stdout and stderr in files."""

    def __init__(self, command: list[str], *, env: dict[str, str], cwd: Path | None, shell: bool,
                 logs: Path, scratch: Path | None = None) -> None:
        logs.mkdir(parents=True, exist_ok=True)
        self.command = command
        self.stdout_path = logs / 'system.stdout.log'
        self.stderr_path = logs / 'system.stderr.log'
        self.ending: Ending = 'running'
        self.sent: list[tuple[str, float]] = []  # each signal sent while the main process ran, seconds into the stop
        # appended to by every process of the system, those started again later included: a writer that does
        # not append writes at its own offset, over what the others appended since
        self._out: IO[bytes] = _new_log(self.stdout_path)
        self._err: IO[bytes] = _new_log(self.stderr_path)
        argv: str | list[str] = command[0] if shell else command
        self.token = secrets.token_hex(8)  # in every process of the system, daemons that left its session included
        env = {**env, MARK: self.token}
        try:
            with _interruptible_children():
                self.popen = subprocess.Popen(argv, shell=shell, env=env, cwd=cwd, stdin=subprocess.DEVNULL,
                                              stdout=self._out, stderr=self._err, start_new_session=True)
        except OSError as exc:
            self._close_logs()
            raise ClosedLoopError(f'system under test: cannot start {" ".join(command)}: '
                                  f'{exc.strerror or exc}') from None
        self.pid = self.popen.pid
        self._known: dict[int, int] = family(self.pid, {})  # the group: the new process at least
        self._watchdog = _watchdog(self.pid, self._known.get(self.pid, 0), self.token, scratch)

    @property
    def returncode(self) -> int | None:
        """The exit status once the main process ended (negative: killed by that signal)."""
        return self.popen.poll()

    def alive(self) -> bool:
        """True while the main process runs."""
        return self.popen.poll() is None

    def watch(self) -> None:
        """Remember the current descendants, so those that leave the group are still stopped."""
        self._known |= family(self.pid, self._known)

    def start_again(self, launch: Launch, extra: list[str] | None = None) -> subprocess.Popen[bytes]:
        """A process of the system that ended (a process fault's kill, a link's remap) started again with its
        command line (and `extra` arguments), environment and working directory, in a session of its own (a
        group of another session cannot be joined; its environment carries the run's mark, so the stop and the
        watchdog find it), its output appended to the system's logs. A new main process becomes the system's
        main process: the group the stop signals; the processes seen so far stay known."""
        with open(self.stdout_path, 'ab') as out, open(self.stderr_path, 'ab') as err:
            popen = subprocess.Popen([*launch.argv, *(extra or [])], env=launch.env, cwd=launch.cwd,
                                     stdin=subprocess.DEVNULL, stdout=out, stderr=err, start_new_session=True)
        if launch.pid == self.pid:
            self.popen.poll()  # the ended one reaped
            self.popen = popen
            self.pid = popen.pid
            self._known |= family(self.pid, {})
        return popen

    def _marked(self) -> set[int]:
        """Processes carrying the run's mark: a daemon that left the session and whose parent has gone."""
        return set(marked(self.token))

    def pids(self) -> set[int]:
        """Every process of the system seen so far (the group and its descendants, looked at again now)."""
        if self.alive():
            self.watch()
        return {self.pid, *self._known, *self._marked()}

    def stop(self, timeout: float) -> Ending:
        """SIGINT, SIGTERM, SIGKILL to the group and its descendants, `timeout` apart; how it ended (the last
        signal the main process got, every one sent in `sent`)."""
        if self.alive():
            self.watch()
        began = time.monotonic()
        for sig, name in ((signal.SIGINT, 'SIGINT'), (signal.SIGTERM, 'SIGTERM'), (signal.SIGKILL, 'SIGKILL')):
            main_running = self.alive()
            remaining = self.leftovers() | ({self.pid} if main_running else set())  # (see _wait)
            if not remaining:
                break
            if main_running:
                self.ending = name  # type: ignore[assignment]
                self.sent.append((name, time.monotonic() - began))
            self._signal(sig, remaining)
            self._wait(timeout if sig != signal.SIGKILL else 5.0)
        else:
            if self.leftovers():
                raise ClosedLoopError(f'system under test: processes {sorted(self.leftovers())} survive SIGKILL')
        if self.ending == 'running':
            self.ending = 'exited'
        self.popen.wait()
        self._close_logs()
        self._release_watchdog()
        return self.ending

    def _release_watchdog(self) -> None:
        """Stopped here: the watchdog has nothing to do."""
        watchdog, self._watchdog = self._watchdog, None
        if watchdog is None:
            return
        with contextlib.suppress(OSError):
            assert watchdog.stdin is not None
            watchdog.stdin.write(b'done\n')
            watchdog.stdin.close()
        with contextlib.suppress(subprocess.TimeoutExpired):
            watchdog.wait(timeout=5)

    def leftovers(self) -> set[int]:
        """Processes of the system still running (its group and the descendants seen)."""
        return (set(family(self.pid, self._known)) | self._marked()) - {os.getpid()}

    def tail(self, lines: int = TAIL_LINES) -> list[str]:
        """The last lines the system wrote, stderr's after stdout's."""
        out = []
        for path in (self.stdout_path, self.stderr_path):
            with contextlib.suppress(OSError):
                text = path.read_bytes()[-64_000:].decode(errors='replace')
                out += [line for line in text.splitlines() if line.strip()][-lines:]
        return out[-lines:]

    def _signal(self, sig: int, pids: set[int]) -> None:
        """Once to the group while it is the system's, and once to each process that left it (never twice to one
        process: a second SIGINT can reach a node after its handler was removed and kill it instead of stopping
        it)."""
        grouped = {p.pid for p in processes() if p.pgid == self.pid} & pids
        if grouped:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(self.pid, sig)
        for pid in pids - grouped:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.kill(pid, sig)

    def _wait(self, timeout: float) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            # the main process runs until poll() reaps it, whatever /proc says meanwhile: a process whose main
            # thread has ended while others still shut down shows as a zombie there (seen: SIGTERM sent 0.2 s
            # after SIGINT to a node that was still stopping on its own)
            if self.popen.poll() is not None and not self.leftovers():
                return
            time.sleep(0.02)

    def _close_logs(self) -> None:
        for handle in (self._out, self._err):
            with contextlib.suppress(OSError):
                handle.close()
