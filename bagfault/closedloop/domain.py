"""A free ROS_DOMAIN_ID held for a run, so concurrent tests on one machine never see each other.

A lease is an exclusive `flock` on a file named after the id in a folder
shared by every bagfault process of the user, and the TCP port 32768 + id
bound on 127.0.0.1, as ROS's `domain_coordinator` (colcon's isolated tests,
launch_testing) claims a domain: each sees the other's claims, whatever the
user or `TMPDIR`. The kernel releases both when the process dies, so a
crashed run never leaks a domain. The holder removes its lock file before it
lets go (a lock taken on a file that was removed meanwhile is taken again, on
the new one), and each lease removes the files a crashed run left unlocked.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import socket
import tempfile
from pathlib import Path
from typing import IO, TYPE_CHECKING

from bagfault import settings
from bagfault.errors import ClosedLoopError

if TYPE_CHECKING:
    from collections.abc import Collection

FIRST, LAST = 30, 101  # ids whose Fast DDS ports stay below Linux's ephemeral range (32768)
COORDINATOR_PORT_BASE = 32768  # domain_coordinator's claim on domain N is this port + N, bound


def port_base() -> int:
    """domain_coordinator's base port (`BAGFAULT_DOMAIN_PORT_BASE` overrides, for tests of leases alone)."""
    return settings.domain_port_base(COORDINATOR_PORT_BASE)


def claim_port(domain: int) -> socket.socket | None:
    """Bind domain_coordinator's port of a domain (never listened on); None when someone holds it."""
    claim = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    try:
        claim.bind(('127.0.0.1', port_base() + domain))
    except OSError:
        claim.close()
        return None
    return claim


def lock_folder() -> Path:
    """Where the lock files live (`BAGFAULT_DOMAIN_LOCKS` overrides, for tests)."""
    folder = settings.domain_locks()
    if folder is not None:
        return folder
    return Path(tempfile.gettempdir()) / f'bagfault-domains-{os.getuid()}'


class DomainLease:
    """An exclusive claim on one ROS domain id; release it (or leave the `with`) when the run ends."""

    def __init__(self, first: int = FIRST, last: int = LAST, avoid: Collection[int] = ()) -> None:
        folder = lock_folder()
        folder.mkdir(parents=True, exist_ok=True)
        ours = os.environ.get('ROS_DOMAIN_ID', '0')
        ids = [domain for domain in range(first, last + 1) if domain not in avoid and str(domain) != ours]
        start = os.getpid() % max(1, len(ids))  # processes start their search at different places
        self._file: IO[bytes] | None = None
        self._claim: socket.socket | None = None
        self._path: Path | None = None
        sweep(folder)
        for domain in ids[start:] + ids[:start]:
            path = folder / f'{domain}.lock'
            handle = _locked(path)
            if handle is None:
                continue
            claim = claim_port(domain)
            if claim is None:  # a colcon test (domain_coordinator) or a bagfault of another TMPDIR has it
                _let_go(path, handle)
                continue
            self.domain = domain
            self._file, self._claim, self._path = handle, claim, path
            return
        raise ClosedLoopError(f'no free ROS domain id between {first} and {last}: each is held by another bagfault '
                              f'run (locks in {folder}) or a domain_coordinator (ports '
                              f'{port_base() + first}-{port_base() + last} on 127.0.0.1)')

    def release(self) -> None:
        """Give the id back, its lock file removed."""
        if self._file is not None and self._path is not None:
            _let_go(self._path, self._file)
            self._file = None
        if self._claim is not None:
            self._claim.close()
            self._claim = None

    def __enter__(self) -> DomainLease:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


def _locked(path: Path) -> IO[bytes] | None:
    """The lock file at `path`, opened (created if need be) and locked, or None when another process holds it.
    A file its holder removed while this process waited to lock it is not the lock any more: taken again."""
    for _ in range(8):
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            handle = path.open('a+b')
        except OSError:
            return None
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            handle.close()
            return None
        try:
            current = os.stat(path)
        except FileNotFoundError:
            current = None
        held = os.fstat(handle.fileno())
        if current is not None and (current.st_dev, current.st_ino) == (held.st_dev, held.st_ino):
            return handle
        handle.close()  # removed (or replaced) meanwhile: lock the file that is there now
    return None


def _let_go(path: Path, handle: IO[bytes]) -> None:
    """Remove a lock file this process holds (if the name is still that file), then unlock it (whoever locks
    the removed file takes it again)."""
    with contextlib.suppress(OSError):
        held, current = os.fstat(handle.fileno()), os.stat(path)
        if (held.st_dev, held.st_ino) == (current.st_dev, current.st_ino):
            os.unlink(path)
    with contextlib.suppress(OSError):
        fcntl.flock(handle, fcntl.LOCK_UN)
    handle.close()


def sweep(folder: Path) -> list[str]:
    """Remove the lock files no process holds (left by a run that was killed); their names."""
    removed = []
    with contextlib.suppress(OSError):
        for path in sorted(folder.glob('*.lock')):
            handle = _locked(path)
            if handle is not None:
                _let_go(path, handle)
                removed.append(path.name)
    return removed
