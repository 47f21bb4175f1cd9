"""MCAP input, read chunk by chunk in log-time order, with every record checked.

The summary is parsed by `mcap_summary` (into the `mcap` library's
records); chunks are read and split here so that messages come out as zero-copy slices of one
decompressed buffer, channels found only inside chunks are still known,
and overlapping chunks are merged by log time.

What the format lets a reader detect is checked: chunk CRCs and sizes,
record lengths, records that refer to channels nobody defined, chunk
indexes that point outside the file. Such corruption is an `InputError`
naming the file and the offset; with `salvage` the readable messages are
kept and every skipped part is listed in `losses`.
"""

from __future__ import annotations

import contextlib
import heapq
import io
import itertools
import mmap
import os
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import IO, TYPE_CHECKING

import lz4.frame
import numpy as np
import zstandard
from mcap.exceptions import McapError
from mcap.reader import SeekingReader
from mcap.records import Channel as McapChannel
from mcap.records import Metadata, Schema

from bagfault.errors import InputError, one_line
from bagfault.io.channel import Channel, normalize_msgtype
from bagfault.io.mcap_layout import MAGIC
from bagfault.io.mcap_summary import FOOTER_LENGTH, SummaryError, read_metadata, read_summary
from bagfault.io.rosbag2_record import distro_of

if TYPE_CHECKING:
    from collections.abc import Iterator

    from mcap.summary import Summary


OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK, OP_MESSAGE_INDEX, OP_DATA_END = 0x03, 0x04, 0x05, 0x06, 0x07, 0x0F
OP_FOOTER, OP_METADATA = 0x02, 0x0C
_INDEX_HEAD = struct.Struct('<BQHI')  # message index: opcode, length, channel id, entries length
_U16 = struct.Struct('<H')
_U32 = struct.Struct('<I')
_U64 = struct.Struct('<Q')
_REC = struct.Struct('<BQ')
_MSG = struct.Struct('<HIQQ')
_CHUNK_HEAD = struct.Struct('<QQQI')
MESSAGE_HEAD = 22  # channel id, sequence, log time, publish time
MAX_CHUNK = 1 << 32  # the mcap library's record size limit
READ_ERRORS = (McapError, struct.error, ValueError, KeyError, EOFError, zstandard.ZstdError, RuntimeError,
               UnicodeDecodeError, OSError, IndexError, MemoryError, zlib.error)

RawItem = tuple[int, int, int, memoryview]  # channel index, log_time, publish_time, data
Split = tuple[int, int, int, int, memoryview]  # log, publish, mcap channel id, position, data


class Corrupt(Exception):  # noqa: N818 - a signal inside this module, turned into InputError or a loss
    """A part of the file cannot be read."""


@dataclass
class _Chunk:
    start: int
    end: int
    offset: int
    length: int = 0  # the whole chunk record (opcode and length included)
    index_offsets: dict[int, int] | None = None  # channel id -> file offset of its message index record
    index_length: int = 0
    compression: str = ''
    compressed_size: int = 0
    uncompressed_size: int = 0
    counts: dict[int, int] | None = None  # channel id -> entries of its message index (None: not looked at)


@dataclass(frozen=True)
class ChunkRef:
    """A chunk as the summary describes it: where it is, its time range, the channels it holds messages of."""

    offset: int
    length: int
    start: int
    end: int
    index_offsets: dict[int, int]  # input channel id -> file offset of its message index record
    index_length: int
    compression: str
    compressed_size: int
    uncompressed_size: int

    @property
    def channel_ids(self) -> list[int]:
        """Input channel ids with messages in this chunk."""
        return list(self.index_offsets)


def _decompress(compression: str, data: bytes | memoryview, size: int) -> memoryview:
    if size > MAX_CHUNK:
        raise Corrupt(f'chunk claims {size} uncompressed bytes')
    if compression == '':
        return memoryview(data)
    if compression == 'zstd':
        return memoryview(zstandard.ZstdDecompressor().decompress(data, max_output_size=size))
    if compression == 'lz4':
        return memoryview(lz4.frame.decompress(bytes(data)))
    raise InputError(f'unsupported chunk compression {compression!r}')


