"""A free ROS_DOMAIN_ID held for a run, so concurrent tests on one machine never see each other.

A lease is an exclusive `flock` on a file named after the id in a folder
shared by every bagfault process of the user; the kernel releases it when
the process dies, so a crashed run never leaks a domain.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import tempfile
from pathlib import Path
from typing import IO

from bagfault.errors import ClosedLoopError

FIRST, LAST = 30, 101  # ids whose Fast DDS ports stay below Linux's ephemeral range (32768)


def lock_folder() -> Path:
    """Where the lock files live (`BAGFAULT_DOMAIN_LOCKS` overrides, for tests)."""
    folder = os.environ.get('BAGFAULT_DOMAIN_LOCKS')
    if folder:
        return Path(folder)
    return Path(tempfile.gettempdir()) / f'bagfault-domains-{os.getuid()}'


class DomainLease:
    """An exclusive claim on one ROS domain id; release it (or leave the `with`) when the run ends."""

    def __init__(self, first: int = FIRST, last: int = LAST) -> None:
        folder = lock_folder()
        folder.mkdir(parents=True, exist_ok=True)
        avoid = os.environ.get('ROS_DOMAIN_ID', '0')
        ids = list(range(first, last + 1))
        start = os.getpid() % len(ids)  # processes start their search at different places
        self._file: IO[bytes] | None = None
        for domain in ids[start:] + ids[:start]:
            if str(domain) == avoid:
                continue
            handle = (folder / f'{domain}.lock').open('a+b')
            try:
                fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                handle.close()
                continue
            self.domain = domain
            self._file = handle
            return
        raise ClosedLoopError(f'no free ROS domain id between {first} and {last}: {last - first + 1} runs '
                              f'hold one already (locks in {folder})')

    def release(self) -> None:
        """Give the id back."""
        if self._file is not None:
            with contextlib.suppress(OSError):
                fcntl.flock(self._file, fcntl.LOCK_UN)
            self._file.close()
            self._file = None

    def __enter__(self) -> DomainLease:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()
