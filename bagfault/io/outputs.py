"""Output paths that are safe to write, and writes that never leave half a file under the requested name.

An output may not be anything the command reads, by file identity (device and inode, so neither a hard
link nor a symlink gets past): an input, a file inside an input folder, an SQLite input's `-wal`, `-shm`
and `-journal` sidecars (a stray `-wal` beside a database is replayed into it by the next reader), the
scenario, a `--msg-path` file. It must be a regular file or a new name, and an existing file must be one
bagfault wrote (it carries its mark: io/marks.py), unless the caller forces it.
"""

from __future__ import annotations

import contextlib
import os
import stat
import struct
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, BinaryIO, Literal

from bagfault.errors import OutputError
from bagfault.io.marks import MCAP_RECORD, Kind, is_marked, mcap_mark, sidecar, stamp, table_mark
from bagfault.io.mcap_layout import MAGIC
from bagfault.io.regular import read_bytes, read_text

if TYPE_CHECKING:
    from collections.abc import Iterable, Sequence

    from typing_extensions import Self

SIDECARS = ('-wal', '-shm', '-journal')
PUBLISHED: list[Path] = []  # every file this process has put under its final name, in order (what a stop says)
FOLDER_FILES_MAX = 100_000  # files of a protected folder looked at (a msg path is a tree)


@dataclass
class Protected:
    """What a command reads or writes besides one output: names and file identities."""

    named: list[tuple[str, Path]] = field(default_factory=list)
    identities: dict[tuple[int, int], tuple[str, Path]] = field(default_factory=dict)
    names: dict[Path, tuple[str, Path]] = field(default_factory=dict)  # resolved names, existing or not

    @classmethod
    def of(cls, pairs: Iterable[tuple[str, Path]]) -> Protected:
        """Each (what, path): the path, the files of a folder, an SQLite file's sidecars."""
        out = cls()
        for name, path in pairs:
            out.named.append((name, path))
            out._add(name, path, path)
            if path.is_dir():
                for count, inner in enumerate(_walk(path)):
                    if count >= FOLDER_FILES_MAX:
                        break
                    out._add(name, path, inner)
            elif path.is_file():
                real = path.resolve()  # a symlinked database keeps its sidecars beside the real file
                for base in dict.fromkeys((path, real)):
                    for suffix in SIDECARS:
                        out._add(f"{name}'s SQLite sidecar", path, base.with_name(base.name + suffix))
        return out

    def holding(self, folder: Path) -> tuple[str, Path] | None:
        """The named folder that `folder` is or lies inside (where an output folder must not be), or None."""
        with contextlib.suppress(OSError, RuntimeError):
            where = folder.resolve()
            for name, path in self.named:
                with contextlib.suppress(OSError, RuntimeError):
                    target = path.resolve()
                    if path.is_dir() and (where == target or target in where.parents):
                        return name, path
        return None

    def _add(self, name: str, top: Path, path: Path) -> None:
        with contextlib.suppress(OSError, RuntimeError):
            self.names.setdefault(path.resolve(), (name, path))
        with contextlib.suppress(OSError):
            info = path.stat()
            self.identities.setdefault((info.st_dev, info.st_ino), (name, top if path == top else path))


def _walk(folder: Path) -> Iterable[Path]:
    for root, _dirs, files in os.walk(folder):
        for name in files:
            yield Path(root) / name


