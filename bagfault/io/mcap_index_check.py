"""An indexed MCAP file's data section checked against its summary, without decompressing a chunk.

Each indexed chunk's record header (type, length, times, compression, sizes)
against its chunk index; its message index records (type, channel, entries
inside the chunk's extent and time range) against the offsets the index gives;
every record of the data section walked, so that a chunk the index lacks, a
message outside any chunk and what follows an early DataEnd are found too
(readers that follow the index skip them); the Statistics record against the
message indexes. Record headers only: one read per chunk and one for its
message indexes.
"""

from __future__ import annotations

import contextlib
import mmap
import os
import struct
import sys
from array import array
from typing import TYPE_CHECKING

from bagfault.errors import one_line
from bagfault.io.mcap_chunks import Corrupt, IndexedChunk, Split
from bagfault.io.mcap_layout import (
    CHUNK_HEAD,
    INDEX_HEAD,
    MESSAGE_FIELDS,
    MESSAGE_HEAD,
    OP_CHUNK,
    OP_DATA_END,
    OP_MESSAGE,
    OP_MESSAGE_INDEX,
    RECORD_HEAD,
    U32,
)

if TYPE_CHECKING:
    from bagfault.io.mcap_chunks import Lost


class ScatteredReads:
    """Small reads at scattered offsets of a file, through a map of it advised MADV_RANDOM: the kernel reads
    the pages asked for and nothing around them, even where another reader's read-ahead marks are (a read()
    that meets one starts a read-ahead of its own, and a walk forward through the file then reads all of it:
    the 2400 s bench's open read 9.8 GB beside a leading copy). Pages mapped are let go every `UNMAP_EVERY`
    reads (the kernel maps up to 64 KB around each fault), so they do not add up in the process's resident
    size (1.6 GB on that bag before). Plain reads where the file cannot be mapped."""

    UNMAP_EVERY = 256

    def __init__(self, fd: int) -> None:
        self.fd = fd
        self._reads = 0
        self._map: mmap.mmap | None = None
        with contextlib.suppress(OSError, ValueError):
            self._map = mmap.mmap(fd, 0, access=mmap.ACCESS_READ)
            if hasattr(mmap, 'MADV_RANDOM'):
                self._map.madvise(mmap.MADV_RANDOM)

    def read(self, length: int, offset: int) -> bytes:
        """Up to `length` bytes from `offset` (fewer at the end of the file)."""
        if self._map is None:
            return os.pread(self.fd, length, offset)
        self._reads += 1
        if self._reads % self.UNMAP_EVERY == 0 and hasattr(mmap, 'MADV_DONTNEED'):
            self._map.madvise(mmap.MADV_DONTNEED)  # a file's map: its pages stay in the page cache
        return self._map[offset:offset + length]

    def close(self) -> None:
        if self._map is not None:
            self._map.close()


