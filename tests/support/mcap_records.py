"""MCAP files as edited lists of records, for the differential tests: written by hand from the MCAP
specification (opcode u8, length u64, little-endian fields), independent of bagfault's reader and writer.

A file is a Header, a data section of items (top-level records and chunks, a DataEnd among them so that it
can sit early), a summary and a Footer. Chunks keep their inner records; their message indexes and CRCs are
derived when the file is written, unless an edit left them stale on purpose (a buggy writer's lie). The
summary is derived by one of four rules: `honest` (every message counted, top-level ones included),
`chunks` (counts and indexes over chunks only, as a writer that forgot top-level messages leaves them:
consistent, and a lie), `stale` (the summary of the file before the edits, at its new place) or `none`.
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass, field, replace
from typing import Literal

import zstandard

MAGIC = b'\x89MCAP0\r\n'
HEADER, FOOTER, SCHEMA, CHANNEL, MESSAGE, CHUNK, MESSAGE_INDEX, CHUNK_INDEX = 1, 2, 3, 4, 5, 6, 7, 8
STATISTICS, DATA_END = 11, 15
UNKNOWN = 0x90  # an opcode the specification leaves to applications: readers skip it

SummaryRule = Literal['honest', 'chunks', 'stale', 'none']


def _str(text: str) -> bytes:
    raw = text.encode()
    return struct.pack('<I', len(raw)) + raw


def _map(pairs: bytes) -> bytes:
    return struct.pack('<I', len(pairs)) + pairs


def record(opcode: int, body: bytes) -> bytes:
    return struct.pack('<BQ', opcode, len(body)) + body


def message_body(channel: int, sequence: int, log_time: int, data: bytes) -> bytes:
    return struct.pack('<HIQQ', channel, sequence, log_time, log_time) + data


def message_fields(body: bytes) -> tuple[int, int]:
    """(channel id, log time) of a Message body."""
    channel, _sequence, log_time, _publish = struct.unpack_from('<HIQQ', body)
    return channel, log_time


def string_cdr(text: str) -> bytes:
    """A std_msgs/msg/String in CDR, as a ROS 2 publisher sends it."""
    raw = text.encode() + b'\0'
    body = struct.pack('<I', len(raw)) + raw
    return b'\0\x01\0\0' + body + b'\0' * (-len(body) % 4)


@dataclass(frozen=True)
class Raw:
    """A top-level record kept as bytes."""

    opcode: int
    body: bytes


@dataclass(frozen=True)
class Chunk:
    """A chunk: its inner records, compression, and (when an edit left them stale) the content its message
    indexes and time range describe."""

    records: tuple[Raw, ...]
    compression: Literal['', 'zstd'] = ''
    crc: bool = True
    stale_index_of: tuple[Raw, ...] | None = None  # the content the message indexes describe, when stale

    def messages(self) -> list[Raw]:
        return [r for r in self.records if r.opcode == MESSAGE]


Item = Raw | Chunk


@dataclass
class McapFile:
    """An MCAP file to write: header, data section items, and the rule its summary follows."""

    items: list[Item]
    summary: SummaryRule = 'honest'
    stale_summary: bytes = b''  # the summary section of the unedited file (for the `stale` rule)
    tail: bytes = b''  # bytes after the closing magic
    cut: int | None = None  # the file ends after this many bytes
    schemas: tuple[Raw, ...] = field(default=())
    channels: tuple[Raw, ...] = field(default=())

    def write(self) -> bytes:
        data, summary = self._data_and_summary()
        out = bytearray(data)
        summary_start = len(out) if summary else 0
        out += summary
        out += struct.pack('<BQQQ', FOOTER, 20, summary_start, 0)
        crc = zlib.crc32(bytes(out[summary_start:])) if summary else 0
        out += struct.pack('<I', crc) + MAGIC + self.tail
        return bytes(out if self.cut is None else out[:self.cut])

    def _data_and_summary(self) -> tuple[bytes, bytes]:
        out = bytearray(MAGIC + record(HEADER, _str('ros2') + _str('differential')))
        indexes: list[bytes] = []
        counted: dict[int, int] = {}
        times: list[int] = []
        chunks = 0
        for item in self.items:
            if isinstance(item, Raw):
                if item.opcode == MESSAGE and self.summary == 'honest':
                    channel, log_time = message_fields(item.body)
                    counted[channel] = counted.get(channel, 0) + 1
                    times.append(log_time)
                out += record(item.opcode, item.body)
                continue
            chunks += 1
            start = len(out)
            inner = b''.join(record(r.opcode, r.body) for r in item.records)
            payload = zstandard.ZstdCompressor().compress(inner) if item.compression == 'zstd' else inner
            described = item.records if item.stale_index_of is None else item.stale_index_of
            stamps = [message_fields(r.body)[1] for r in described if r.opcode == MESSAGE] or [0]
            body = (struct.pack('<QQQI', min(stamps), max(stamps), len(inner), zlib.crc32(inner) if item.crc else 0)
                    + _str(item.compression) + struct.pack('<Q', len(payload)) + payload)
            out += record(CHUNK, body)
            chunk_length = len(out) - start
            index_start = len(out)
            offsets: list[tuple[int, int]] = []
            for channel, entries in _message_indexes(described).items():
                offsets.append((channel, len(out)))
                out += record(MESSAGE_INDEX, struct.pack('<H', channel) + _map(b''.join(
                    struct.pack('<QQ', t, o) for t, o in entries)))
            for message in item.messages():
                channel, log_time = message_fields(message.body)
                counted[channel] = counted.get(channel, 0) + 1
                times.append(log_time)
            indexes.append(record(CHUNK_INDEX, struct.pack('<QQQQ', min(stamps), max(stamps), start, chunk_length)
                                  + _map(b''.join(struct.pack('<HQ', c, o) for c, o in offsets))
                                  + struct.pack('<Q', len(out) - index_start) + _str(item.compression)
                                  + struct.pack('<QQ', len(payload), len(inner))))
        if self.summary == 'none':
            return bytes(out), b''
        if self.summary == 'stale':
            return bytes(out), self.stale_summary
        statistics = (struct.pack('<QHIIII', sum(counted.values()), len(self.schemas), len(self.channels), 0, 0, chunks)
                      + struct.pack('<QQ', min(times, default=0), max(times, default=0))
                      + _map(b''.join(struct.pack('<HQ', c, n) for c, n in sorted(counted.items()))))
        summary = b''.join(record(r.opcode, r.body) for r in (*self.schemas, *self.channels))
        return bytes(out), summary + record(STATISTICS, statistics) + b''.join(indexes)


def _message_indexes(records: tuple[Raw, ...]) -> dict[int, list[tuple[int, int]]]:
    """Per channel, (log time, offset in the uncompressed chunk) of each message, as a writer indexes them."""
    out: dict[int, list[tuple[int, int]]] = {}
    offset = 0
    for raw in records:
        if raw.opcode == MESSAGE:
            channel, log_time = message_fields(raw.body)
            out.setdefault(channel, []).append((log_time, offset))
        offset += 9 + len(raw.body)
    return out


def summary_section(data: bytes) -> bytes:
    """The bytes between a file's summary start and its footer."""
    footer = len(data) - len(MAGIC) - 29
    _, _, summary_start, _, _ = struct.unpack_from('<BQQQI', data, footer)
    return data[summary_start:footer] if summary_start else b''