def check_output(path: Path, what: str, protected: Sequence[tuple[str, Path]] | Protected, *,
                 force: bool = False) -> None:
    """Refuse an output that is a folder or not a regular file, lands in a missing folder, is (or is inside)
    something protected, or replaces an existing file bagfault did not write (unless `force`).

    `protected` names what the command reads or writes besides this output (inputs, the scenario, the
    main output, other reports).
    """
    guard = protected if isinstance(protected, Protected) else Protected.of(protected)
    if path.is_dir():
        raise OutputError(f'{path}: {what} is a directory; give a file name')
    folder = path.parent if str(path.parent) else Path('.')
    if not folder.is_dir():
        raise OutputError(f'{path}: {what}: folder {folder} does not exist')
    try:
        resolved = path.resolve()
    except (OSError, RuntimeError) as exc:  # a symlink loop
        raise OutputError(f'{path}: {what}: cannot resolve the name ({exc})') from None
    hit = guard.names.get(resolved)
    if hit is not None:
        raise OutputError(f'{path}: {what} would replace {hit[0]} {hit[1]}; choose another name')
    for name, other in guard.named:
        with contextlib.suppress(OSError, RuntimeError):
            target = other.resolve()
            if target.is_dir() and target in resolved.parents:
                raise OutputError(f'{path}: {what} would be written inside {name} {other}; choose another folder')
    try:
        info = path.stat()
    except FileNotFoundError:
        return
    except OSError as exc:
        raise OutputError(f'{path}: {what}: cannot look at the existing file: {exc.strerror}') from None
    hit = guard.identities.get((info.st_dev, info.st_ino))
    if hit is not None:
        raise OutputError(f'{path}: {what} is the same file as {hit[0]} {hit[1]}; choose another name')
    if not stat.S_ISREG(info.st_mode):
        raise OutputError(f'{path}: {what} exists and is not a regular file ({_kind(info.st_mode)}); '
                          'give a file name')
    if not force and not written_by_bagfault(path):
        raise OutputError(f'{path}: {what} exists and bagfault did not write it; nothing replaced '
                          '(--force replaces it)')


def check_derived(base: Path, pattern: str, what: str, protected: Sequence[tuple[str, Path]] | Protected, *,
                  force: bool = False) -> None:
    """Every existing file a run may write under names derived from `base` (`pattern` a glob in its folder)."""
    guard = protected if isinstance(protected, Protected) else Protected.of(protected)
    folder = base.parent if str(base.parent) else Path('.')
    with contextlib.suppress(OSError):
        for path in sorted(folder.glob(pattern)):
            check_output(path, what, guard, force=force)


def _kind(mode: int) -> str:
    kinds = ((stat.S_ISFIFO, 'a FIFO'), (stat.S_ISCHR, 'a character device'), (stat.S_ISBLK, 'a block device'),
             (stat.S_ISSOCK, 'a socket'))
    return next((name for test, name in kinds if test(mode)), 'not a file')


def write_atomic(path: Path, data: bytes | str, kind: Kind) -> None:
    """Write a whole file, with its mark (io/marks.py), under a temporary name in the same folder, then rename
    it; a table's mark goes beside it, after it."""
    payload = stamp(data.encode() if isinstance(data, str) else data, kind)
    _replace(path, payload)
    if kind == 'table':
        _replace(sidecar(path), table_mark(path.name, payload).encode(), published=False)


def mark_table(path: Path) -> None:
    """Mark a table or log bagfault wrote piece by piece (an exploration's runs.jsonl), now that it is whole."""
    try:
        data = read_bytes(path)
    except OSError as exc:
        raise OutputError(f'{path}: cannot read back: {exc.strerror or exc}') from None
    _replace(sidecar(path), table_mark(path.name, data).encode(), published=False)


def _replace(path: Path, payload: bytes, *, published: bool = True) -> None:
    folder = path.parent if str(path.parent) else Path('.')
    try:
        handle, tmp = tempfile.mkstemp(prefix=f'.{path.name}.', suffix='.partial', dir=folder)
    except OSError as exc:
        raise OutputError(f'{path}: cannot write: {exc.strerror}') from None
    try:
        with os.fdopen(handle, 'wb') as stream:
            stream.write(payload)
        os.chmod(tmp, 0o666 & ~current_umask())
        os.replace(tmp, path)
        if published:
            PUBLISHED.append(path)
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
    """Whether bagfault wrote a file as it is now (so a run may replace it): it holds its own valid mark, or
    has one beside it (io/marks.py). A look at its first bytes is no proof: nothing else counts."""
    try:
        marker = sidecar(path)
        if marker.is_file() and not marker.is_symlink():
            return read_text(marker).strip() == table_mark(path.name, read_bytes(path))
        with path.open('rb') as stream:
            size = os.fstat(stream.fileno()).st_size
            if stream.read(len(MAGIC)) == MAGIC:
                return _mcap_marked(stream, size)
            if size > MARKED_TEXT_MAX:
                return False
            stream.seek(0)
            return is_marked(stream.read())
    except (OSError, ValueError):
        return False


