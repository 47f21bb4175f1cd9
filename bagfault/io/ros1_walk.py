"""The records of a ROS 1 bag (format 2.0) as the file holds them, not as its index says: every record of the
data section walked by its header, every chunk split into its records. rosbags follows the bag's index (the
header's chunk_count of chunk infos, each chunk's index data), so a message the index forgot, a chunk it does
not list or a message outside any chunk is invisible to it; this walk finds them, and the source checks what
the index declares against it.
"""

from __future__ import annotations

import bz2
import os
import struct
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import lz4.frame
import numpy as np

if TYPE_CHECKING:
    from pathlib import Path

VERSION = b'#ROSBAG V2.0\n'
OP_MESSAGE, OP_BAG_HEADER, OP_INDEX_DATA, OP_CHUNK, OP_CHUNK_INFO, OP_CONNECTION = 2, 3, 4, 5, 6, 7
_U32 = struct.Struct('<I')
_ENTRY = np.dtype([('sec', '<u4'), ('nsec', '<u4'), ('offset', '<u4')])  # an index data entry


class Corrupt(Exception):  # noqa: N818 - a signal, turned into InputError or a loss by the source
    """A part of the bag cannot be read."""


@dataclass
class ChunkRecord:
    """A chunk record of the data section and the index data records that follow it."""

    position: int
    data_position: int
    data_size: int
    compression: str
    size: int  # uncompressed
    entries: dict[int, np.ndarray] = field(default_factory=dict)  # conn -> its index data entries (time, offset)


@dataclass(frozen=True)
class Message:
    """A message data record: its connection id, time (ns), offset (in its chunk, or in the file) and data."""

    conn: int
    time: int
    offset: int
    data: bytes | memoryview


@dataclass
class Layout:
    """What the data section holds, in file order, and what the index section holds."""

    index_pos: int
    chunks: list[ChunkRecord] = field(default_factory=list)
    loose: list[Message] = field(default_factory=list)  # message data records outside any chunk
    index_connections: int = 0  # connection records in the index section
    index_chunk_infos: int = 0


def fields(header: bytes | memoryview) -> dict[bytes, bytes]:
    """The name=value fields of a record header; a field that runs past its header is corrupt."""
    out = {}
    at = 0
    while at < len(header):
        if at + 4 > len(header):
            raise Corrupt('a record header ends inside a field length')
        (length,) = _U32.unpack_from(header, at)
        if at + 4 + length > len(header):
            raise Corrupt('a record header field runs past its header')
        name, found, value = bytes(header[at + 4:at + 4 + length]).partition(b'=')
        if not found:
            raise Corrupt('a record header field without "="')
        out[name] = value
        at += 4 + length
    return out


def _u32(values: dict[bytes, bytes], name: bytes) -> int:
    raw = values.get(name, b'')
    if len(raw) != 4:
        raise Corrupt(f'a record without a 4-byte {name.decode()!r} field')
    return int(_U32.unpack(raw)[0])


def _time(values: dict[bytes, bytes], name: bytes) -> int:
    raw = values.get(name, b'')
    if len(raw) != 8:
        raise Corrupt(f'a record without an 8-byte {name.decode()!r} field')
    sec, nsec = struct.unpack('<II', raw)
    return int(sec) * 1_000_000_000 + int(nsec)


def walk(path: Path) -> Layout:
    """The data section record by record (its end: the header's index_pos), then the index section, where
    bytes that make no whole record end the walk (trailing garbage). No read is larger than the file has left."""
    with path.open('rb') as stream:
        size = os.fstat(stream.fileno()).st_size
        if stream.read(len(VERSION)) != VERSION:
            raise Corrupt('not a ROS 1 bag of format 2.0')
        position = len(VERSION)
        header, data_size = _record_head(stream, position, size)
        values = fields(header)
        if values.get(b'op') != bytes([OP_BAG_HEADER]) or len(values.get(b'index_pos', b'')) != 8:
            raise Corrupt('the first record is not a bag header')
        (index_pos,) = struct.unpack('<Q', values[b'index_pos'])
        if index_pos == 0:
            raise Corrupt('the bag has no index (its recording was not closed; `rosbag reindex` writes one)')
        if index_pos > size:
            raise Corrupt(f'its header puts the index at {index_pos}, past the end of the file ({size} bytes)')
        layout = Layout(index_pos)
        position += 8 + len(header) + data_size
        stream.seek(position)
        while position < index_pos:
            header, data_size = _record_head(stream, position, index_pos)
            values = fields(header)
            data_position = position + 8 + len(header)
            op = values.get(b'op', b'\xff')[:1]
            if op == bytes([OP_CHUNK]):
                layout.chunks.append(ChunkRecord(position, data_position, data_size,
                                                 values.get(b'compression', b'').decode(errors='replace'),
                                                 _u32(values, b'size')))
                stream.seek(data_size, os.SEEK_CUR)
            elif op == bytes([OP_INDEX_DATA]):
                if not layout.chunks:
                    raise Corrupt(f'index data at {position} before any chunk')
                conn, count = _u32(values, b'conn'), _u32(values, b'count')
                if count * _ENTRY.itemsize != data_size:
                    raise Corrupt(f'index data at {position} lists {count} entries in {data_size} bytes')
                entries = np.frombuffer(stream.read(data_size), _ENTRY)
                chunk = layout.chunks[-1]
                chunk.entries[conn] = np.concatenate([chunk.entries[conn], entries]) if conn in chunk.entries \
                    else entries
            elif op == bytes([OP_MESSAGE]):
                layout.loose.append(Message(_u32(values, b'conn'), _time(values, b'time'), position,
                                            stream.read(data_size)))
            else:  # connection records (rosbag keeps them in chunks and the index) or records of unknown type
                stream.seek(data_size, os.SEEK_CUR)
            position = data_position + data_size
        if position != index_pos:
            raise Corrupt(f'a record at {position} runs across the index position {index_pos}')
        _walk_index(stream, layout, size)
        return layout