def source(*, topics: int = 2, per_chunk: int = 5, chunks: int = 4, compression: Literal['', 'zstd'] = '',
           crc: bool = True) -> McapFile:
    """A small ROS 2 MCAP: a std_msgs/String schema, `topics` channels, `chunks` chunks of `per_chunk` messages
    (10 ms apart, channels in turn), the schema and channels at top level and in the summary."""
    schema = Raw(SCHEMA, struct.pack('<H', 1) + _str('std_msgs/msg/String') + _str('ros2msg') + _str('string data'))
    channels = tuple(Raw(CHANNEL, struct.pack('<HH', number, 1) + _str(f'/topic{number}') + _str('cdr')
                         + _map(_str('offered_qos_profiles') + _str('')))
                     for number in range(1, topics + 1))
    items: list[Item] = [schema, *channels]
    count = 0
    for _ in range(chunks):
        inner = []
        for _ in range(per_chunk):
            channel = count % topics + 1
            inner.append(Raw(MESSAGE, message_body(channel, count, 10**9 + count * 10**7, string_cdr(f'm{count}'))))
            count += 1
        items.append(Chunk(tuple(inner), compression, crc))
    items.append(Raw(DATA_END, struct.pack('<I', 0)))
    built = McapFile(items, schemas=(schema,), channels=channels)
    built.stale_summary = summary_section(built.write())
    return built


def edited_chunk(chunk: Chunk, records: list[Raw], *, stale_index: bool) -> Chunk:
    """The chunk with new content; its message indexes describe the old content when `stale_index`."""
    old = chunk.records if chunk.stale_index_of is None else chunk.stale_index_of
    return replace(chunk, records=tuple(records), stale_index_of=old if stale_index else chunk.stale_index_of)
