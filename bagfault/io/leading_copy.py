"""A copy that runs ahead: an input's leading chunks copied into the output before the run has decided on them.

`bagfault run` spends its first few hundred milliseconds importing and
setting up, while the chunks at the start of a bag, before any fault, are
copied as they are anyway. A `LeadingCopy` is started first, on a guess of
where those chunks will land in the output, and copies them on a thread of
its own. The writer takes a copied span from it only where it copied exactly
those input bytes to exactly that place, and stops it at the first write of
its own into the range it covers; so a wrong guess costs time, never a byte
(see `McapWriter`).
"""

from __future__ import annotations

import contextlib
import os
import threading
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

from bagfault.io.file_copy import copy_range

if TYPE_CHECKING:
    from collections.abc import Iterator, Sequence
    from pathlib import Path

    from typing_extensions import Self

    from bagfault.io.outputs import PartialFile
    from bagfault.io.sources import ReadMark

PART = 64 << 20  # bytes per copy call: a stop waits for one part at most
SLOW_OPEN = 0.3  # seconds: an input open that takes longer reads from the disk (warm: 0.14 s for 3000 chunks)


@dataclass(frozen=True)
class Piece:
    """Input bytes [source, source + length) belong at output offset `target`."""

    source: int
    target: int
    length: int


class LeadingCopy:
    """Copies pieces of one input into an output's partial file, in order, until done or stopped.

    The file is the `PartialFile`'s, which outlives the copy: the copy writes
    into it and neither removes nor closes it.
    """

    def __init__(self, source: Path, pieces: Sequence[Piece], output: PartialFile) -> None:
        """Open `source` (OSError) and start copying into `output` (pieces as far as the input goes)."""
        self._input = os.open(source, os.O_RDONLY)
        self.fd = output.fd
        stat = os.fstat(self._input)
        size = stat.st_size
        self.pieces = sorted((Piece(p.source, p.target, min(p.length, size - p.source)) for p in pieces
                              if p.source < size and p.length > 0), key=lambda p: p.target)
        self.end = max((p.target + p.length for p in self.pieces), default=0)
        self.extent = 0  # the furthest output offset written
        self._identity = (stat.st_dev, stat.st_ino)
        self._same: dict[int, bool] = {}
        self._limit = self.end  # copy up to here, then stop
        self._lock = threading.Lock()
        self._failure: tuple[int, OSError] | None = None  # where a copy failed, and why
        self._closed = False
        self._mark: ReadMark | None = None  # told how far the input was read (`pace`)
        self._copied = False  # the thread is done
        self._stopping = False  # asked to stop: it no longer waits for a hash
        self._opening: float | None = None  # when the run began opening the input (see `opening`)
        self._source_reached = self.pieces[0].source if self.pieces else 0  # the input read up to here
        self._thread = threading.Thread(target=self._copy, name='bagfault-leading-copy', daemon=True)
        self._thread.start()

    def pace(self, mark: ReadMark) -> None:
        """Tell `mark` how far this copy has read the input, as it goes (the provenance hash follows it)."""
        with self._lock:
            if not self._copied:
                self._mark = mark
                mark.cap(self._source_reached)

    def _copy(self) -> None:
        try:
            self._copy_pieces()
        finally:
            with self._lock:
                self._copied = True
                if self._mark is not None:
                    self._mark.cap(None)

    def _copy_pieces(self) -> None:
        in_kernel = True
        for piece in self.pieces:
            for done in range(0, piece.length, PART):
                at, length = piece.target + done, min(PART, piece.length - done)
                self._wait_for_open()
                mark = self._mark
                if mark is not None:  # a first run's hash, reading the same input: not left behind
                    mark.wait_for_hash(piece.source + done, lambda: self._stopping)
                with self._lock:
                    if at >= self._limit:
                        return
                self.extent = max(self.extent, at + length)
                try:
                    in_kernel = copy_range(self._input, self.fd, piece.source + done, length, at, in_kernel=in_kernel)
                except OSError as exc:  # a full disk; or a guess past the input's end, which the writer never takes
                    self._failure = (at, exc)
                    return
                with self._lock:
                    self._source_reached = piece.source + done + length
                    if self._mark is not None:
                        self._mark.cap(self._source_reached)

    @contextlib.contextmanager
    def opening(self) -> Iterator[None]:
        """The run opens the input meanwhile (its reads of every chunk's record header). An open that takes
        longer than `SLOW_OPEN` reads from a cold disk: the copy waits for it to end, rather than share the
        disk with it (the two together read a 9.9 GB bag up to 1.6 times in a 4 GB page cache)."""
        with self._lock:
            self._opening = time.monotonic()
        try:
            yield
        finally:
            with self._lock:
                self._opening = None

    def _wait_for_open(self) -> None:
        while True:
            with self._lock:
                since = self._opening
            if since is None or self._stopping or time.monotonic() - since < SLOW_OPEN:
                return
            time.sleep(0.01)

    # -- the writer's questions -------------------------------------------------------------
    def covers(self, fd: int, offset: int, length: int, at: int) -> int:
        """How many bytes of `fd` from `offset`, placed at output offset `at`, this copy has put there or will
        (0 once stopped): a prefix of the span, as far as one of its pieces holds exactly those bytes."""
        with self._lock:
            if self._limit < self.end:
                return 0
        if not self._is_input(fd):
            return 0
        for piece in self.pieces:
            if piece.target <= at < piece.target + piece.length:
                if piece.source - piece.target != offset - at:
                    return 0
                return min(length, piece.target + piece.length - at)
        return 0

    def writes(self, at: int, length: int) -> bool:
        """Whether this copy may write into output bytes [at, at + length) (where one of its pieces lies)."""
        return any(p.target < at + length and at < p.target + p.length for p in self.pieces)

    def _is_input(self, fd: int) -> bool:
        same = self._same.get(fd)
        if same is None:
            stat = os.fstat(fd)
            same = self._same[fd] = (stat.st_dev, stat.st_ino) == self._identity
        return same

    def stop(self, keep: int) -> None:
        """Copy what lies before output offset `keep` (the writer has taken it), then nothing more; raise a
        copy of those bytes that failed (a failure past them only means the writer writes them itself)."""
        self._stopping = True
        with self._lock:
            self._limit = min(self._limit, keep)
        self._thread.join()
        failure, self._failure = self._failure, None
        if failure is not None and failure[0] < keep:
            raise failure[1]

    def close(self) -> None:
        """Stop copying and close the input (once; later calls do nothing). The output stays as it is."""
        if self._closed:
            return
        self._closed = True
        self._stopping = True
        with self._lock:
            self._limit = 0
        self._thread.join()
        with contextlib.suppress(OSError):
            os.close(self._input)

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
