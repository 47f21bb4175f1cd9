"""A lean MCAP writer: message records packed by hand, chunks compressed on a second thread.

Everything but the hot path uses the record classes of the `mcap` library
(schemas, channels, chunk and summary records). Message records are packed
with one struct call each into the open chunk; full chunks are handed to a
worker thread that computes the CRC and compresses (zstd and lz4 release
the GIL), and are written in order as they complete, so compression runs
on the second core while the main thread reads and injects. The file has
the layout of the `mcap` library's writer (chunks with message indexes,
repeated schemas and channels, statistics, chunk/metadata/attachment
indexes, summary offsets) and is byte-identical from run to run.
"""

from __future__ import annotations

import struct
import zlib
from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor
from typing import IO

import lz4.frame
import numpy as np
import zstandard
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (
    Attachment,
    AttachmentIndex,
    Channel,
    Chunk,
    ChunkIndex,
    DataEnd,
    Header,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)

MAGIC = b'\x89MCAP0\r\n'
_MESSAGE_HEAD = struct.Struct('<BQHIQQ')
_MESSAGE_HEAD_SIZE = 2 + 4 + 8 + 8
_INDEX_HEAD = struct.Struct('<BQHI')
PENDING_CHUNKS = 16


def _compress(compression: str, data: bytes) -> tuple[bytes, int]:
    crc = zlib.crc32(data)
    if compression == 'zstd':
        return zstandard.ZstdCompressor(level=3).compress(data), crc
    if compression == 'lz4':
        return lz4.frame.compress(data), crc
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


class McapWriter:
    """Writes an MCAP stream; `finish` writes the summary and footer."""

    def __init__(self, stream: IO[bytes], *, compression: str = 'zstd', chunk_size: int = 1 << 20,
                 profile: str = 'ros2', library: str = 'bagfault') -> None:
        self._stream = stream
        self._compression = '' if compression == 'none' else compression
        self._chunk_size = chunk_size
        self._schemas: list[Schema] = []
        self._channels: list[Channel] = []
        self._chunk_indexes: list[ChunkIndex] = []
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
        self._pending: deque[tuple[_OpenChunk, Future[tuple[bytes, int]], int]] = deque()
        self._stream.write(MAGIC)
        self._offset = len(MAGIC)
        self._record(Header(profile=profile, library=library))

    # -- plain records -------------------------------------------------------
    def _record(self, record: object) -> int:
        builder = RecordBuilder()
        record.write(builder)  # type: ignore[attr-defined]
        data: bytes = builder.end()  # type: ignore[no-untyped-call]
        start = self._offset
        self._stream.write(data)
        self._offset += len(data)
        if self._summary_crc is not None:
            self._summary_crc = zlib.crc32(data, self._summary_crc)
        return start

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        """Add a schema (written at once, outside chunks); return its id (1-based)."""
        schema = Schema(id=len(self._schemas) + 1, name=name, encoding=encoding, data=data)
        self._schemas.append(schema)
        self._record(schema)
        return schema.id

    def register_channel(self, topic: str, message_encoding: str, schema_id: int, metadata: dict[str, str]) -> int:
        """Add a channel (written at once, before any chunk that uses it); return its id (1-based)."""
        channel = Channel(id=len(self._channels) + 1, topic=topic, message_encoding=message_encoding,
                          schema_id=schema_id, metadata=dict(metadata))
        self._channels.append(channel)
        self._record(channel)
        return channel.id

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        """A metadata record in the data section."""
        self._flush_chunk()
        self._drain(wait=True)
        start = self._record(Metadata(name=name, metadata=data))
        self._metadata_indexes.append(MetadataIndex(offset=start, length=self._offset - start, name=name))
        self._metadata_count += 1

    def add_attachment(self, create_time: int, log_time: int, name: str, media_type: str, data: bytes) -> None:
        """An attachment record in the data section."""
        self._flush_chunk()
        self._drain(wait=True)
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
        chunk.parts.append(_MESSAGE_HEAD.pack(Opcode.MESSAGE, _MESSAGE_HEAD_SIZE + size, channel_id, sequence,
                                              log_time, publish_time))
        chunk.parts.append(data)
        if chunk.count == 0:
            chunk.start = chunk.end = log_time
        elif log_time < chunk.start:
            chunk.start = log_time
        elif log_time > chunk.end:
            chunk.end = log_time
        chunk.count += 1
        chunk.size += 9 + _MESSAGE_HEAD_SIZE + size
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
        future = self._pool.submit(_compress, self._compression, data)
        self._pending.append((chunk, future, len(data)))
        self._drain(wait=False)

    def _drain(self, *, wait: bool) -> None:
        """Write completed chunks in order; with wait, every pending chunk."""
        while self._pending and (wait or self._pending[0][1].done() or len(self._pending) > PENDING_CHUNKS):
            chunk, future, size = self._pending.popleft()
            compressed, crc = future.result()
            self._write_chunk(chunk, compressed, crc, size)

    def _write_chunk(self, chunk: _OpenChunk, compressed: bytes, crc: int, size: int) -> None:
        start = self._offset
        self._record(Chunk(message_start_time=chunk.start, message_end_time=chunk.end, uncompressed_size=size,
                           uncompressed_crc=crc, compression=self._compression, data=compressed))
        chunk_length = self._offset - start
        index_start = self._offset
        offsets = {}
        for channel_id in sorted(chunk.indexes):
            offsets[channel_id] = self._offset
            entries = chunk.indexes[channel_id]
            body = np.array(entries, dtype='<u8').tobytes()
            record = _INDEX_HEAD.pack(Opcode.MESSAGE_INDEX, 2 + 4 + len(body), channel_id, len(body)) + body
            self._stream.write(record)
            self._offset += len(record)
            self._counts[channel_id] = self._counts.get(channel_id, 0) + len(entries)
        if self._message_count == 0:
            self._start, self._end = chunk.start, chunk.end
        else:
            self._start, self._end = min(self._start, chunk.start), max(self._end, chunk.end)
        self._message_count += chunk.count
        self._chunk_indexes.append(ChunkIndex(
            message_start_time=chunk.start, message_end_time=chunk.end, chunk_start_offset=start,
            chunk_length=chunk_length, message_index_offsets=offsets, message_index_length=self._offset - index_start,
            compression=self._compression, compressed_size=len(compressed), uncompressed_size=size))

    def flush(self) -> None:
        """Write the open chunk and every pending one (counts and times are then complete)."""
        self._flush_chunk()
        self._drain(wait=True)

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
        self._stream.write(head + struct.pack('<I', crc))
        self._offset += len(head) + 4
        self._stream.write(MAGIC)

    def abandon(self) -> None:
        """Stop the worker without writing more (failed run)."""
        self._pool.shutdown(wait=True, cancel_futures=True)
