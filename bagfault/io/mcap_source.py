"""MCAP input, read chunk by chunk in log-time order.

The `mcap` library parses the summary and metadata; chunks are read and
split here so that messages come out as zero-copy slices of one
decompressed buffer, channels found only inside chunks are still known,
and overlapping chunks are merged by log time.
"""

from __future__ import annotations

import heapq
import io
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import lz4.frame
import zstandard
from mcap.exceptions import McapError
from mcap.reader import NonSeekingReader, SeekingReader
from mcap.records import Channel as McapChannel
from mcap.records import Chunk, Message, Metadata, Schema
from mcap.stream_reader import StreamReader, breakup_chunk

from bagfault.errors import InputError
from bagfault.io.channel import Channel, normalize_msgtype

if TYPE_CHECKING:
    from collections.abc import Iterator


MAGIC = b'\x89MCAP0\r\n'
OP_SCHEMA, OP_CHANNEL, OP_MESSAGE = 0x03, 0x04, 0x05
_U16 = struct.Struct('<H')
_U32 = struct.Struct('<I')
_U64 = struct.Struct('<Q')
_REC = struct.Struct('<BQ')
_MSG = struct.Struct('<HIQQ')
_CHUNK_HEAD = struct.Struct('<QQQI')

RawItem = tuple[int, int, int, memoryview]  # channel index, log_time, publish_time, data


@dataclass
class _Chunk:
    start: int
    end: int
    offset: int


def _decompress(compression: str, data: bytes | memoryview, size: int) -> memoryview:
    if compression == '':
        return memoryview(data)
    if compression == 'zstd':
        return memoryview(zstandard.ZstdDecompressor().decompress(data, max_output_size=size))
    if compression == 'lz4':
        return memoryview(lz4.frame.decompress(bytes(data)))
    msg = f'unsupported chunk compression {compression!r}'
    raise InputError(msg)


def _string(buf: memoryview, pos: int) -> tuple[str, int]:
    (length,) = _U32.unpack_from(buf, pos)
    pos += 4
    return bytes(buf[pos : pos + length]).decode(), pos + length


