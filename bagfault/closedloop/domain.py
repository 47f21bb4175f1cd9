"""A free ROS_DOMAIN_ID held for a run, so concurrent tests on one machine never see each other.

A lease is an exclusive `flock` on a file named after the id in a folder
shared by every bagfault process of the user, and the TCP port 32768 + id
bound on 127.0.0.1, as ROS's `domain_coordinator` (colcon's isolated tests,
launch_testing) claims a domain: each sees the other's claims, whatever the
user or `TMPDIR`. The kernel releases both when the process dies, so a
crashed run never leaks a domain.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import socket
import tempfile
from pathlib import Path
from typing import IO, TYPE_CHECKING

from bagfault.errors import ClosedLoopError

if TYPE_CHECKING:
    from collections.abc import Collection

FIRST, LAST = 30, 101  # ids whose Fast DDS ports stay below Linux's ephemeral range (32768)
COORDINATOR_PORT_BASE = 32768  # domain_coordinator's claim on domain N is this port + N, bound


def port_base() -> int:
    """domain_coordinator's base port (`BAGFAULT_DOMAIN_PORT_BASE` overrides, for tests of leases alone)."""
    return int(os.environ.get('BAGFAULT_DOMAIN_PORT_BASE', COORDINATOR_PORT_BASE))


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
    folder = os.environ.get('BAGFAULT_DOMAIN_LOCKS')
    if folder:
        return Path(folder)
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
        for domain in ids[start:] + ids[:start]:
            handle = (folder / f'{domain}.lock').open('a+b')
            try:
                fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                handle.close()
                continue
            claim = claim_port(domain)
            if claim is None:  # a colcon test (domain_coordinator) or a bagfault of another TMPDIR has it
                handle.close()
                continue
            self.domain = domain
            self._file, self._claim = handle, claim
            return
        raise ClosedLoopError(f'no free ROS domain id between {first} and {last}: each is held by another bagfault '
                              f'run (locks in {folder}) or a domain_coordinator (ports '
                              f'{port_base() + first}-{port_base() + last} on 127.0.0.1)')

    def release(self) -> None:
        """Give the id back."""
        if self._file is not None:
            with contextlib.suppress(OSError):
                fcntl.flock(self._file, fcntl.LOCK_UN)
            self._file.close()
            self._file = None
        if self._claim is not None:
            self._claim.close()
            self._claim = None

    def __enter__(self) -> DomainLease:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()
