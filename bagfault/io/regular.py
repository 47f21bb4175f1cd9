"""Reading a named file whole, only when it is a regular file: a FIFO, a device or a socket given as a scenario,
a campaign or a message definition would block the reader for ever (or never end). Opened without blocking,
checked, then read; the refusal is an OSError, so each caller's own message for unreadable files says it."""

from __future__ import annotations

import errno
import os
import stat
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from pathlib import Path

KINDS = ((stat.S_ISFIFO, 'a FIFO'), (stat.S_ISCHR, 'a character device'), (stat.S_ISBLK, 'a block device'),
         (stat.S_ISSOCK, 'a socket'))


class NotRegularFileError(OSError):
    """The name is not a regular file."""

    def __init__(self, path: Path, kind: str) -> None:
        super().__init__(errno.EINVAL, f'not a regular file ({kind}: reading it could block for ever)', str(path))

    def __str__(self) -> str:
        return str(self.strerror)  # the callers name the file themselves


def kind_of(mode: int) -> str:
    """'a FIFO', 'a socket', ... for a file mode that is not a regular file's."""
    return next((name for test, name in KINDS if test(mode)), 'not a file')


def read_bytes(path: Path) -> bytes:
    """The whole file; NotRegularFileError (an OSError) unless it is a regular file."""
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)  # a FIFO opens at once, writer or not
    try:
        mode = os.fstat(fd).st_mode
        if stat.S_ISDIR(mode):  # as Path.read_bytes says it, so callers' own messages for folders stay
            raise IsADirectoryError(errno.EISDIR, os.strerror(errno.EISDIR), str(path))
        if not stat.S_ISREG(mode):
            raise NotRegularFileError(path, kind_of(mode))
        os.set_blocking(fd, True)
        chunks = []
        while chunk := os.read(fd, 1 << 20):
            chunks.append(chunk)
        return b''.join(chunks)
    finally:
        os.close(fd)


def read_text(path: Path, encoding: str = 'utf-8', errors: str = 'strict') -> str:
    """The whole file as text; NotRegularFileError (an OSError) unless it is a regular file."""
    return read_bytes(path).decode(encoding, errors)