class DataSection:
    """The walk of one file's data section: what it finds is added to `chunks` (unindexed chunks, each
    indexed one's message counts) and `loose` (messages outside chunks); losses go to `lost`, remarks to
    `warnings`."""

    NUMPY_AFTER = 1_000_000
    """Message index entries bounded in Python (about 75 ns each) before numpy is imported for the rest: as
    many as cost what numpy's import does (about 0.1 s), so a walk never pays more than twice the cheaper way,
    and a run on a bag below it whose faults never act imports no numpy at all. Where numpy is loaded already
    (a campaign's or explore's worker) it is used from the first entry."""

    def __init__(self, fd: int, data_end: int, lost: Lost) -> None:
        self.fd, self.data_end, self.lost = fd, data_end, lost
        self._bounded_in_python = 0  # entries so far, against NUMPY_AFTER
        self.loose: list[Split] = []  # message records outside any chunk (the specification allows them)
        self.warnings: list[str] = []

    def check(self, chunks: list[IndexedChunk]) -> list[IndexedChunk]:
        """Every record of the data section, to its end; the chunks (the index's and those found) in time order.
        The kernel reads no more than those records (no read-ahead): from a cold disk that is all this walk
        needs, and a leading copy reading the whole file meanwhile does not have to share the disk with it."""
        reads = ScatteredReads(self.fd)
        try:
            return self._walk(reads, chunks)
        finally:
            reads.close()

    def _walk(self, reads: ScatteredReads, chunks: list[IndexedChunk]) -> list[IndexedChunk]:
        chunks = list(chunks)
        indexed = {c.offset: c for c in chunks}
        position, end = 8, self.data_end
        loose: list[tuple[int, int]] = []  # (offset, length) of message records outside any chunk
        ended: int | None = None  # where a DataEnd record stood before the end of the data section
        while position + 9 <= end:
            chunk = indexed.get(position)
            if chunk is not None:
                self._check_chunk(reads, chunk)
                position = chunk.offset + chunk.length
                if chunk.index_offsets and min(chunk.index_offsets.values()) == position:
                    position += chunk.index_length
                continue
            head = reads.read(9 + 16, position)
            if len(head) < 9:
                break
            opcode, length = RECORD_HEAD.unpack_from(head)
            if opcode == OP_DATA_END and ended is None:
                ended = position  # records may follow it: every one is looked at
            if position + 9 + length > end:
                self.lost(f'record at offset {position}', f'claims {length} bytes, past the data section; the '
                                                          'file is not read beyond it')
                break
            if opcode == OP_CHUNK:
                start, stop = struct.unpack_from('<QQ', head, 9) if len(head) >= 25 else (0, 0)
                self.lost(f'chunk at offset {position}', 'not in the chunk index, which readers follow (its '
                                                         'messages would be skipped); read as well')
                chunks.append(IndexedChunk(start, stop, position, 9 + length))
            elif opcode == OP_MESSAGE:
                loose.append((position, length))
            position += 9 + length
        self._read_loose(reads, loose)
        if ended is not None and any(c.offset > ended for c in chunks):
            self.warnings.append(f'chunks follow the DataEnd record at offset {ended}, which should end the data '
                                 'section; they are read')
        return sorted(chunks, key=lambda c: (c.start, c.offset))

    def _read_loose(self, reads: ScatteredReads, loose: list[tuple[int, int]]) -> None:
        """Message records outside any chunk: the specification allows them and readers that follow the chunk
        index skip them; bagfault reads them (into memory, as they are few) and merges them in time order."""
        for position, length in loose:
            if length < MESSAGE_HEAD:
                self.lost(f'message record at offset {position}', f'{length} bytes, shorter than its header')
                continue
            data = memoryview(bytes(reads.read(9 + length, position)))
            if len(data) != 9 + length:
                self.lost(f'message record at offset {position}', 'runs past the end of the file')
                continue
            channel_id, _seq, log_time, publish_time = MESSAGE_FIELDS.unpack_from(data, 9)
            self.loose.append((log_time, publish_time, channel_id, position, data[9 + MESSAGE_HEAD:]))
        self.loose.sort(key=lambda m: (m[0], m[3]))

    def _check_chunk(self, reads: ScatteredReads, chunk: IndexedChunk) -> None:
        """One indexed chunk's record header and message index records against its chunk index."""
        head = reads.read(9 + CHUNK_HEAD.size + 4 + 64, chunk.offset)
        where = f'chunk at offset {chunk.offset}'
        if len(head) < 9 + CHUNK_HEAD.size + 4:
            self.lost(where, 'the chunk index points past the end of the file')
            return
        opcode, length = RECORD_HEAD.unpack_from(head)
        start, end, size, _ = CHUNK_HEAD.unpack_from(head, 9)
        (name_length,) = U32.unpack_from(head, 9 + CHUNK_HEAD.size)
        name = bytes(head[9 + CHUNK_HEAD.size + 4:][:name_length])
        told = (OP_CHUNK, chunk.length, chunk.start, chunk.end, chunk.uncompressed_size, chunk.compression.encode())
        found = (opcode, 9 + length, start, end, size, name)
        if found != told:
            fields = ('type', 'length', 'start time', 'end time', 'uncompressed size', 'compression')
            differ = '; '.join(f'{f} {a!r} in the record, {b!r} in the index'
                               for f, a, b in zip(fields, found, told, strict=True) if a != b)
            self.lost(where, f'the record and its chunk index disagree ({differ})')
            return
        if not chunk.index_offsets:
            return
        try:
            counts = self._index_counts(reads, chunk, start, end, size)
        except (struct.error, ValueError) as exc:
            self.lost(where, f'its message indexes cannot be read ({one_line(exc)})')
            return
        except Corrupt as exc:
            self.lost(where, str(exc))
            return
        if set(counts) != set(chunk.index_offsets):
            self.lost(where, f'its chunk index lists message indexes of channels {sorted(chunk.index_offsets)}, '
                             f'the file holds {sorted(counts)}')
            return
        chunk.counts = counts

    def _index_counts(self, reads: ScatteredReads, chunk: IndexedChunk, start: int, end: int,
                      size: int) -> dict[int, int]:
        """Entries per channel of a chunk's message index records, each where the chunk index says and every
        entry inside the chunk (its records' extent, its time range)."""
        offsets = chunk.index_offsets or {}
        first = min(offsets.values())
        data = reads.read(chunk.index_length, first) if first >= chunk.offset + chunk.length else b''
        counts, at, parts = {}, 0, []
        while at < len(data):
            opcode, length, channel_id, entries_length = INDEX_HEAD.unpack_from(data, at)
            if opcode != OP_MESSAGE_INDEX or at + 9 + length > len(data) or 6 + entries_length > length:
                raise Corrupt(f'a record of type {opcode:#x} where its message indexes should be')
            if offsets.get(channel_id) != first + at:
                raise Corrupt(f'a message index of channel {channel_id} the chunk index does not list there')
            counts[channel_id] = entries_length // 16
            parts.append(data[at + 15:at + 15 + entries_length // 16 * 16])
            at += 9 + length
        entries = b''.join(parts)  # (log time, offset) pairs, every channel
        if entries:
            first_time, last_time, last_offset = self._bounds(entries)
            if last_offset + 9 + MESSAGE_HEAD > size or first_time < start or last_time > end:
                raise Corrupt('its message indexes point outside the chunk (an offset past its records, or a '
                              'time outside its range)')
        return counts

    def _bounds(self, entries: bytes) -> tuple[int, int, int]:
        """(least log time, greatest log time, greatest offset) of message index entries, in Python until
        NUMPY_AFTER entries (or numpy is loaded), with numpy after."""
        count = len(entries) // 16
        if 'numpy' in sys.modules or self._bounded_in_python + count > self.NUMPY_AFTER:
            return bounds_with_numpy(entries)
        self._bounded_in_python += count
        return bounds_in_python(entries)


def bounds_in_python(entries: bytes) -> tuple[int, int, int]:
    """(least log time, greatest log time, greatest offset) of little-endian (log time, offset) pairs."""
    words = array('Q', entries)
    if sys.byteorder != 'little':
        words.byteswap()
    times = words[0::2]
    return min(times), max(times), max(words[1::2])


def bounds_with_numpy(entries: bytes) -> tuple[int, int, int]:
    """bounds_in_python's result at 1.3 ns an entry instead of 75, once numpy's import (0.1 s) is paid."""
    import numpy as np  # noqa: PLC0415

    pairs = np.frombuffer(entries, '<u8').reshape(-1, 2)
    return int(pairs[:, 0].min()), int(pairs[:, 0].max()), int(pairs[:, 1].max())


def check_statistics(chunks: list[IndexedChunk], loose: list[Split], total: int, declared: dict[int, int],
                     lost: Lost) -> None:
    """The Statistics record's messages (per channel, or in total where a writer left the map empty) against
    the message indexes of every chunk and the messages outside chunks (each chunk's indexes are checked
    against its records when it is decompressed, or under --verify)."""
    if any(c.counts is None and c.index_offsets is not None for c in chunks):
        return
    if any(c.index_offsets is None or not c.index_offsets for c in chunks):
        return  # unindexed chunks (salvage) or chunks without message indexes: not countable here
    indexed: dict[int, int] = {}
    for _, _, channel_id, _, _ in loose:
        indexed[channel_id] = indexed.get(channel_id, 0) + 1
    for chunk in chunks:
        for channel_id, count in (chunk.counts or {}).items():
            indexed[channel_id] = indexed.get(channel_id, 0) + count
    if not declared:
        if total != sum(indexed.values()):
            lost('the Statistics record', f'declares {total} messages, the message indexes '
                                          f'{sum(indexed.values())}')
        return
    differ = [f'channel {cid}: {declared.get(cid, 0)} declared, {indexed.get(cid, 0)} indexed'
              for cid in sorted(set(declared) | set(indexed)) if declared.get(cid, 0) != indexed.get(cid, 0)]
    if differ:
        lost('the Statistics record', f'its messages per channel and the message indexes disagree '
                                      f'({"; ".join(differ[:3])})')
