"""Open any supported input and merge several inputs in time order."""

from __future__ import annotations

import contextlib
import math
import mmap
import os
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import blake3

from bagfault.errors import InputError
from bagfault.io import digests
from bagfault.io.mcap_layout import MAGIC
from bagfault.io.mcap_source import McapSource
from bagfault.io.merged import MergedSource
from bagfault.io.rosbag2_source import Rosbag2Source
from bagfault.io.source import Source

if TYPE_CHECKING:
    from collections.abc import Iterator, Sequence


class ReadMark:
    """How far a run has read its one input file, so that its provenance hash follows the run through the file
    instead of reading it a second time: each page the hash reads (up to `lead` bytes ahead of the run) is still
    in the page cache when the run copies or decodes it, and the other way round (an input larger than the page
    cache is read from the disk once, bench/run.py --page-cache-gb)."""

    def __init__(self, lead: int = 128 << 20) -> None:
        self.lead = lead
        self._position = 0
        self._cap: int | None = None  # how far a leading copy has copied, while it copies
        self._hashed: int | None = None  # how far the hash has read, while it hashes
        self._released = False
        self._moved = threading.Condition()

    def advance(self, offset: int) -> None:
        """The run has asked for the input's bytes up to `offset`."""
        with self._moved:
            if offset > self._position:
                self._position = offset
                self._moved.notify_all()

    def cap(self, offset: int | None) -> None:
        """A leading copy has read the input up to `offset` (None: it reads no more); the run's position counts
        only up to there, since the run takes chunks from it before it has copied them, and a run that
        released the file still holds the hash to the copy."""
        with self._moved:
            self._cap = offset
            self._moved.notify_all()

    def hashed(self, offset: int | None) -> None:
        """The hash has read the input up to `offset` (None: it is done, or stopped)."""
        with self._moved:
            self._hashed = offset
            self._moved.notify_all()

    def wait_for_hash(self, offset: int, stopped: Callable[[], bool]) -> None:
        """A leading copy about to read from `offset` waits for a hash that is more than `lead` behind it: a
        copy that does not wait leaves the hash so far behind, on a cold disk, that the page cache no longer
        holds what it needs (the 2400 s bench read the input 1.8 times)."""
        with self._moved:
            while self._hashed is not None and offset > self._hashed + self.lead and not stopped():
                self._moved.wait(0.05)

    def release(self) -> None:
        """The run reads no more of the input in order (it ended, failed, or reads it another way)."""
        with self._moved:
            self._released = True
            self._moved.notify_all()

    def wait_for(self, offset: int, stop: threading.Event | None) -> None:
        """Block until the bytes before `offset` are within `lead` of the run (or the run released the file)."""
        with self._moved:
            while offset > self._reached() + self.lead:
                if stop is not None and stop.is_set():
                    return
                self._moved.wait(0.1)

    def _reached(self) -> float:
        """How far the input has been read in order, by the run and a leading copy."""
        if self._cap is not None:
            return self._cap if self._released else min(self._position, self._cap)
        return math.inf if self._released else self._position


@dataclass(frozen=True)
class InputFile:
    """One file that makes up an input, for the provenance record."""

    name: str
    size: int
    blake3: str  # hex digest (`b3sum` prints the same)


@dataclass(frozen=True)
class InputFormat:
    """An input format: how its files begin, and its reader (`open(path, salvage=)`)."""

    name: str
    begins: Callable[[bytes, Path], bool]  # the file's first 16 bytes and its name: is it one?
    open: Callable[..., Source]


def _ros1(path: Path, *, salvage: bool = False) -> Source:
    from bagfault.io.ros1_source import Ros1Source  # noqa: PLC0415 - its reader is imported when one is read

    return Ros1Source(path, salvage=salvage)


def _old_ros1(path: Path, *, salvage: bool = False) -> Source:
    with path.open('rb') as stream:
        version = stream.read(12)[1:].decode(errors='replace')
    raise InputError(f'{path}: ROS 1 bag format {version!r} is not supported (V2.0 only)')


FORMATS = (  # a file is read by the first whose beginning it has; a folder is a rosbag2 bag
    InputFormat('MCAP', lambda head, _: head.startswith(MAGIC[:5]), McapSource),
    InputFormat('ROS 1 bag', lambda head, _: head.startswith(b'#ROSBAG V2.0'), _ros1),
    InputFormat('ROS 1 bag of an older format', lambda head, _: head.startswith(b'#ROSBAG'), _old_ros1),
    InputFormat('rosbag2 storage file', lambda head, path: head.startswith(b'SQLite format 3') or
                path.name.endswith('.zstd'), Rosbag2Source),
)


def open_source(path: Path, *, salvage: bool = False) -> Source:
    """Open an MCAP file, a rosbag2 directory or storage file, or a ROS 1 bag (the reader from `FORMATS`)."""
    if not path.exists():
        if path.is_symlink():
            raise InputError(f'{path}: a symbolic link that leads nowhere (its target is missing, or links loop)')
        raise InputError(f'{path}: no such file or directory')
    if path.is_dir():
        return Rosbag2Source(path, salvage=salvage)
    require_regular(path)
    try:
        with path.open('rb') as stream:
            head = stream.read(16)
    except OSError as exc:
        raise InputError(f'{path}: cannot read: {exc.strerror}') from None
    if not head:
        raise InputError(f'{path}: file is empty')
    for kind in FORMATS:
        if kind.begins(head, path):
            return kind.open(path, salvage=salvage)
    raise InputError(f'{path}: not a bag (expected MCAP, rosbag2 .db3, a rosbag2 directory or a ROS 1 .bag)')