class McapSource:
    """Messages of one MCAP file in log-time order."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.channels: list[Channel] = []
        self.ros_distro: str | None = None
        self.message_count: int | None = None
        self.start_time: int | None = None
        self.end_time: int | None = None
        self._ids: dict[int, int] = {}
        self._schemas: dict[int, tuple[str, str, str]] = {}
        self._pending_channels: dict[int, tuple[int, str, str, dict[str, str]]] = {}
        self._chunks: list[_Chunk] = []
        self._indexed = False
        try:
            self._file = path.open('rb')
        except OSError as exc:
            raise InputError(f'{path}: cannot open: {exc.strerror}') from None
        try:
            self._open()
        except InputError:
            self._file.close()
            raise
        except (McapError, struct.error, ValueError, KeyError, EOFError, zstandard.ZstdError, RuntimeError) as exc:
            self._file.close()
            raise InputError(f'{path}: corrupt or truncated MCAP file ({exc or type(exc).__name__})') from None

    def _open(self) -> None:
        head = self._file.read(8)
        if head != MAGIC:
            raise InputError(f'{self.path}: not an MCAP file (bad magic bytes)')
        self._file.seek(0, io.SEEK_END)
        if self._file.tell() < 8 + 9 + 20 + 8:
            raise InputError(f'{self.path}: truncated MCAP file')
        self._file.seek(-8, io.SEEK_END)
        if self._file.read(8) != MAGIC:
            raise InputError(f'{self.path}: truncated MCAP file (no closing magic; was the recording stopped cleanly?)')
        self._file.seek(0)
        reader = SeekingReader(self._file)
        summary = reader.get_summary()
        for record in reader.iter_metadata():
            if record.name == 'rosbag2':
                self._read_rosbag2_metadata(record.metadata)
        if summary is not None and summary.chunk_indexes:
            self._indexed = True
            for schema in summary.schemas.values():
                self._schemas[schema.id] = (schema.name, schema.encoding, schema.data.decode(errors='replace'))
            for channel in summary.channels.values():
                self._pending_channels[channel.id] = (channel.schema_id, channel.topic, channel.message_encoding,
                                                      dict(channel.metadata))
            self._chunks = sorted(
                (_Chunk(c.message_start_time, c.message_end_time, c.chunk_start_offset) for c in summary.chunk_indexes),
                key=lambda c: (c.start, c.offset),
            )
            known = set(self._pending_channels)
            referenced = {cid for c in summary.chunk_indexes for cid in c.message_index_offsets}
            if not known or referenced - known:
                for chunk in self._chunks:
                    self._split(self._read_chunk(chunk))
            if summary.statistics is not None:
                self.message_count = summary.statistics.message_count
                if summary.statistics.message_count:
                    self.start_time = summary.statistics.message_start_time
                    self.end_time = summary.statistics.message_end_time
            else:
                self.start_time = self._chunks[0].start
                self.end_time = max(c.end for c in self._chunks)
            for channel_id in sorted(self._pending_channels):
                self._register(channel_id)
        else:
            self._scan_unindexed()

    def _read_rosbag2_metadata(self, metadata: dict[str, str]) -> None:
        import yaml  # noqa: PLC0415

        try:
            info = yaml.safe_load(metadata.get('serialized_metadata', '')) or {}
            stored = info.get('rosbag2_bagfile_information', {}).get('ros_distro')
            self.ros_distro = stored or metadata.get('ROS_DISTRO')
        except yaml.YAMLError:
            self.ros_distro = metadata.get('ROS_DISTRO')

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

    def _read_chunk(self, chunk: _Chunk) -> memoryview:
        self._file.seek(chunk.offset)
        opcode, length = _REC.unpack(self._file.read(9))
        if opcode != 0x06:
            raise InputError(f'{self.path}: chunk index points at a record of type {opcode:#x}, not a chunk')
        body = memoryview(self._file.read(length))
        if len(body) < length:
            raise InputError(f'{self.path}: truncated chunk at offset {chunk.offset}')
        _, _, size, _ = _CHUNK_HEAD.unpack_from(body, 0)
        compression, pos = _string(body, _CHUNK_HEAD.size)
        (records_len,) = _U64.unpack_from(body, pos)
        pos += 8
        return _decompress(compression, body[pos : pos + records_len], size)

    def _split(self, data: memoryview) -> list[tuple[int, int, int, int, memoryview]]:
        """Messages of a decompressed chunk as (log, pub, mcap channel id, position, data)."""
        out = []
        pos, end = 0, len(data)
        unpack_rec, unpack_msg = _REC.unpack_from, _MSG.unpack_from
        while pos + 9 <= end:
            opcode, length = unpack_rec(data, pos)
            body = pos + 9
            if opcode == OP_MESSAGE:
                channel_id, _seq, log_time, publish_time = unpack_msg(data, body)
                out.append((log_time, publish_time, channel_id, pos, data[body + 22 : body + length]))
            elif opcode == OP_SCHEMA:
                (schema_id,) = _U16.unpack_from(data, body)
                name, p = _string(data, body + 2)
                encoding, p = _string(data, p)
                (size,) = _U32.unpack_from(data, p)
                self._schemas.setdefault(
                    schema_id, (name, encoding, bytes(data[p + 4 : p + 4 + size]).decode(errors='replace'))
                )
            elif opcode == OP_CHANNEL:
                channel_id, schema_id = struct.unpack_from('<HH', data, body)
                topic, p = _string(data, body + 4)
                encoding, p = _string(data, p)
                (map_len,) = _U32.unpack_from(data, p)
                p += 4
                stop, metadata = p + map_len, {}
                while p < stop:
                    key, p = _string(data, p)
                    value, p = _string(data, p)
                    metadata[key] = value
                self._pending_channels.setdefault(channel_id, (schema_id, topic, encoding, metadata))
            pos = body + length
        return out

    def _scan_unindexed(self) -> None:
        """Files without chunk index: read every record once, keep messages in memory."""
        self._file.seek(0)
        messages: list[tuple[int, int, int, int, memoryview]] = []
        order = 0
        for record in StreamReader(self._file, skip_magic=False).records:
            if isinstance(record, Chunk):
                parts = list(breakup_chunk(record))
            else:
                parts = [record]
            for part in parts:
                if isinstance(part, Schema):
                    self._schemas.setdefault(part.id, (part.name, part.encoding, part.data.decode(errors='replace')))
                elif isinstance(part, McapChannel):
                    self._pending_channels.setdefault(
                        part.id, (part.schema_id, part.topic, part.message_encoding, dict(part.metadata))
                    )
                elif isinstance(part, Metadata) and part.name == 'rosbag2':
                    self._read_rosbag2_metadata(part.metadata)
                elif isinstance(part, Message):
                    messages.append((part.log_time, part.publish_time, part.channel_id, order, memoryview(part.data)))
                    order += 1
        messages.sort(key=lambda m: (m[0], m[3]))
        for channel_id in sorted(self._pending_channels):
            self._register(channel_id)
        self._memory = messages
        self.message_count = len(messages)
        if messages:
            self.start_time, self.end_time = messages[0][0], messages[-1][0]

    def messages(self) -> Iterator[RawItem]:
        """(channel index, log_time, publish_time, data) in log-time order."""
        try:
            if not self._indexed:
                ids = self._ids
                for log_time, publish_time, channel_id, _, data in self._memory:
                    if channel_id in ids:
                        yield ids[channel_id], log_time, publish_time, data
                return
            yield from self._indexed_messages()
        except (struct.error, zstandard.ZstdError, RuntimeError, ValueError) as exc:
            raise InputError(f'{self.path}: corrupt chunk data ({exc})') from None

    def _indexed_messages(self) -> Iterator[RawItem]:
        ids, register = self._ids, self._register
        pending: list[tuple[int, int, int, int, int, memoryview]] = []
        chunks = self._chunks
        for number, chunk in enumerate(chunks):
            items = self._split(self._read_chunk(chunk))
            horizon = chunks[number + 1].start if number + 1 < len(chunks) else None
            in_order = all(items[i][0] <= items[i + 1][0] for i in range(len(items) - 1))
            if not pending and in_order and (horizon is None or not items or items[-1][0] <= horizon):
                for log_time, publish_time, channel_id, _, data in items:
                    index = ids.get(channel_id)
                    if index is None:
                        index = register(channel_id)
                    yield index, log_time, publish_time, data
                continue
            for log_time, publish_time, channel_id, pos, data in items:
                heapq.heappush(pending, (log_time, number, pos, publish_time, channel_id, data))
            while pending and (horizon is None or pending[0][0] < horizon):
                log_time, _, _, publish_time, channel_id, data = heapq.heappop(pending)
                index = ids.get(channel_id)
                if index is None:
                    index = register(channel_id)
                yield index, log_time, publish_time, data

    def close(self) -> None:
        """Release the file."""
        self._file.close()


def read_attachments(path: Path) -> list[tuple[str, bytes]]:
    """(name, data) of every attachment; used by `info` and tests."""
    with path.open('rb') as stream:
        return [(a.name, a.data) for a in NonSeekingReader(stream).iter_attachments()]
