"""MCAP input, read chunk by chunk in log-time order, with every record checked.

The summary is parsed by `mcap_summary` (into the `mcap` library's
records) and the data section checked against it by `mcap_index_check`;
chunks are read here and split by `mcap_chunks`, so that messages come out
as zero-copy slices of one decompressed buffer, channels found only inside
chunks are still known, and overlapping chunks are merged by log time.
Files without chunk index, or cut short, are read record by record
(`mcap_salvage`).

What the format lets a reader detect is checked: chunk CRCs and sizes,
record lengths, records that refer to channels nobody defined, chunk
indexes that point outside the file. Such corruption is an `InputError`
naming the file and the offset; with `salvage` the readable messages are
kept and every skipped part is listed in `losses`.
"""

from __future__ import annotations

import heapq
import io
import itertools
import os
import struct
import zlib
from pathlib import Path
from typing import IO, TYPE_CHECKING

import zstandard
from mcap.reader import SeekingReader
from mcap.records import Channel as McapChannel
from mcap.records import Metadata, Schema

from bagfault.errors import InputError, one_line
from bagfault.io.channel import Channel, normalize_msgtype
from bagfault.io.mcap_chunks import (
    READ_ERRORS,
    ChunkRef,
    Corrupt,
    Definitions,
    IndexedChunk,
    Split,
    check_counts,
    chunk_records,
    split_chunk,
    verify_records,
)
from bagfault.io.mcap_index_check import DataSection, check_statistics
from bagfault.io.mcap_layout import (
    FOOTER_LENGTH,
    MAGIC,
    MAX_RECORD,
    OP_CHANNEL,
    OP_CHUNK,
    OP_DATA_END,
    OP_SCHEMA,
    RECORD_HEAD,
)
from bagfault.io.mcap_salvage import walk_records
from bagfault.io.mcap_summary import SummaryError, read_metadata, read_summary
from bagfault.io.rosbag2_record import distro_of

if TYPE_CHECKING:
    from collections.abc import Iterator

    from mcap.summary import Summary

RawItem = tuple[int, int, int, memoryview]  # channel index, log_time, publish_time, data


