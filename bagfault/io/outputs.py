"""Output paths that are safe to write, and writes that never leave half a file under the requested name."""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING

from bagfault.errors import OutputError

if TYPE_CHECKING:
    from collections.abc import Sequence


def check_output(path: Path, what: str, protected: Sequence[tuple[str, Path]]) -> None:
    """Refuse an output that is a folder, lands in a missing folder, or would replace or go inside a protected path.

    `protected` names what the command reads or writes besides this output
    (inputs, the scenario, the main output, other reports).
    """
    if path.is_dir():
        raise OutputError(f'{path}: {what} is a directory; give a file name')
    folder = path.parent if str(path.parent) else Path('.')
    if not folder.is_dir():
        raise OutputError(f'{path}: {what}: folder {folder} does not exist')
    resolved = path.resolve()
    for name, other in protected:
        target = other.resolve()
        if resolved == target:
            raise OutputError(f'{path}: {what} would replace {name} {other}; choose another name')
        if target.is_dir() and target in resolved.parents:
            raise OutputError(f'{path}: {what} would be written inside {name} {other}; choose another folder')


def write_atomic(path: Path, data: bytes | str) -> None:
    """Write a whole file under a temporary name in the same folder, then rename it."""
    folder = path.parent if str(path.parent) else Path('.')
    payload = data.encode() if isinstance(data, str) else data
    try:
        handle, tmp = tempfile.mkstemp(prefix=f'.{path.name}.', suffix='.partial', dir=folder)
    except OSError as exc:
        raise OutputError(f'{path}: cannot write: {exc.strerror}') from None
    try:
        with os.fdopen(handle, 'wb') as stream:
            stream.write(payload)
        os.chmod(tmp, 0o666 & ~current_umask())
        os.replace(tmp, path)
    except OSError as exc:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise OutputError(f'{path}: cannot write: {exc.strerror}') from None
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def current_umask() -> int:
    """The process umask (read by setting and restoring it)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def written_by_bagfault(path: Path) -> bool:
    """Whether a file is an MCAP whose header names bagfault as its writer (a file bagfault may replace)."""
    try:
        with path.open('rb') as stream:
            head = stream.read(8 + 9 + 4 + 256 + 4 + 64)
    except OSError:
        return False
    if head[:8] != b'\x89MCAP0\r\n' or len(head) < 21 or head[8] != 0x01:
        return False
    profile_length = int.from_bytes(head[17:21], 'little')
    at = 21 + profile_length
    if at + 4 > len(head):
        return False
    library_length = int.from_bytes(head[at:at + 4], 'little')
    return head[at + 4:at + 4 + library_length].startswith(b'bagfault ')  # as McapSink names itself