def require_regular(path: Path) -> None:
    """InputError for a FIFO, device or socket: reading one would block the run (or never end)."""
    if path.exists() and not path.is_file() and not path.is_dir():
        raise InputError(f'{path}: not a regular file (a FIFO, device or socket is not a bag)')


def input_files(path: Path) -> list[Path]:
    """The files that make up an input, in a stable order (regular files only: InputError for others)."""
    if path.is_dir():
        return sorted(x for x in path.iterdir() if x.is_file() and not x.name.endswith(('-shm', '-wal')))
    require_regular(path)
    return [path]


StatKey = tuple[int, int, int, int, int]  # device, inode, size, mtime_ns, ctime_ns: the same file, unchanged
_known: dict[StatKey, str] = {}  # digests this process was given (a campaign job: the plan hashed the bag)


def stat_key(file: Path) -> StatKey:
    """What identifies a file's content without reading it (any write changes ctime)."""
    info = file.stat()
    return info.st_dev, info.st_ino, info.st_size, info.st_mtime_ns, info.st_ctime_ns


def remember_digests(known: dict[StatKey, str]) -> None:
    """Digests computed elsewhere for files as they are now (a campaign's plan, a node's cache), so this
    process does not read those files a second time to hash them; a file changed since is hashed again."""
    _known.update(known)


def fingerprint(path: Path, stop: threading.Event | None = None, mark: ReadMark | None = None) -> list[InputFile]:
    """Name, size and BLAKE3 digest of each file of an input. BLAKE3 rather than sha256 because it hashes
    4 GB/s on one core here against sha256's 0.8 GB/s, so the hash of a bag stays below the time of copying
    it (README, Chunk copy). `stop` set: give up at the next window (the run failed; nobody waits for it).
    `mark`: the run reads this one-file input in order; the hash keeps pace with it."""
    out = []
    for file in input_files(path):
        try:
            key = stat_key(file)
            out.append(InputFile(file.name, key[2], _digest(file, key, stop, mark)))
        except OSError as exc:
            raise InputError(f'{file}: cannot read: {exc.strerror or exc}') from None
    return out


def digests_of(path: Path) -> dict[StatKey, str]:
    """Each file of an input by its stat key, with its digest (to hand to `remember_digests` elsewhere)."""
    return {(key := stat_key(file)): _digest(file, key, None) for file in input_files(path)}


def _digest(file: Path, key: StatKey, stop: threading.Event | None, mark: ReadMark | None = None) -> str:
    """The file's BLAKE3: given to this process, kept from an earlier run (io/digests.py), or hashed now."""
    known = _known.get(key) or digests.recall(key)
    if known is not None:
        return known
    started = time.time_ns()  # the wall clock, as file times are stamped
    digest = _blake3(file, stop, mark)
    digests.keep(key, digest, started)
    return digest


class HashStopped(Exception):  # noqa: N818 - a signal to the hashing thread, never shown
    """The run ended before the input was hashed."""


def _blake3(file: Path, stop: threading.Event | None, mark: ReadMark | None = None, window: int = 16 << 20) -> str:
    """Hex BLAKE3 of a file, hashed through mapped windows: no copy through a buffer (0.4 s per GB here
    against 0.6 s reading it), memory bounded by the window, the GIL released while it hashes; with `mark`,
    each window only once the run is near it."""
    digest = blake3.blake3()
    with file.open('rb') as stream, _hashing(mark):
        size = os.fstat(stream.fileno()).st_size
        try:
            for offset in range(0, size, window):
                if mark is not None:
                    mark.hashed(offset)
                    mark.wait_for(offset + window, stop)
                if stop is not None and stop.is_set():
                    raise HashStopped
                with mmap.mmap(stream.fileno(), min(window, size - offset), access=mmap.ACCESS_READ,
                               offset=offset) as mapped:
                    digest.update(mapped)
        except OSError:  # a file system that cannot map files: read it
            if mark is not None:
                mark.hashed(None)
            digest = blake3.blake3()
            stream.seek(0)
            while block := stream.read(1 << 22):
                digest.update(block)
    return str(digest.hexdigest())


@contextlib.contextmanager
def _hashing(mark: ReadMark | None) -> Iterator[None]:
    """However the hash ends, a leading copy no longer waits for it."""
    try:
        yield
    finally:
        if mark is not None:
            mark.hashed(None)


class InputSet(MergedSource):
    """The inputs of a run (files and rosbag2 directories) seen as one bag."""

    def __init__(self, paths: Sequence[Path], *, salvage: bool = False) -> None:
        self.paths = list(paths)
        sources: list[Source] = []
        try:
            for path in self.paths:
                sources.append(open_source(path, salvage=salvage))
        except BaseException:
            for source in sources:
                source.close()
            raise
        super().__init__(sources)