class McapSource:
    """Messages of one MCAP file in log-time order."""

    def __init__(self, path: Path, *, salvage: bool = False) -> None:
        self.path = path
        self.salvage = salvage
        self.channels: list[Channel] = []
        self.ros_distro: str | None = None
        self.message_count: int | None = None
        self.start_time: int | None = None
        self.end_time: int | None = None
        self.losses: list[str] = []
        self.warnings: list[str] = []
        self.recorded_origin: int | None = None  # bag time zero of a bagfault live recording
        self._ids: dict[int, int] = {}
        self._definitions = Definitions()
        self._chunks: list[IndexedChunk] = []
        self._by_offset: dict[int, IndexedChunk] = {}
        self._memory: list[Split] = []
        self._loose: list[Split] = []  # message records outside any chunk of an indexed file (the spec allows them)
        self._indexed = False
        self._data_end = 0  # where the data section ends (the summary's start, else the footer's)
        self.schema_records: dict[int, Schema] = {}  # as the summary holds them (indexed files)
        self.channel_records: dict[int, McapChannel] = {}
        try:
            self._file = path.open('rb')
        except OSError as exc:
            raise InputError(f'{path}: cannot open: {exc.strerror}') from None
        self._size = path.stat().st_size
        try:
            self._open()
        except InputError:
            self._file.close()
            raise
        except Corrupt as exc:
            self._file.close()
            raise InputError(f'{path}: corrupt MCAP file: {one_line(exc)}') from None
        except READ_ERRORS as exc:
            self._file.close()
            raise InputError(f'{path}: corrupt or truncated MCAP file ({one_line(exc)})') from None

    # -- corruption -------------------------------------------------------------------------
    def _lost(self, where: str, reason: str) -> None:
        """A part that cannot be read: an error, or (salvage) a listed loss."""
        if not self.salvage:
            raise InputError(f'{self.path}: corrupt MCAP file: {where}: {reason} (--salvage copies what can be read)')
        self.losses.append(f'{self.path}: {where}: {reason}')

    # -- opening ------------------------------------------------------------------------------
    def _open(self) -> None:
        head = self._file.read(8)
        if head != MAGIC:
            raise InputError(f'{self.path}: not an MCAP file (bad magic bytes)')
        if self._size < 8 + 9 + 20 + 8:
            raise InputError(f'{self.path}: truncated MCAP file')
        self._file.seek(-8, io.SEEK_END)
        if self._file.read(8) != MAGIC:
            if not self.salvage:
                raise InputError(f'{self.path}: truncated MCAP file (no closing magic; was the recording stopped '
                                 'cleanly?) (--salvage reads what it holds; `bagfault recover` completes it)')
            self.losses.append(f'{self.path}: no closing magic: the file was cut short; read record by record')
            self._data_end = self._size
            self._scan_unindexed(None)
            return
        summary, metadata = self._read_summary()
        for record in metadata:
            if record.name == 'rosbag2':
                self._read_rosbag2_metadata(record.metadata)
            elif record.name == 'bagfault.origin' and record.metadata.get('origin_ns', '').isdigit():
                self.recorded_origin = int(record.metadata['origin_ns'])
        if summary is None or not summary.chunk_indexes:
            self._scan_unindexed(summary)
            return
        self._indexed = True
        self._open_indexed(summary)

    def _open_indexed(self, summary: Summary) -> None:
        """An indexed file: its definitions and chunk indexes from the summary, checked against the data section
        (`mcap_index_check`) and the Statistics record."""
        definitions = self._definitions
        for schema in summary.schemas.values():
            definitions.schemas[schema.id] = (schema.name, schema.encoding, schema.data.decode(errors='replace'))
        for channel in summary.channels.values():
            definitions.channels[channel.id] = (channel.schema_id, channel.topic, channel.message_encoding,
                                                dict(channel.metadata))
        for index in summary.chunk_indexes:
            if index.chunk_start_offset + index.chunk_length > self._size or index.chunk_start_offset < 8:
                raise Corrupt(f'a chunk index points outside the file (offset {index.chunk_start_offset})')
        unique: dict[int, IndexedChunk] = {}
        for c in summary.chunk_indexes:
            if c.chunk_start_offset in unique:
                self._lost(f'chunk at offset {c.chunk_start_offset}', 'indexed twice in the summary (its messages '
                           'would be read twice); read once')
                continue
            unique[c.chunk_start_offset] = IndexedChunk(
                c.message_start_time, c.message_end_time, c.chunk_start_offset, c.chunk_length,
                dict(c.message_index_offsets), c.message_index_length, c.compression, c.compressed_size,
                c.uncompressed_size)
        section = DataSection(self._file.fileno(), self._data_end, self._lost)
        self._chunks = section.check(sorted(unique.values(), key=lambda c: (c.start, c.offset)))
        self._loose = section.loose
        self.warnings += [f'{self.path}: {warning}' for warning in section.warnings]
        self._by_offset = {c.offset: c for c in self._chunks}
        self.schema_records = dict(summary.schemas)
        self.channel_records = dict(summary.channels)
        referenced = {cid for c in summary.chunk_indexes for cid in c.message_index_offsets}
        missing_schemas = {s for s, _, _, _ in definitions.channels.values() if s and s not in definitions.schemas}
        if not definitions.channels or referenced - set(definitions.channels) or missing_schemas:
            self._scan_definitions()  # a valid layout may keep schemas (or channels) in the data section only
        if summary.statistics is not None:
            self.message_count = summary.statistics.message_count
            check_statistics(self._chunks, self._loose, summary.statistics.message_count,
                             dict(summary.statistics.channel_message_counts), self._lost)
            if summary.statistics.message_count:
                self.start_time = summary.statistics.message_start_time
                self.end_time = summary.statistics.message_end_time
        else:
            self.start_time = self._chunks[0].start
            self.end_time = max(c.end for c in self._chunks)
        for channel_id in sorted(definitions.channels):
            self._register(channel_id)

    def _read_summary(self) -> tuple[Summary | None, list[Metadata]]:
        """The summary section (its CRC checked) and the metadata records its index points at; without a
        summary, the metadata records found by reading the file through."""
        try:
            summary_start, summary = read_summary(self._file, self._size)
            self._data_end = summary_start or self._size - 8 - FOOTER_LENGTH
            if summary is None:
                self._file.seek(0)
                return None, list(SeekingReader(self._file).iter_metadata())
            return summary, [read_metadata(self._file, index) for index in summary.metadata_indexes]
        except SummaryError as exc:
            raise Corrupt(str(exc)) from None

    def _scan_definitions(self) -> None:
        """Schemas and channels from the data section: top-level records, and inside chunks."""
        position = 8
        while position + 9 <= self._size - 8:
            self._file.seek(position)
            opcode, length = RECORD_HEAD.unpack(self._file.read(9))
            if position + 9 + length > self._size:
                raise Corrupt(f'record at offset {position} claims {length} bytes, past the end of the file')
            if opcode == OP_DATA_END:  # the summary follows
                return
            if opcode == OP_CHUNK:
                data = self._chunk_at(position)
                if data is not None:
                    split_chunk(data, position, self._definitions, self._lost)
            elif opcode in (OP_SCHEMA, OP_CHANNEL) and length <= MAX_RECORD:
                body = memoryview(self._file.read(length))
                self._definitions.add(opcode, body, 0, len(body))
            position += 9 + length

    def _scan_unindexed(self, summary: Summary | None) -> None:
        """Files without chunk index: read record by record (`mcap_salvage`), messages kept in memory; the
        Statistics record of a summary without chunk index checked against them."""
        definitions = self._definitions
        if summary is not None:
            for schema in summary.schemas.values():
                definitions.schemas.setdefault(schema.id, (schema.name, schema.encoding,
                                                           schema.data.decode(errors='replace')))
            for channel in summary.channels.values():
                definitions.channels.setdefault(channel.id, (channel.schema_id, channel.topic,
                                                             channel.message_encoding, dict(channel.metadata)))
        walked = walk_records(self._file, self._data_end, definitions, self._lost)
        for metadata in walked.rosbag2:
            self._read_rosbag2_metadata(metadata)
        messages = walked.messages
        if summary is not None and summary.statistics is not None and \
                summary.statistics.message_count != len(messages):
            self._lost('the Statistics record', f'declares {summary.statistics.message_count} messages, the file '
                                                f'holds {len(messages)}')
        messages.sort(key=lambda m: (m[0], m[3]))
        for channel_id in sorted(definitions.channels):
            self._register(channel_id)
        self._memory = messages
        self.message_count = len(messages)
        if messages:
            self.start_time, self.end_time = messages[0][0], messages[-1][0]

    def _read_rosbag2_metadata(self, metadata: dict[str, str]) -> None:
        self.ros_distro = distro_of(metadata) or self.ros_distro

    def _register(self, channel_id: int) -> int:
        index = self._ids.get(channel_id)
        if index is not None:
            return index
        schema_id, topic, encoding, metadata = self._definitions.channels[channel_id]
        name, schema_encoding, text = self._definitions.schemas.get(schema_id, ('', '', ''))
        self.channels.append(
            Channel(
                topic=topic,
                msgtype=normalize_msgtype(name) if name else '',
                schema_encoding=schema_encoding,
                schema_text=text,
                message_encoding=encoding,
                metadata=tuple(sorted(metadata.items())),
            )
        )
        self._ids[channel_id] = len(self.channels) - 1
        return self._ids[channel_id]

    # -- chunks -------------------------------------------------------------------------------
    def _chunk_at(self, offset: int) -> memoryview | None:
        """The decompressed records of the chunk at `offset`, checked; None when salvage skips it."""
        try:
            return self._read_chunk(offset)
        except Corrupt as exc:
            self._lost(f'chunk at offset {offset}', str(exc))
        except (zstandard.ZstdError, RuntimeError, ValueError, zlib.error, struct.error, MemoryError) as exc:
            self._lost(f'chunk at offset {offset}', f'cannot decompress ({one_line(exc)})')
        return None

    def _read_chunk(self, offset: int) -> memoryview:
        self._file.seek(offset)
        opcode, length = RECORD_HEAD.unpack(self._file.read(9))
        if opcode != OP_CHUNK:
            raise Corrupt(f'the index points at a record of type {opcode:#x}, not a chunk')
        if offset + 9 + length > self._size:
            raise Corrupt(f'the chunk claims {length} bytes, past the end of the file')
        return chunk_records(memoryview(self._file.read(length)), offset)

    # -- messages -----------------------------------------------------------------------------
    def messages(self) -> Iterator[RawItem]:
        """(channel index, log_time, publish_time, data) in log-time order."""
        try:
            if self._indexed:
                yield from self._indexed_messages()
            else:
                yield from self._known(self._memory)
        except Corrupt as exc:
            raise InputError(f'{self.path}: corrupt MCAP file: {one_line(exc)}') from None
        except READ_ERRORS as exc:
            raise InputError(f'{self.path}: corrupt chunk data ({one_line(exc)})') from None

    def _known(self, items: list[Split]) -> Iterator[RawItem]:
        """Messages whose channel is defined; one that refers to no channel is corrupt."""
        ids, pending, register = self._ids, self._definitions.channels, self._register
        for log_time, publish_time, channel_id, _, data in items:
            index = ids.get(channel_id)
            if index is None:
                if channel_id not in pending:
                    self._lost(f'message at {log_time} ns', f'refers to channel {channel_id}, which no record '
                                                            'defines')
                    continue
                index = register(channel_id)
            yield index, log_time, publish_time, data

    def _indexed_messages(self) -> Iterator[RawItem]:
        pending = [(log_time, -1, pos, publish_time, channel_id, payload)
                   for log_time, publish_time, channel_id, pos, payload in self._loose]
        chunks = self._chunks
        for number, chunk in enumerate(chunks):
            data = self._chunk_at(chunk.offset)
            items = split_chunk(data, chunk.offset, self._definitions, self._lost) if data is not None else []
            if data is not None:
                check_counts(chunk, items, self._lost)
            horizon = chunks[number + 1].start if number + 1 < len(chunks) else None
            in_order = all(items[i][0] <= items[i + 1][0] for i in range(len(items) - 1))
            if not pending and in_order and (horizon is None or not items or items[-1][0] <= horizon):
                yield from self._known(items)
                continue
            for log_time, publish_time, channel_id, pos, payload in items:
                heapq.heappush(pending, (log_time, number, pos, publish_time, channel_id, payload))
            ready = []
            while pending and (horizon is None or pending[0][0] < horizon):
                log_time, _, pos, publish_time, channel_id, payload = heapq.heappop(pending)
                ready.append((log_time, publish_time, channel_id, pos, payload))
            yield from self._known(ready)

    # -- chunks as they are (chunk copy) -----------------------------------------------------------
    def chunk_refs(self) -> list[ChunkRef] | None:
        """The chunks in file order when they can be copied as they are: an indexed file whose chunks follow
        each other in time, each with its message indexes, and no message outside them; None otherwise."""
        if not self._indexed or self.salvage or not self._chunks or self._loose:
            return None
        chunks = sorted(self._chunks, key=lambda c: c.offset)
        if chunks != self._chunks or any(a.end > b.start for a, b in itertools.pairwise(chunks)):
            return None
        if any(c.index_offsets is None or (c.index_offsets and not c.index_length) for c in chunks):
            return None
        if any(cid not in self._ids for c in chunks for cid in c.index_offsets or {}):
            return None
        return [ChunkRef(c.offset, c.length, c.start, c.end, dict(c.index_offsets or {}), c.index_length,
                         c.compression, c.compressed_size, c.uncompressed_size) for c in chunks]

    def channel_number(self, channel_id: int) -> int:
        """The index in `channels` of an input channel id."""
        return self._ids[channel_id]

    def read_record(self, ref: ChunkRef, handle: IO[bytes] | None = None) -> bytes:
        """The chunk record as bytes (from `handle`, a reader thread's own, or this source's file)."""
        handle = handle or self._file
        handle.seek(ref.offset)
        record = handle.read(ref.length)
        if len(record) != ref.length:
            raise InputError(f'{self.path}: truncated chunk at offset {ref.offset}')
        return record

    def counts_of(self, ref: ChunkRef) -> dict[int, int]:
        """Messages per channel id of a chunk, as its message indexes say (read and checked at opening)."""
        counts = self._by_offset[ref.offset].counts
        if counts is None:
            raise InputError(f'{self.path}: the message indexes of the chunk at offset {ref.offset} were not read')
        return dict(counts)

    @property
    def handle(self) -> IO[bytes]:
        """The open input file (positioned anywhere; readers seek)."""
        return self._file

    def fileno(self) -> int:
        """The input file's descriptor (chunk copy copies from it with explicit offsets)."""
        return self._file.fileno()

    def records_of(self, ref: ChunkRef, record: bytes) -> memoryview:
        """The decompressed, checked records of a chunk read by `read_raw`."""
        try:
            return chunk_records(memoryview(record)[9:], ref.offset)
        except Corrupt as exc:
            raise InputError(f'{self.path}: corrupt MCAP file: chunk at offset {ref.offset}: {one_line(exc)}') from None
        except READ_ERRORS as exc:
            raise InputError(f'{self.path}: corrupt chunk data ({one_line(exc)})') from None

    def messages_of(self, ref: ChunkRef, records: memoryview) -> list[RawItem]:
        """The messages of a decompressed chunk, in its order (chunks of the copy path are in time order)."""
        items = split_chunk(records, ref.offset, self._definitions, self._lost)
        check_counts(self._by_offset[ref.offset], items, self._lost)
        if any(items[i][0] > items[i + 1][0] for i in range(len(items) - 1)):
            items.sort(key=lambda m: (m[0], m[3]))
        return list(self._known(items))

    def verify_chunk(self, ref: ChunkRef) -> None:
        """`--verify` of a copied chunk (from any thread; nothing of the source changes): read again,
        decompressed, CRC-checked, its records walked and counted against its message indexes."""
        record = os.pread(self._file.fileno(), ref.length, ref.offset)
        if len(record) != ref.length:
            raise InputError(f'{self.path}: truncated chunk at offset {ref.offset}')
        where = f'{self.path}: corrupt MCAP file: chunk at offset {ref.offset} (copied, then verified)'
        verify_records(self.records_of(ref, record), where, self._by_offset[ref.offset].counts)

    def close(self) -> None:
        """Release the file."""
        self._file.close()