def _string(buf: memoryview, pos: int, end: int) -> tuple[str, int]:
    (length,) = _U32.unpack_from(buf, pos)
    pos += 4
    if pos + length > end:
        raise Corrupt(f'a string of {length} bytes runs past its record')
    return bytes(buf[pos : pos + length]).decode(), pos + length


def _string_map(buf: memoryview, pos: int, end: int) -> dict[str, str]:
    (length,) = _U32.unpack_from(buf, pos)
    pos += 4
    stop, out = pos + length, {}
    if stop > end:
        raise Corrupt(f'a map of {length} bytes runs past its record')
    while pos < stop:
        key, pos = _string(buf, pos, stop)
        out[key], pos = _string(buf, pos, stop)
    return out


class _ScatteredReads:
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
        self._schemas: dict[int, tuple[str, str, str]] = {}
        self._pending_channels: dict[int, tuple[int, str, str, dict[str, str]]] = {}
        self._chunks: list[_Chunk] = []
        self._by_offset: dict[int, _Chunk] = {}
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
        for schema in summary.schemas.values():
            self._schemas[schema.id] = (schema.name, schema.encoding, schema.data.decode(errors='replace'))
        for channel in summary.channels.values():
            self._pending_channels[channel.id] = (channel.schema_id, channel.topic, channel.message_encoding,
                                                  dict(channel.metadata))
        for index in summary.chunk_indexes:
            if index.chunk_start_offset + index.chunk_length > self._size or index.chunk_start_offset < 8:
                raise Corrupt(f'a chunk index points outside the file (offset {index.chunk_start_offset})')
        unique: dict[int, _Chunk] = {}
        for c in summary.chunk_indexes:
            if c.chunk_start_offset in unique:
                self._lost(f'chunk at offset {c.chunk_start_offset}', 'indexed twice in the summary (its messages '
                           'would be read twice); read once')
                continue
            unique[c.chunk_start_offset] = _Chunk(
                c.message_start_time, c.message_end_time, c.chunk_start_offset, c.chunk_length,
                dict(c.message_index_offsets), c.message_index_length, c.compression, c.compressed_size,
                c.uncompressed_size)
        self._chunks = sorted(unique.values(), key=lambda c: (c.start, c.offset))
        self._check_layout()
        self.schema_records = dict(summary.schemas)
        self.channel_records = dict(summary.channels)
        referenced = {cid for c in summary.chunk_indexes for cid in c.message_index_offsets}
        missing_schemas = {s for s, _, _, _ in self._pending_channels.values() if s and s not in self._schemas}
        if not self._pending_channels or referenced - set(self._pending_channels) or missing_schemas:
            self._scan_definitions()  # a valid layout may keep schemas (or channels) in the data section only
        if summary.statistics is not None:
            self.message_count = summary.statistics.message_count
            self._check_channel_counts(summary.statistics.message_count,
                                       dict(summary.statistics.channel_message_counts))
            if summary.statistics.message_count:
                self.start_time = summary.statistics.message_start_time
                self.end_time = summary.statistics.message_end_time
        else:
            self.start_time = self._chunks[0].start
            self.end_time = max(c.end for c in self._chunks)
        for channel_id in sorted(self._pending_channels):
            self._register(channel_id)

    def _check_layout(self) -> None:
        """The data section against the summary, without decompressing: each indexed chunk's record (type,
        length, times, compression, sizes) against its chunk index, its message index records (type, channel,
        entries inside the chunk's extent and time range) against the offsets the index gives, and every
        chunk the file holds against the chunk index. Record headers only: one read per chunk and one for its
        message indexes, walking record by record only where something unindexed lies. The kernel reads no
        more than those records (no read-ahead): from a cold disk that is all this walk needs, and a leading
        copy reading the whole file meanwhile does not have to share the disk with it."""
        reads = _ScatteredReads(self._file.fileno())
        try:
            self._walk_layout(reads)
        finally:
            reads.close()

    def _walk_layout(self, reads: _ScatteredReads) -> None:
        """Every record of the data section, to its end: a chunk the index lacks, a message outside any chunk
        and what follows an early DataEnd are found too (readers that follow the index skip them)."""
        indexed = {c.offset: c for c in self._chunks}
        position, end = 8, self._data_end
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
            opcode, length = _REC.unpack_from(head)
            if opcode == OP_DATA_END and ended is None:
                ended = position  # records may follow it: every one is looked at
            if position + 9 + length > end:
                self._lost(f'record at offset {position}', f'claims {length} bytes, past the data section; the '
                                                           'file is not read beyond it')
                break
            if opcode == OP_CHUNK:
                start, stop = struct.unpack_from('<QQ', head, 9) if len(head) >= 25 else (0, 0)
                self._lost(f'chunk at offset {position}', 'not in the chunk index, which readers follow (its '
                                                          'messages would be skipped); read as well')
                self._chunks.append(_Chunk(start, stop, position, 9 + length))
            elif opcode == OP_MESSAGE:
                loose.append((position, length))
            position += 9 + length
        self._read_loose(reads, loose)
        if ended is not None and any(c.offset > ended for c in self._chunks):
            self.warnings.append(f'{self.path}: chunks follow the DataEnd record at offset {ended}, which should '
                                 'end the data section; they are read')
        self._chunks.sort(key=lambda c: (c.start, c.offset))
        self._by_offset = {c.offset: c for c in self._chunks}

    def _read_loose(self, reads: _ScatteredReads, loose: list[tuple[int, int]]) -> None:
        """Message records outside any chunk: the specification allows them and readers that follow the chunk
        index skip them; bagfault reads them (into memory, as they are few) and merges them in time order."""
        for position, length in loose:
            if length < MESSAGE_HEAD:
                self._lost(f'message record at offset {position}', f'{length} bytes, shorter than its header')
                continue
            data = memoryview(bytes(reads.read(9 + length, position)))
            if len(data) != 9 + length:
                self._lost(f'message record at offset {position}', 'runs past the end of the file')
                continue
            channel_id, _seq, log_time, publish_time = _MSG.unpack_from(data, 9)
            self._loose.append((log_time, publish_time, channel_id, position, data[9 + MESSAGE_HEAD:]))
        self._loose.sort(key=lambda m: (m[0], m[3]))

    def _check_channel_counts(self, total: int, declared: dict[int, int]) -> None:
        """The Statistics record's messages (per channel, or in total where a writer left the map empty) against
        the message indexes of every chunk and the messages outside chunks (each chunk's indexes are checked
        against its records when it is decompressed, or under --verify)."""
        if any(c.counts is None and c.index_offsets is not None for c in self._chunks):
            return
        if any(c.index_offsets is None or not c.index_offsets for c in self._chunks):
            return  # unindexed chunks (salvage) or chunks without message indexes: not countable here
        indexed: dict[int, int] = {}
        for _, _, channel_id, _, _ in self._loose:
            indexed[channel_id] = indexed.get(channel_id, 0) + 1
        for chunk in self._chunks:
            for channel_id, count in (chunk.counts or {}).items():
                indexed[channel_id] = indexed.get(channel_id, 0) + count
        if not declared:
            if total != sum(indexed.values()):
                self._lost('the Statistics record', f'declares {total} messages, the message indexes '
                                                    f'{sum(indexed.values())}')
            return
        differ = [f'channel {cid}: {declared.get(cid, 0)} declared, {indexed.get(cid, 0)} indexed'
                  for cid in sorted(set(declared) | set(indexed)) if declared.get(cid, 0) != indexed.get(cid, 0)]
        if differ:
            self._lost('the Statistics record', f'its messages per channel and the message indexes disagree '
                                                f'({"; ".join(differ[:3])})')

    def _check_chunk(self, reads: _ScatteredReads, chunk: _Chunk) -> None:
        """One indexed chunk's record header and message index records against its chunk index."""
        head = reads.read(9 + _CHUNK_HEAD.size + 4 + 64, chunk.offset)
        where = f'chunk at offset {chunk.offset}'
        if len(head) < 9 + _CHUNK_HEAD.size + 4:
            self._lost(where, 'the chunk index points past the end of the file')
            return
        opcode, length = _REC.unpack_from(head)
        start, end, size, _ = _CHUNK_HEAD.unpack_from(head, 9)
        (name_length,) = _U32.unpack_from(head, 9 + _CHUNK_HEAD.size)
        name = bytes(head[9 + _CHUNK_HEAD.size + 4:][:name_length])
        told = (OP_CHUNK, chunk.length, chunk.start, chunk.end, chunk.uncompressed_size, chunk.compression.encode())
        found = (opcode, 9 + length, start, end, size, name)
        if found != told:
            fields = ('type', 'length', 'start time', 'end time', 'uncompressed size', 'compression')
            differ = '; '.join(f'{f} {a!r} in the record, {b!r} in the index'
                               for f, a, b in zip(fields, found, told, strict=True) if a != b)
            self._lost(where, f'the record and its chunk index disagree ({differ})')
            return
        if not chunk.index_offsets:
            return
        first = min(chunk.index_offsets.values())
        data = reads.read(chunk.index_length, first) if first >= chunk.offset + chunk.length else b''
        counts, at, parts = {}, 0, []
        try:
            while at < len(data):
                opcode, length, channel_id, entries_length = _INDEX_HEAD.unpack_from(data, at)
                if opcode != OP_MESSAGE_INDEX or at + 9 + length > len(data) or 6 + entries_length > length:
                    raise Corrupt(f'a record of type {opcode:#x} where its message indexes should be')
                if chunk.index_offsets.get(channel_id) != first + at:
                    raise Corrupt(f'a message index of channel {channel_id} the chunk index does not list there')
                counts[channel_id] = entries_length // 16
                parts.append(data[at + 15:at + 15 + entries_length // 16 * 16])
                at += 9 + length
            entries = np.frombuffer(b''.join(parts), '<u8').reshape(-1, 2)  # (log time, offset), every channel
            if len(entries) and (int(entries[:, 1].max()) + 9 + MESSAGE_HEAD > size or
                                 int(entries[:, 0].min()) < start or int(entries[:, 0].max()) > end):
                raise Corrupt('its message indexes point outside the chunk (an offset past its records, or a '
                              'time outside its range)')
        except (struct.error, ValueError) as exc:
            self._lost(where, f'its message indexes cannot be read ({one_line(exc)})')
            return
        except Corrupt as exc:
            self._lost(where, str(exc))
            return
        if set(counts) != set(chunk.index_offsets):
            self._lost(where, f'its chunk index lists message indexes of channels {sorted(chunk.index_offsets)}, '
                              f'the file holds {sorted(counts)}')
            return
        chunk.counts = counts

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
            opcode, length = _REC.unpack(self._file.read(9))
            if position + 9 + length > self._size:
                raise Corrupt(f'record at offset {position} claims {length} bytes, past the end of the file')
            if opcode == 0x0F:  # data end: the summary follows
                return
            if opcode == OP_CHUNK:
                data = self._chunk_at(position)
                if data is not None:
                    self._split(data, position)
            elif opcode in (OP_SCHEMA, OP_CHANNEL) and length <= MAX_CHUNK:
                body = memoryview(self._file.read(length))
                self._definition(opcode, body, 0, len(body))
            position += 9 + length

    def _read_rosbag2_metadata(self, metadata: dict[str, str]) -> None:
        self.ros_distro = distro_of(metadata) or self.ros_distro

    def _register(self, channel_id: int) -> int:
        index = self._ids.get(channel_id)
        if index is not None:
            return index
        schema_id, topic, encoding, metadata = self._pending_channels[channel_id]
        name, schema_encoding, text = self._schemas.get(schema_id, ('', '', ''))
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
        opcode, length = _REC.unpack(self._file.read(9))
        if opcode != OP_CHUNK:
            raise Corrupt(f'the index points at a record of type {opcode:#x}, not a chunk')
        if offset + 9 + length > self._size:
            raise Corrupt(f'the chunk claims {length} bytes, past the end of the file')
        return self._records(memoryview(self._file.read(length)), offset)

    def _records(self, body: memoryview, offset: int) -> memoryview:
        """A chunk record's body decompressed and checked against its size and CRC."""
        if len(body) < _CHUNK_HEAD.size + 4:
            raise Corrupt(f'the chunk at offset {offset} is shorter than its header')
        _, _, size, crc = _CHUNK_HEAD.unpack_from(body, 0)
        compression, pos = _string(body, _CHUNK_HEAD.size, len(body))
        (records_len,) = _U64.unpack_from(body, pos)
        pos += 8
        if pos + records_len > len(body):
            raise Corrupt(f'the chunk claims {records_len} bytes of records, more than it holds')
        data = _decompress(compression, body[pos : pos + records_len], size)
        if len(data) != size:
            raise Corrupt(f'the chunk holds {len(data)} bytes of records, its header says {size}')
        if crc and zlib.crc32(data) != crc:
            raise Corrupt(f'CRC mismatch (stored {crc:#010x}, computed {zlib.crc32(data):#010x})')
        return data

    def _definition(self, opcode: int, data: memoryview, body: int, end: int) -> None:
        """A schema or channel record (inside a chunk or at the top level): known from here on."""
        if opcode == OP_SCHEMA:
            (schema_id,) = _U16.unpack_from(data, body)
            name, p = _string(data, body + 2, end)
            encoding, p = _string(data, p, end)
            (size,) = _U32.unpack_from(data, p)
            if p + 4 + size > end:
                raise Corrupt('a schema runs past its record')
            self._schemas.setdefault(schema_id, (name, encoding, bytes(data[p + 4 : p + 4 + size]).decode(
                errors='replace')))
            return
        channel_id, schema_id = struct.unpack_from('<HH', data, body)
        topic, p = _string(data, body + 4, end)
        encoding, p = _string(data, p, end)
        (map_len,) = _U32.unpack_from(data, p)
        p += 4
        stop, metadata = p + map_len, {}
        if stop > end:
            raise Corrupt('a channel runs past its record')
        while p < stop:
            key, p = _string(data, p, stop)
            value, p = _string(data, p, stop)
            metadata[key] = value
        known = self._pending_channels.setdefault(channel_id, (schema_id, topic, encoding, metadata))
        if known[:3] != (schema_id, topic, encoding):
            raise Corrupt(f'channel {channel_id} is defined as {known[1]!r} and again as {topic!r} (schema '
                          f'{known[0]}/{schema_id}, encoding {known[2]!r}/{encoding!r})')

    def _split(self, data: memoryview, offset: int) -> list[Split]:
        """Messages of a decompressed chunk; a record that cannot be read ends the chunk (an error or a loss)."""
        out = []
        pos, end = 0, len(data)
        unpack_rec, unpack_msg = _REC.unpack_from, _MSG.unpack_from
        while pos < end:
            try:
                if pos + 9 > end:
                    raise Corrupt(f'{end - pos} stray bytes after the last record')
                opcode, length = unpack_rec(data, pos)
                body = pos + 9
                if body + length > end:
                    raise Corrupt(f'record at {pos} claims {length} bytes, past the end of the chunk')
                if opcode == OP_MESSAGE:
                    if length < MESSAGE_HEAD:
                        raise Corrupt(f'message record at {pos} is {length} bytes, shorter than its header')
                    channel_id, _seq, log_time, publish_time = unpack_msg(data, body)
                    out.append((log_time, publish_time, channel_id, pos, data[body + MESSAGE_HEAD : body + length]))
                elif opcode in (OP_SCHEMA, OP_CHANNEL):
                    self._definition(opcode, data, body, body + length)
                else:  # a flipped bit in a message's opcode looks like this, and every reader skips it
                    self._lost(f'chunk at offset {offset}', f'a record of type {opcode:#x} at {pos} inside it (only '
                                                            'schemas, channels and messages belong there); skipped')
            except (Corrupt, struct.error, UnicodeDecodeError) as exc:
                self._lost(f'chunk at offset {offset}', f'{one_line(exc)}; {len(out)} messages before it are kept')
                return out
            pos = body + length
        return out

    def _check_counts(self, chunk: _Chunk, items: list[Split]) -> None:
        """The messages found in a chunk, per channel, against the entries of its message indexes."""
        if not chunk.counts:
            return
        found: dict[int, int] = {}
        for item in items:
            found[item[2]] = found.get(item[2], 0) + 1
        if found != chunk.counts:
            differ = ', '.join(f'channel {cid}: {chunk.counts.get(cid, 0)} indexed, {found.get(cid, 0)} found'
                               for cid in sorted(set(found) | set(chunk.counts))
                               if found.get(cid, 0) != chunk.counts.get(cid, 0))
            self._lost(f'chunk at offset {chunk.offset}', f'its messages and its message indexes disagree ({differ})')

    def _scan_unindexed(self, summary: Summary | None) -> None:
        """Files without chunk index: every record of the data section read once, in file order (top-level
        messages, chunks after a DataEnd, records of unknown type, which the specification lets readers skip);
        messages kept in memory. What the file declares is checked against what it holds: each chunk's
        message indexes, the DataEnd record's CRC, the Statistics record of a summary without chunk index."""
        messages: list[Split] = []
        if summary is not None:
            for schema in summary.schemas.values():
                self._schemas.setdefault(schema.id, (schema.name, schema.encoding,
                                                     schema.data.decode(errors='replace')))
            for channel in summary.channels.values():
                self._pending_channels.setdefault(channel.id, (channel.schema_id, channel.topic,
                                                               channel.message_encoding, dict(channel.metadata)))
        try:
            self._walk_unindexed(messages)
        except (Corrupt, *READ_ERRORS) as exc:
            self._lost(f'after {len(messages)} messages', f'{one_line(exc)}')
        if summary is not None and summary.statistics is not None and \
                summary.statistics.message_count != len(messages):
            self._lost('the Statistics record', f'declares {summary.statistics.message_count} messages, the file '
                                                f'holds {len(messages)}')
        messages.sort(key=lambda m: (m[0], m[3]))
        for channel_id in sorted(self._pending_channels):
            self._register(channel_id)
        self._memory = messages
        self.message_count = len(messages)
        if messages:
            self.start_time, self.end_time = messages[0][0], messages[-1][0]

    def _walk_unindexed(self, messages: list[Split]) -> None:
        """The records of the data section into `messages` (position: the order found), checked as they come."""
        self._file.seek(0)
        crc = zlib.crc32(self._file.read(8))
        position, end = 8, self._data_end
        chunk: tuple[int, dict[int, int]] | None = None  # the last chunk: offset, messages per channel
        indexed: dict[int, int] = {}  # entries of the message indexes that follow it, per channel
        while position < end:
            head = self._file.read(9)
            if len(head) < 9:
                raise Corrupt(f'{len(head)} stray bytes at offset {position}, after the last record')
            opcode, length = _REC.unpack(head)
            if position + 9 + length > end:
                raise Corrupt(f'the record at offset {position} claims {length} bytes, past the end of the data '
                              'section')
            body = memoryview(self._file.read(length))
            if opcode != OP_MESSAGE_INDEX and chunk is not None:
                self._check_declared(*chunk, indexed)
                chunk, indexed = None, {}
            if opcode == OP_DATA_END:
                (declared,) = _U32.unpack_from(body) if length >= 4 else (0,)
                if declared and declared != crc:
                    raise Corrupt(f'the data section CRC does not match (stored {declared:#010x}, computed '
                                  f'{crc:#010x})')
            crc = zlib.crc32(body, zlib.crc32(head, crc))
            if opcode == OP_MESSAGE:
                if length < MESSAGE_HEAD:
                    raise Corrupt(f'the message record at offset {position} is shorter than its header')
                channel_id, _seq, log_time, publish_time = _MSG.unpack_from(body)
                messages.append((log_time, publish_time, channel_id, len(messages), body[MESSAGE_HEAD:]))
            elif opcode in (OP_SCHEMA, OP_CHANNEL):
                self._definition(opcode, body, 0, length)
            elif opcode == OP_CHUNK:
                found: dict[int, int] = {}
                for log_time, publish_time, channel_id, _, data in self._split(self._records(body, position),
                                                                                position):
                    messages.append((log_time, publish_time, channel_id, len(messages), data))
                    found[channel_id] = found.get(channel_id, 0) + 1
                chunk = (position, found)
            elif opcode == OP_MESSAGE_INDEX and chunk is not None and length >= 6:
                channel_id, entries = struct.unpack_from('<HI', body)
                indexed[channel_id] = indexed.get(channel_id, 0) + entries // 16
            elif opcode == OP_METADATA:
                name, at = _string(body, 0, length)
                if name == 'rosbag2':
                    self._read_rosbag2_metadata(_string_map(body, at, length))
            elif opcode == OP_FOOTER:
                raise Corrupt(f'a Footer record at offset {position}, inside the data section')
            position += 9 + length
        if chunk is not None:
            self._check_declared(*chunk, indexed)

    def _check_declared(self, offset: int, found: dict[int, int], indexed: dict[int, int]) -> None:
        """A chunk's messages per channel against the message indexes after it (none: nothing declared)."""
        if indexed and indexed != found:
            differ = ', '.join(f'channel {cid}: {indexed.get(cid, 0)} indexed, {found.get(cid, 0)} found'
                               for cid in sorted(set(found) | set(indexed)) if found.get(cid, 0) != indexed.get(cid, 0))
            self._lost(f'chunk at offset {offset}', f'its messages and its message indexes disagree ({differ})')

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
        ids, pending, register = self._ids, self._pending_channels, self._register
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
            items = self._split(data, chunk.offset) if data is not None else []
            if data is not None:
                self._check_counts(chunk, items)
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
            return self._records(memoryview(record)[9:], ref.offset)
        except Corrupt as exc:
            raise InputError(f'{self.path}: corrupt MCAP file: chunk at offset {ref.offset}: {one_line(exc)}') from None
        except READ_ERRORS as exc:
            raise InputError(f'{self.path}: corrupt chunk data ({one_line(exc)})') from None

    def messages_of(self, ref: ChunkRef, records: memoryview) -> list[RawItem]:
        """The messages of a decompressed chunk, in its order (chunks of the copy path are in time order)."""
        items = self._split(records, ref.offset)
        self._check_counts(self._by_offset[ref.offset], items)
        if any(items[i][0] > items[i + 1][0] for i in range(len(items) - 1)):
            items.sort(key=lambda m: (m[0], m[3]))
        return list(self._known(items))

    def verify_chunk(self, ref: ChunkRef) -> None:
        """`--verify` of a copied chunk (from any thread; nothing of the source changes): read again,
        decompressed, CRC-checked, its records walked and counted against its message indexes."""
        record = os.pread(self._file.fileno(), ref.length, ref.offset)
        if len(record) != ref.length:
            raise InputError(f'{self.path}: truncated chunk at offset {ref.offset}')
        data = self.records_of(ref, record)
        counts: dict[int, int] = {}
        pos, end = 0, len(data)
        where = f'{self.path}: corrupt MCAP file: chunk at offset {ref.offset} (copied, then verified)'
        while pos < end:
            if pos + 9 > end:
                raise InputError(f'{where}: {end - pos} stray bytes after the last record')
            opcode, length = _REC.unpack_from(data, pos)
            if pos + 9 + length > end:
                raise InputError(f'{where}: record at {pos} claims {length} bytes, past the end of the chunk')
            if opcode == OP_MESSAGE:
                if length < MESSAGE_HEAD:
                    raise InputError(f'{where}: message record at {pos} is shorter than its header')
                (channel_id,) = _U16.unpack_from(data, pos + 9)
                counts[channel_id] = counts.get(channel_id, 0) + 1
            elif opcode not in (OP_SCHEMA, OP_CHANNEL):
                raise InputError(f'{where}: a record of type {opcode:#x} at {pos} inside it')
            pos += 9 + length
        expected = self._by_offset[ref.offset].counts
        if expected is not None and counts != expected:
            raise InputError(f'{where}: its message indexes list {sum(expected.values())} messages, it holds '
                             f'{sum(counts.values())}')

    def close(self) -> None:
        """Release the file."""
        self._file.close()

