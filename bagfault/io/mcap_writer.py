"""A lean MCAP writer: message records packed by hand, chunks compressed on a second thread.

Everything but the hot path uses the record classes of the `mcap` library
(schemas, channels, chunk and summary records). Message records are packed
with one struct call each into the open chunk; full chunks are handed to a
worker thread that computes the CRC and compresses (zstd and lz4 release
the GIL), and are written in order as they complete, so compression runs
on the second core while the main thread reads and injects. The file has
the layout of the `mcap` library's writer (chunks with message indexes,
repeated schemas and channels, statistics, chunk/metadata/attachment
indexes, summary offsets) and is byte-identical from run to run. An
input's chunks can be copied into it as they are, by a copy thread or ahead
of the run by a leading copy (`io/leading_copy.py`); so that they can come
right after the header and the input's own schemas and channels, new ones
are written just before the writer's next record of its own. A run of
copied chunks of 1 MiB or more is placed a multiple of 64 KiB from where it
is in the input, after a padding record (an application opcode every reader
skips), where the kernel copies it as fast as `cp` (`io/mcap_layout.py`).
"""

from __future__ import annotations

import contextlib
import os
import struct
import zlib
from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from itertools import chain
from typing import IO, TYPE_CHECKING

import lz4.frame
import zstandard
from mcap.opcode import Opcode
from mcap.records import (
    Attachment,
    AttachmentIndex,
    Channel,
    Chunk,
    DataEnd,
    Header,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)

from bagfault.io import mcap_layout
from bagfault.io.file_copy import IN_KERNEL, copy_range
from bagfault.io.marks import MCAP_RECORD, mcap_mark
from bagfault.io.mcap_layout import (
    INDEX_ENTRY,
    INDEX_HEAD,
    MAGIC,
    MESSAGE_HEAD,
    padding_length,
    padding_record,
    record_bytes,
)

if TYPE_CHECKING:
    from bagfault.io.leading_copy import LeadingCopy

_MESSAGE_HEAD = struct.Struct('<BQHIQQ')
_CHUNK_INDEX_HEAD = struct.Struct('<BQQQQQI')
_CHUNK_INDEX_MID = struct.Struct('<QI')
_CHUNK_INDEX_TAIL = struct.Struct('<QQ')
PENDING_CHUNKS = 16
SPAN_LIMIT = 64 << 20  # copied bytes handed to the copy thread at least this often
COPIES_AHEAD = 2  # spans handed over and not yet copied: the writer reads the input at most ~128 MB ahead of the
# copy, so what it (and the provenance hash that follows it) brought into the page cache is still there
def chunk_index_record(start: int, end: int, offset: int, length: int, index_offsets: dict[int, int],
                       index_length: int, compression: str, compressed_size: int, uncompressed_size: int) -> bytes:
    """A chunk index record, packed as the `mcap` library's ChunkIndex.write packs it (ten times faster: the
    summary of a 3000-chunk bag is mostly these)."""
    entries = b''.join([INDEX_ENTRY.pack(cid, position) for cid, position in index_offsets.items()])
    name = compression.encode()
    length_of_body = 8 * 4 + 4 + len(entries) + 8 + 4 + len(name) + 8 * 2
    return b''.join((_CHUNK_INDEX_HEAD.pack(Opcode.CHUNK_INDEX, length_of_body, start, end, offset, length,
                                            len(entries)),
                     entries, _CHUNK_INDEX_MID.pack(index_length, len(name)), name,
                     _CHUNK_INDEX_TAIL.pack(compressed_size, uncompressed_size)))


DEFAULT_LEVELS = {'zstd': 1, 'lz4': 0}  # the MCAP C++ writer's default (rosbag2's mcap plugin); zstd 1 against 3:
# half the CPU for 10 % more bytes (docs/notes/performance.md, Compression)
LEVELS = {'zstd': (-7, 22), 'lz4': (0, 16)}  # the range each accepts here


def _compress(compression: str, level: int, data: bytes) -> tuple[bytes, int]:
    crc = zlib.crc32(data)
    if compression == 'zstd':
        return zstandard.ZstdCompressor(level=level).compress(data), crc
    if compression == 'lz4':
        return lz4.frame.compress(data, compression_level=level), crc
    return data, crc


class _OpenChunk:
    """Records of the chunk being filled, and its per-channel message index."""

    __slots__ = ('count', 'end', 'indexes', 'parts', 'size', 'start')

    def __init__(self) -> None:
        self.parts: list[bytes | memoryview] = []
        self.size = 0
        self.count = 0
        self.start = 0
        self.end = 0
        self.indexes: dict[int, list[tuple[int, int]]] = {}