def _record_head(stream: object, position: int, end: int) -> tuple[bytes, int]:
    """A record's header and data size, both checked to end by `end`."""
    read = stream.read  # type: ignore[attr-defined]
    raw = read(4)
    if len(raw) < 4 or position + 4 > end:
        raise Corrupt(f'a record at {position} is cut short')
    (length,) = _U32.unpack(raw)
    if position + 8 + length > end:
        raise Corrupt(f'the record at {position} claims a {length}-byte header, past the end')
    header = read(length)
    raw = read(4)
    if len(header) != length or len(raw) < 4:
        raise Corrupt(f'the record at {position} is cut short')
    (data_size,) = _U32.unpack(raw)
    if position + 8 + length + data_size > end:
        raise Corrupt(f'the record at {position} claims {data_size} bytes of data, past the end')
    return header, data_size


def _walk_index(stream: object, layout: Layout, size: int) -> None:
    """Connection and chunk info records of the index section; a record cut short ends it (trailing bytes)."""
    position = layout.index_pos
    stream.seek(position)  # type: ignore[attr-defined]
    while position < size:
        try:
            header, data_size = _record_head(stream, position, size)
            op = fields(header).get(b'op', b'')[:1]
        except Corrupt:
            return
        if op == bytes([OP_CONNECTION]):
            layout.index_connections += 1
        elif op == bytes([OP_CHUNK_INFO]):
            layout.index_chunk_infos += 1
        stream.seek(data_size, os.SEEK_CUR)  # type: ignore[attr-defined]
        position += 8 + len(header) + data_size


def decompress(chunk: ChunkRecord, raw: bytes) -> bytes:
    """A chunk's records, decompressed and checked against the size its header gives."""
    try:
        if chunk.compression == 'none':
            data = raw
        elif chunk.compression == 'bz2':
            data = bz2.decompress(raw)
        elif chunk.compression == 'lz4':
            data = lz4.frame.decompress(raw)
        else:
            raise Corrupt(f'the chunk at {chunk.position} has unknown compression {chunk.compression!r}')
    except (OSError, ValueError, RuntimeError, EOFError) as exc:
        raise Corrupt(f'the chunk at {chunk.position} does not decompress ({exc})') from None
    if len(data) != chunk.size:
        raise Corrupt(f'the chunk at {chunk.position} holds {len(data)} bytes, its header says {chunk.size}')
    return data


def split(chunk: ChunkRecord, data: bytes) -> tuple[list[Message], list[int]]:
    """A chunk's message data records and the connection ids its connection records define; any other record
    inside a chunk (a flipped op, a record of unknown type) is corrupt: readers that follow the index skip it."""
    view = memoryview(data)
    messages: list[Message] = []
    defined: list[int] = []
    at = 0
    while at < len(view):
        if at + 4 > len(view):
            raise Corrupt(f'the chunk at {chunk.position} ends with {len(view) - at} stray bytes')
        (length,) = _U32.unpack_from(view, at)
        if at + 8 + length > len(view):
            raise Corrupt(f'a record at {at} in the chunk at {chunk.position} runs past the chunk')
        values = fields(view[at + 4:at + 4 + length])
        (data_size,) = _U32.unpack_from(view, at + 4 + length)
        start = at + 8 + length
        if start + data_size > len(view):
            raise Corrupt(f'a record at {at} in the chunk at {chunk.position} runs past the chunk')
        op = values.get(b'op', b'')[:1]
        if op == bytes([OP_MESSAGE]):
            messages.append(Message(_u32(values, b'conn'), _time(values, b'time'), at, view[start:start + data_size]))
        elif op == bytes([OP_CONNECTION]):
            defined.append(_u32(values, b'conn'))
        else:
            raise Corrupt(f'a record of op {op.hex() or "(none)"} at {at} in the chunk at {chunk.position} (only '
                          'connections and messages belong in a chunk)')
        at = start + data_size
    return messages, defined


def check_entries(chunk: ChunkRecord, messages: list[Message]) -> str | None:
    """The chunk's index data against its messages (per connection: times and offsets); what differs, or None."""
    found: dict[int, list[tuple[int, int]]] = {}
    for message in messages:
        found.setdefault(message.conn, []).append((message.time, message.offset))
    differ = []
    for conn in sorted(set(found) | set(chunk.entries)):
        entries = chunk.entries.get(conn, np.empty(0, _ENTRY))
        listed = sorted(zip((entries['sec'].astype(np.int64) * 1_000_000_000 + entries['nsec']).tolist(),
                            entries['offset'].tolist(), strict=True))
        held = sorted(found.get(conn, []))
        if listed != held:
            what = 'at other times or offsets' if len(listed) == len(held) else ''
            differ.append(f'connection {conn}: {len(listed)} indexed, {len(held)} found {what}'.strip())
    return '; '.join(differ[:3]) or None
