"""The system under test ends with bagfault, even when bagfault is killed with SIGKILL.

A tiny process started beside the system waits on a pipe from bagfault.
bagfault writes `done` when it has stopped the system itself; if instead
the pipe closes without it (bagfault died: the kernel closes its end), the
watchdog ends every process of the system's session (SIGTERM, then SIGKILL
2 s later): the system runs in a session of its own, whose id is its pid,
and its descendants stay in it unless they start one of their own. A
leader pid that now belongs to a process started later is another program:
its session is left alone.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import time

GRACE = 2.0  # seconds between SIGTERM and SIGKILL


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


def main(argv: list[str]) -> int:
    """`watchdog LEADER_PID LEADER_START`: wait for `done` on stdin; without it, end the leader's session."""
    leader, start = int(argv[0]), int(argv[1])
    if sys.stdin.readline().strip() == 'done':
        return 0
    fields = _stat(leader)
    if fields is not None and int(fields[19]) != start:
        return 0  # the pid is another program's now, and so is its session
    for number in (signal.SIGTERM, signal.SIGKILL):
        for pid in session_members(leader):
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.kill(pid, number)
        deadline = time.monotonic() + GRACE
        while session_members(leader) and time.monotonic() < deadline:
            time.sleep(0.05)
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
