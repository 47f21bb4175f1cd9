"""Chunks of one MCAP input read ahead on a second thread, as they are and (when they will be processed)
decompressed, so reading and zstd overlap the main thread's work.

zstd and file reads release the GIL; splitting records into messages does
not, so it stays on the main thread.
"""

from __future__ import annotations

import queue
import struct
import threading
from dataclasses import dataclass
from typing import TYPE_CHECKING

from bagfault.errors import InputError, one_line
from bagfault.io.mcap_writer import CopiedChunk

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator

    from bagfault.io.mcap_source import ChunkRef, McapSource

DEPTH = 8  # chunks read ahead at most


@dataclass
class RawChunk:
    """A chunk as read ahead: its message indexes (parsed), and its records when decompressed ahead."""

    ref: ChunkRef
    chunk: CopiedChunk
    records: memoryview | None


class ChunkReader:
    """Iterates the chunks of `refs` in order; `decompress(ref)` says which to decompress ahead."""

    def __init__(self, source: McapSource, refs: list[ChunkRef], decompress: Callable[[ChunkRef], bool]) -> None:
        self.source = source
        self.refs = refs
        self.decompress = decompress
        self._queue: queue.Queue[RawChunk | BaseException | None] = queue.Queue(DEPTH)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._read, name='bagfault-read-ahead', daemon=True)
        self._thread.start()

    def _read(self) -> None:
        try:
            with self.source.path.open('rb') as handle:
                for ref in self.refs:
                    if self._stop.is_set():
                        return
                    indexes = self.source.read_indexes(ref, handle)
                    records = None
                    if self.decompress(ref):
                        records = self.source.records_of(ref, self.source.read_record(ref, handle))
                    try:
                        chunk = CopiedChunk.of(self.source.fileno(), ref.offset, ref.length, indexes, ref.start,
                                               ref.end, ref.compression, ref.compressed_size, ref.uncompressed_size)
                    except (struct.error, ValueError) as exc:
                        raise InputError(f'{self.source.path}: corrupt message index after the chunk at offset '
                                         f'{ref.offset}: {one_line(exc)}') from None
                    self._put(RawChunk(ref, chunk, records))
        except BaseException as exc:  # noqa: BLE001 - handed to the main thread, raised there
            self._put(exc)
            return
        self._put(None)

    def _put(self, item: RawChunk | BaseException | None) -> None:
        while not self._stop.is_set():
            try:
                self._queue.put(item, timeout=0.1)
                return
            except queue.Full:
                continue

    def __iter__(self) -> Iterator[RawChunk]:
        while True:
            item = self._queue.get()
            if item is None:
                return
            if isinstance(item, BaseException):
                raise item
            yield item

    def close(self) -> None:
        """Stop reading (the thread ends at its next chunk)."""
        self._stop.set()
        self._thread.join(timeout=5)