class _Span:
    """Copied bytes not yet handed to the copy thread: input [begin, end) of `fd`, placed at output offset `at`
    (before any padding), and the chunk index fields of its chunks, packed once its place is final."""

    __slots__ = ('at', 'begin', 'end', 'fd', 'indexes')

    def __init__(self, fd: int, begin: int, at: int) -> None:
        self.fd, self.begin, self.end, self.at = fd, begin, begin, at
        self.indexes: list[tuple[CopiedChunk, int]] = []  # each chunk, and its offset from `at`


@dataclass(frozen=True)
class CopiedChunk:
    """An input chunk to write as it is, with the message index records that follow it in the input: where
    they are, and what the input's indexes (checked when it was opened) say of them."""

    fd: int  # the input file, read with explicit offsets (copy_file_range where the kernel has it)
    offset: int
    length: int  # the whole chunk record, opcode and length included
    index_length: int  # its message index records, right after it
    index_offsets: dict[int, int]  # channel id -> offset of its message index record from the first one
    counts: dict[int, int]  # channel id -> messages
    start: int
    end: int
    compression: str
    compressed_size: int
    uncompressed_size: int


class McapWriter:
    """Writes an MCAP stream; `finish` writes the summary and footer."""

    def __init__(self, stream: IO[bytes], *, compression: str = 'zstd', chunk_size: int = 1 << 20,
                 profile: str = 'ros2', library: str = 'bagfault', level: int | None = None,
                 lead: LeadingCopy | None = None) -> None:
        self._stream = stream
        self._lead = lead  # copies an input's leading chunks into this file ahead of the run (until stopped)
        self._lead_taken = 0  # output offset up to which copied spans were taken from it
        self._lead_extent = 0  # how far it wrote, once stopped (the file is cut back to its own end)
        self._deferred: list[Schema | Channel] = []  # numbered schemas and channels not written yet
        self._compression = '' if compression == 'none' else compression
        self._level = DEFAULT_LEVELS.get(compression, 0) if level is None else level
        self._chunk_size = chunk_size
        self._schemas: list[Schema] = []
        self._channels: list[Channel] = []
        self._chunk_indexes: list[bytes] = []  # packed chunk index records
        self._metadata_indexes: list[MetadataIndex] = []
        self._attachment_indexes: list[AttachmentIndex] = []
        self._counts: dict[int, int] = {}
        self._message_count = 0
        self._start = 0
        self._end = 0
        self._metadata_count = 0
        self._attachment_count = 0
        self._chunk = _OpenChunk()
        self._summary_crc: int | None = None  # running CRC of the summary section, once it starts
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix='mcap-compress')
        self._pending: deque[tuple[_OpenChunk | CopiedChunk, Future[tuple[bytes, int]] | None, int, bytes]] = deque()
        self._next_schema = 1
        self._next_channel = 1
        self._in_kernel = IN_KERNEL
        self._span: _Span | None = None
        self._copier = ThreadPoolExecutor(max_workers=1, thread_name_prefix='mcap-copy')
        self._copies: deque[Future[None]] = deque()
        self._stream.write(MAGIC)
        self._offset = len(MAGIC)
        self._record(Header(profile=profile, library=library))

    # -- plain records -------------------------------------------------------
    def _record(self, record: object) -> int:
        self._settle()
        data = record_bytes(record)
        start = self._offset
        self._write(data)
        if self._summary_crc is not None:
            self._summary_crc = zlib.crc32(data, self._summary_crc)
        return start

    def _write(self, data: bytes) -> None:
        """Bytes of the writer's own at the current offset; a leading copy whose range they fall in is stopped
        first (once it has copied what was taken from it), so it never writes over them."""
        lead = self._lead
        if lead is not None and lead.writes(self._offset, len(data)):
            self._end_lead()
        self._stream.write(data)
        self._offset += len(data)

    def _end_lead(self) -> None:
        """The leading copy has copied every span taken from it, and copies nothing more (its failure raised)."""
        lead, self._lead = self._lead, None
        if lead is not None:
            lead.stop(self._lead_taken)
            self._lead_extent = lead.extent

    def _write_deferred(self) -> None:
        """Numbered schemas and channels, before the record that follows them: after the chunks copied before
        it, so an input's leading chunks come right after its own channels, where a leading copy put them."""
        records, self._deferred = self._deferred, []
        for record in records:
            self._record(record)

    def reserve(self, schema_ids: int, channel_ids: int) -> None:
        """Ids up to these are given explicitly (an input's, kept for copied chunks); new ones start above."""
        self._next_schema = max(self._next_schema, schema_ids + 1)
        self._next_channel = max(self._next_channel, channel_ids + 1)

    def register_schema(self, name: str, encoding: str, data: bytes, schema_id: int | None = None) -> int:
        """Add a schema (outside chunks); return its id. A given id (an input's) is written at once, a numbered
        one (the next free id) before the next chunk, metadata or attachment this writer writes itself."""
        given = schema_id is not None
        if schema_id is None:
            schema_id = self._next_schema
            self._next_schema += 1
        schema = Schema(id=schema_id, name=name, encoding=encoding, data=data)
        self._schemas.append(schema)
        if given:
            self._record(schema)
        else:
            self._deferred.append(schema)
        return schema.id

    def register_channel(self, topic: str, message_encoding: str, schema_id: int, metadata: dict[str, str],
                         channel_id: int | None = None) -> int:
        """Add a channel (before any chunk that uses it); return its id. As with schemas, a given id is written at
        once, a numbered one (the next free id) later."""
        given = channel_id is not None
        if channel_id is None:
            channel_id = self._next_channel
            self._next_channel += 1
        channel = Channel(id=channel_id, topic=topic, message_encoding=message_encoding,
                          schema_id=schema_id, metadata=dict(metadata))
        self._channels.append(channel)
        if given:
            self._record(channel)
        else:
            self._deferred.append(channel)
        return channel.id

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        """A metadata record in the data section."""
        self._flush_chunk()
        self._drain(wait=True)
        self._write_deferred()
        start = self._record(Metadata(name=name, metadata=data))
        self._metadata_indexes.append(MetadataIndex(offset=start, length=self._offset - start, name=name))
        self._metadata_count += 1

    def add_mark(self) -> None:
        """The `bagfault.mark` metadata record (see io/marks.py), the last of the data section: over its own
        offset and every chunk index record the summary will hold. Only `finish` may follow."""
        self.flush()
        start = self._offset
        self.add_metadata(MCAP_RECORD, {'mark': mcap_mark(start, self._chunk_indexes)})
        if self._metadata_indexes[-1].offset != start:  # flush wrote everything pending: nothing may move it
            raise AssertionError(f'the mark record moved from {start} to {self._metadata_indexes[-1].offset}')

    def add_attachment(self, create_time: int, log_time: int, name: str, media_type: str, data: bytes) -> None:
        """An attachment record in the data section."""
        self._flush_chunk()
        self._drain(wait=True)
        self._write_deferred()
        start = self._record(Attachment(create_time=create_time, log_time=log_time, name=name,
                                        media_type=media_type, data=data))
        self._attachment_indexes.append(AttachmentIndex(
            offset=start, length=self._offset - start, create_time=create_time, log_time=log_time,
            data_size=len(data), name=name, media_type=media_type))
        self._attachment_count += 1

    # -- messages --------------------------------------------------------------
    def add_message(self, channel_id: int, log_time: int, data: bytes | memoryview, publish_time: int,
                    sequence: int = 0) -> None:
        """Append one message to the open chunk."""
        chunk = self._chunk
        size = len(data)
        index = chunk.indexes.get(channel_id)
        if index is None:
            index = chunk.indexes[channel_id] = []
        index.append((log_time, chunk.size))
        chunk.parts.append(_MESSAGE_HEAD.pack(Opcode.MESSAGE, MESSAGE_HEAD + size, channel_id, sequence,
                                              log_time, publish_time))
        chunk.parts.append(data)
        if chunk.count == 0:
            chunk.start = chunk.end = log_time
        elif log_time < chunk.start:
            chunk.start = log_time
        elif log_time > chunk.end:
            chunk.end = log_time
        chunk.count += 1
        chunk.size += 9 + MESSAGE_HEAD + size
        if chunk.size >= self._chunk_size:
            self._flush_chunk()

    # -- chunks -------------------------------------------------------------------
    def _flush_chunk(self) -> None:
        chunk = self._chunk
        if chunk.count == 0:
            return
        self._chunk = _OpenChunk()
        data = b''.join(chunk.parts)
        chunk.parts = []
        future = self._pool.submit(_compress, self._compression, self._level, data)
        self._pending.append((chunk, future, len(data), data))
        self._drain(wait=False)

    def copy_chunk(self, chunk: CopiedChunk) -> None:
        """Write an input's chunk as it is (after the chunks pending before it); the open chunk stays open."""
        self._pending.append((chunk, None, 0, b''))
        self._drain(wait=False)

    def _drain(self, *, wait: bool) -> None:
        """Write completed chunks in order; with wait, every pending chunk."""
        while self._pending and (wait or self._pending[0][1] is None or self._pending[0][1].done()
                                 or len(self._pending) > PENDING_CHUNKS):
            head = self._pending[0][1]
            while head is not None and not head.done() and self._help():
                pass
            chunk, future, size, _ = self._pending.popleft()
            if future is None:
                assert isinstance(chunk, CopiedChunk)
                self._write_copied(chunk)
                continue
            assert isinstance(chunk, _OpenChunk)
            compressed, crc = future.result()
            self._write_chunk(chunk, compressed, crc, size)

    def _help(self) -> bool:
        """Instead of waiting for the compressor, compress here a queued chunk it has not started (zstd
        releases the GIL, so both cores compress); False when there is none."""
        for position in range(1, len(self._pending)):
            chunk, future, size, data = self._pending[position]
            if future is not None and future.cancel():
                done: Future[tuple[bytes, int]] = Future()
                done.set_result(_compress(self._compression, self._level, data))
                self._pending[position] = (chunk, done, size, b'')
                return True
        return False

    def _write_copied(self, chunk: CopiedChunk) -> None:
        """The chunk record and its message indexes byte for byte; the chunk index pointing at them. The bytes
        of consecutive copied chunks are copied in one call when something else is written next."""
        span = self._span
        if span is None or span.fd != chunk.fd or span.end != chunk.offset:
            self._settle()
            span = self._span = _Span(chunk.fd, chunk.offset, self._offset)
        span.indexes.append((chunk, span.end - span.begin))
        span.end += chunk.length + chunk.index_length
        self._offset += chunk.length + chunk.index_length
        for channel_id, count in chunk.counts.items():
            self._counts[channel_id] = self._counts.get(channel_id, 0) + count
        count = sum(chunk.counts.values())
        if count:
            if self._message_count == 0:
                self._start, self._end = chunk.start, chunk.end
            else:
                self._start, self._end = min(self._start, chunk.start), max(self._end, chunk.end)
        self._message_count += count
        if span.end - span.begin >= max(SPAN_LIMIT, mcap_layout.ALIGN_FROM):  # the padding sees ALIGN_FROM whole
            self._settle()

    def _settle(self) -> None:
        """Hand the input bytes owed by copied chunks to the copy thread, which writes them at their place
        in the file (os.copy_file_range with explicit offsets) while this thread writes on after them. A long
        span is placed a multiple of mcap_layout.ALIGN from where it is in the input, after a padding record."""
        span, self._span = self._span, None
        if span is None:
            return
        fd, begin, end = span.fd, span.begin, span.end
        pad = padding_length(span.at, begin, end - begin)
        at = span.at + pad
        self._offset += pad
        for chunk, relative in span.indexes:
            start = at + relative
            index_start = start + chunk.length
            offsets = {cid: index_start + offset for cid, offset in sorted(chunk.index_offsets.items())}
            self._chunk_indexes.append(chunk_index_record(
                chunk.start, chunk.end, start, chunk.length, offsets, chunk.index_length, chunk.compression,
                chunk.compressed_size, chunk.uncompressed_size))
        lead = self._lead
        if pad:  # the stream stands at the span's first offset: nothing was written since
            if lead is not None and lead.writes(span.at, pad):
                self._end_lead()
            self._stream.write(padding_record(pad))
        self._stream.flush()
        self._stream.seek(at + end - begin)
        lead = self._lead
        if lead is not None:
            taken = lead.covers(fd, begin, end - begin, at)
            if taken:
                self._lead_taken = at + taken
                begin, at = begin + taken, at + taken
            if begin < end and lead.writes(at, end - begin):
                self._end_lead()
        if begin == end:
            return
        if self._in_kernel and hasattr(os, 'posix_fadvise'):  # the disk reads the span while earlier ones copy
            with contextlib.suppress(OSError):
                os.posix_fadvise(fd, begin, end - begin, os.POSIX_FADV_WILLNEED)
        self._copies.append(self._copier.submit(self._copy_range, fd, begin, end - begin, at))
        while self._copies and (self._copies[0].done() or len(self._copies) > COPIES_AHEAD):
            self._copies.popleft().result()  # a failed copy (a full disk) raises here, not at the end

    def _wait_copies(self) -> None:
        """Every handed-over copy is in the file (or its error raised)."""
        while self._copies:
            self._copies.popleft().result()

    def _copy_range(self, fd: int, offset: int, length: int, at: int) -> None:
        """Bytes of another file into this one at `at` (copy thread)."""
        self._in_kernel = copy_range(fd, self._stream.fileno(), offset, length, at, in_kernel=self._in_kernel)

    def _write_chunk(self, chunk: _OpenChunk, compressed: bytes, crc: int, size: int) -> None:
        self._write_deferred()
        start = self._record(Chunk(message_start_time=chunk.start, message_end_time=chunk.end,
                                   uncompressed_size=size, uncompressed_crc=crc, compression=self._compression,
                                   data=compressed))
        chunk_length = self._offset - start
        index_start = self._offset
        offsets = {}
        for channel_id in sorted(chunk.indexes):
            offsets[channel_id] = self._offset
            entries = chunk.indexes[channel_id]
            body = struct.pack(f'<{2 * len(entries)}Q', *chain.from_iterable(entries))
            self._write(INDEX_HEAD.pack(Opcode.MESSAGE_INDEX, 2 + 4 + len(body), channel_id, len(body)) + body)
            self._counts[channel_id] = self._counts.get(channel_id, 0) + len(entries)
        if self._message_count == 0:
            self._start, self._end = chunk.start, chunk.end
        else:
            self._start, self._end = min(self._start, chunk.start), max(self._end, chunk.end)
        self._message_count += chunk.count
        self._chunk_indexes.append(chunk_index_record(
            chunk.start, chunk.end, start, chunk_length, offsets, self._offset - index_start, self._compression,
            len(compressed), size))

    def flush(self) -> None:
        """Write the open chunk and every pending one (counts and times are then complete)."""
        self._flush_chunk()
        self._drain(wait=True)
        self._write_deferred()
        self._settle()
        self._wait_copies()
        self._end_lead()

    @property
    def counts(self) -> dict[int, int]:
        """Messages written per channel id so far (chunks completed)."""
        return dict(self._counts)

    @property
    def time_range(self) -> tuple[int, int]:
        """First and last log time written so far (chunks completed)."""
        return self._start, self._end

    # -- end ------------------------------------------------------------------------
    def finish(self) -> None:
        """Last chunk, data end, summary, summary offsets, footer."""
        try:
            self._flush_chunk()
            self._drain(wait=True)
        finally:
            self._pool.shutdown(wait=True)
        self._write_deferred()
        self._settle()
        self._end_lead()
        self._record(DataEnd(data_section_crc=0))
        summary_start = self._offset
        self._summary_crc = 0
        groups = []
        for opcode, records in (
            (Opcode.SCHEMA, self._schemas),
            (Opcode.CHANNEL, self._channels),
            (Opcode.STATISTICS, [Statistics(
                message_count=self._message_count, schema_count=len(self._schemas),
                channel_count=len(self._channels), attachment_count=self._attachment_count,
                metadata_count=self._metadata_count, chunk_count=len(self._chunk_indexes),
                message_start_time=self._start, message_end_time=self._end,
                channel_message_counts=dict(sorted(self._counts.items())))]),
            (Opcode.CHUNK_INDEX, self._chunk_indexes),
            (Opcode.ATTACHMENT_INDEX, self._attachment_indexes),
            (Opcode.METADATA_INDEX, self._metadata_indexes),
        ):
            if not records:
                continue
            group_start = self._offset
            for record in records:
                if isinstance(record, bytes):
                    self._write_summary_bytes(record)
                else:
                    self._record(record)
            groups.append(SummaryOffset(group_opcode=opcode, group_start=group_start,
                                        group_length=self._offset - group_start))
        summary_offset_start = self._offset
        for group in groups:
            self._record(group)
        # The footer's CRC covers the summary and the footer itself up to the CRC field.
        head = struct.pack('<BQQQ', Opcode.FOOTER, 8 + 8 + 4, summary_start, summary_offset_start)
        crc = zlib.crc32(head, self._summary_crc or 0)
        self._summary_crc = None
        self._write(head + struct.pack('<I', crc))
        self._write(MAGIC)
        try:
            self._wait_copies()
        finally:
            self._copier.shutdown(wait=True)
        if self._lead_extent > self._offset:  # a leading copy that went further than the run's copy
            self._stream.flush()
            os.ftruncate(self._stream.fileno(), self._offset)

    def _write_summary_bytes(self, data: bytes) -> None:
        """A packed summary record (chunk indexes), under the summary CRC."""
        self._write(data)
        self._summary_crc = zlib.crc32(data, self._summary_crc or 0)

    def abandon(self) -> None:
        """Stop the worker without writing more (failed run)."""
        self._span = None
        self._pool.shutdown(wait=True, cancel_futures=True)
        self._copier.shutdown(wait=True, cancel_futures=True)
        lead, self._lead = self._lead, None
        if lead is not None:  # before the sink closes the file it writes into
            with contextlib.suppress(OSError):
                lead.stop(0)