MARKED_TEXT_MAX = 256 << 20  # text read whole to check its mark; a larger file needs --force


def _mcap_marked(stream: BinaryIO, size: int) -> bool:
    """The file's `bagfault.mark` record (named by the summary's metadata index) matches its offset and the
    summary's chunk index records; the chunks are not read."""
    from bagfault.io import mcap_summary  # noqa: PLC0415 - struct and the mcap record classes only
    from bagfault.io.mcap_layout import OP_CHUNK_INDEX  # noqa: PLC0415

    try:
        start, section = mcap_summary.read_section(stream, size)
        if not start:
            return False
        indexes = [i for i in mcap_summary.parse_summary(section).metadata_indexes if i.name == MCAP_RECORD]
        if not indexes:
            return False
        record = mcap_summary.read_metadata(stream, indexes[-1])
        chunks = mcap_summary.raw_records(section, OP_CHUNK_INDEX)
    except (mcap_summary.SummaryError, struct.error):
        return False
    return record.name == MCAP_RECORD and record.metadata.get('mark') == mcap_mark(indexes[-1].offset, chunks)


class PartialFile:
    """An output file's one owner, from the command line to its last byte: its bytes grow under a new name
    beside it (`.NAME.XXXX.partial`) until `publish` moves them under the name; `close` removes them unless
    published. A leading copy writes into `fd`; the sink writes into it and publishes it or drops it through
    this owner; nothing else makes, renames or removes the file."""

    def __init__(self, path: Path) -> None:
        """Make the partial file (OutputError when its folder is missing or not writable)."""
        directory = path.parent if str(path.parent) else Path('.')
        if path.is_dir():
            raise OutputError(f'{path}: is a directory; give a file name such as out.mcap')
        if not directory.is_dir():
            raise OutputError(f'{path}: directory {directory} does not exist')
        try:
            self.fd, name = tempfile.mkstemp(prefix=f'.{path.name}.', suffix='.partial', dir=directory)
        except OSError as exc:
            raise OutputError(f'{path}: cannot write in {directory}: {exc.strerror}') from None
        os.chmod(self.fd, 0o666 & ~current_umask())  # mkstemp makes 0600; outputs get the usual permissions
        self.path = path
        self.partial = Path(name)  # where the file grows (`bagfault recover` reads it after a kill)
        self.state: Literal['open', 'published', 'removed'] = 'open'

    def clear(self) -> None:
        """Empty the file (what a leading copy stopped before the run wrote in it is not the run's)."""
        try:
            os.ftruncate(self.fd, 0)
        except OSError as exc:
            raise OutputError(f'{self.path}: cannot write: {exc.strerror or exc}') from None

    def publish(self) -> None:
        """Close the file and move it under its name (OutputError when that fails: the file is removed)."""
        try:
            self._close_fd()
            os.replace(self.partial, self.path)
        except OSError as exc:
            self.close()
            raise OutputError(f'{self.path}: cannot write: {exc.strerror or exc}') from None
        self.state = 'published'
        PUBLISHED.append(self.path)

    def close(self) -> None:
        """Remove the file unless it was published (once; later calls do nothing)."""
        if self.state != 'open':
            return
        self.state = 'removed'
        with contextlib.suppress(OSError):
            self._close_fd()
        self.partial.unlink(missing_ok=True)

    def _close_fd(self) -> None:
        fd, self.fd = self.fd, -1  # closed once: the number may soon be another file's
        if fd >= 0:
            os.close(fd)

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
