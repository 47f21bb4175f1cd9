"""The system under test ends with bagfault, even when bagfault is killed with SIGKILL.

A tiny process started beside the system waits on a pipe from bagfault.
bagfault writes `done` when it has stopped the system itself; if instead
the pipe closes without it (bagfault died: the kernel closes its end), the
watchdog ends every process of the system's session (SIGTERM, then SIGKILL
2 s later) and removes the run's scratch folder (its logs, unless kept):
the system runs in a session of its own, whose id is its pid, and its
descendants stay in it unless they start one of their own. A
leader pid that now belongs to a process started later is another program:
its session is left alone.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import sys
import time

GRACE = 2.0  # seconds between SIGTERM and SIGKILL
MARK = 'BAGFAULT_SYSTEM_RUN'  # environment variable holding the run's token in every process of the system
SCRATCH_PREFIX = 'bagfault-test-'  # a run's own log folder (tempfile.TemporaryDirectory's prefix)


def _stat(pid: int) -> list[str] | None:
    try:
        with open(f'/proc/{pid}/stat', encoding='ascii', errors='replace') as handle:
            text = handle.read()
    except OSError:
        return None
    return text[text.rfind(')') + 2:].split()  # state, ppid, pgrp, session, ... starttime (index 19)


def session_members(leader: int) -> list[int]:
    """Live processes of the session `leader` started (zombies excluded)."""
    found = []
    for entry in os.listdir('/proc'):
        if entry.isdigit() and int(entry) != os.getpid():
            fields = _stat(int(entry))
            if fields is not None and fields[0] != 'Z' and int(fields[3]) == leader:
                found.append(int(entry))
    return found


def marked(token: str) -> list[int]:
    """Live processes whose environment holds the run's mark (zombies and this process excluded)."""
    needle = f'{MARK}={token}'.encode() + b'\0'
    found = []
    for entry in os.listdir('/proc'):
        if not entry.isdigit() or int(entry) == os.getpid():
            continue
        try:
            with open(f'/proc/{entry}/environ', 'rb') as handle:
                environment = handle.read() + b'\0'
        except OSError:
            continue
        if needle in environment:
            fields = _stat(int(entry))
            if fields is not None and fields[0] != 'Z':
                found.append(int(entry))
    return found


def main(argv: list[str]) -> int:
    """`watchdog LEADER_PID LEADER_START [TOKEN [SCRATCH]]`: wait for `done` on stdin; without it, end the
    leader's session and every process marked with the run's token, then remove the run's scratch folder."""
    leader, start = int(argv[0]), int(argv[1])
    token = argv[2] if len(argv) > 2 else ''
    if sys.stdin.readline().strip() == 'done':
        return 0
    fields = _stat(leader)
    ours = fields is None or int(fields[19]) == start  # else the pid is another program's now, and its session

    def members() -> set[int]:
        return set(session_members(leader) if ours else ()) | set(marked(token) if token else ())

    for number in (signal.SIGTERM, signal.SIGKILL):
        for pid in members():
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.kill(pid, number)
        deadline = time.monotonic() + GRACE
        while members() and time.monotonic() < deadline:
            time.sleep(0.05)
    if len(argv) > 3 and os.path.basename(argv[3].rstrip('/')).startswith(SCRATCH_PREFIX):
        shutil.rmtree(argv[3], ignore_errors=True)  # the run's own log folder (never one a user named)
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))


def hold_scratch(folder: str) -> int:
    """Mark a run's scratch folder as in use: a lock held on its `.owner` file for as long as the returned
    descriptor stays open (the kernel lets go when the run's process dies, however it dies)."""
    import fcntl  # noqa: PLC0415

    handle = os.open(os.path.join(folder, '.owner'), os.O_CREAT | os.O_RDWR, 0o600)
    fcntl.flock(handle, fcntl.LOCK_EX)
    return handle


def sweep_scratch(parent: str) -> list[str]:
    """Remove the scratch folders in `parent` whose run is gone (its `.owner` lock free): left by a run whose
    watchdog could not clean up. A folder without `.owner` (being made) is left alone."""
    import fcntl  # noqa: PLC0415

    removed = []
    with contextlib.suppress(OSError):
        for name in sorted(os.listdir(parent)):
            folder = os.path.join(parent, name)
            if not name.startswith(SCRATCH_PREFIX) or not os.path.isdir(folder):
                continue
            try:
                handle = os.open(os.path.join(folder, '.owner'), os.O_RDWR)
            except OSError:
                continue
            try:
                fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                continue  # a live run holds it
            finally:
                os.close(handle)
            shutil.rmtree(folder, ignore_errors=True)
            removed.append(name)
    return removed
