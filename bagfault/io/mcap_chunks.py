"""An MCAP chunk's records: decompressed, checked against its header, and split into zero-copy messages.

Shared by the three ways `McapSource` reads a file: the indexed path (chunk
by chunk in time order), the chunk copy's decode of touched chunks and
`--verify`, and the record-by-record walk of unindexed or cut files
(`mcap_salvage`). A part that cannot be read is `Corrupt` here; the source
turns it into an `InputError` or, with `--salvage`, a listed loss.
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import lz4.frame
import zstandard
from mcap.exceptions import McapError

from bagfault.errors import InputError, one_line
from bagfault.io.mcap_layout import (
    CHUNK_HEAD,
    MAX_RECORD,
    MESSAGE_FIELDS,
    MESSAGE_HEAD,
    OP_CHANNEL,
    OP_MESSAGE,
    OP_SCHEMA,
    RECORD_HEAD,
    U16,
    U32,
    U64,
)

if TYPE_CHECKING:
    from collections.abc import Callable

    Lost = Callable[[str, str], None]  # (where, reason): an error, or under --salvage a listed loss

Split = tuple[int, int, int, int, memoryview]  # log, publish, mcap channel id, position, data
READ_ERRORS = (McapError, struct.error, ValueError, KeyError, EOFError, zstandard.ZstdError, RuntimeError,
               UnicodeDecodeError, OSError, IndexError, MemoryError, zlib.error)  # what reading a damaged file raises


class Corrupt(Exception):  # noqa: N818 - a signal inside the reader, turned into InputError or a loss
    """A part of the file cannot be read."""


@dataclass
class IndexedChunk:
    """A chunk as the reader knows it: from its chunk index (and the record's header), or found unindexed."""

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


@dataclass
class Definitions:
    """The schemas and channels a file defines (summary, data section, inside chunks): each id once."""

    schemas: dict[int, tuple[str, str, str]] = field(default_factory=dict)  # id -> name, encoding, text
    channels: dict[int, tuple[int, str, str, dict[str, str]]] = field(default_factory=dict)  # id -> schema
    # id, topic, message encoding, metadata

    def add(self, opcode: int, data: memoryview, body: int, end: int) -> None:
        """A schema or channel record (inside a chunk or at the top level): known from here on; a channel
        defined again otherwise is Corrupt."""
        if opcode == OP_SCHEMA:
            (schema_id,) = U16.unpack_from(data, body)
            name, p = read_string(data, body + 2, end)
            encoding, p = read_string(data, p, end)
            (size,) = U32.unpack_from(data, p)
            if p + 4 + size > end:
                raise Corrupt('a schema runs past its record')
            self.schemas.setdefault(schema_id, (name, encoding, bytes(data[p + 4 : p + 4 + size]).decode(
                errors='replace')))
            return
        channel_id, schema_id = struct.unpack_from('<HH', data, body)
        topic, p = read_string(data, body + 4, end)
        encoding, p = read_string(data, p, end)
        (map_len,) = U32.unpack_from(data, p)
        p += 4
        stop, metadata = p + map_len, {}
        if stop > end:
            raise Corrupt('a channel runs past its record')
        while p < stop:
            key, p = read_string(data, p, stop)
            value, p = read_string(data, p, stop)
            metadata[key] = value
        known = self.channels.setdefault(channel_id, (schema_id, topic, encoding, metadata))
        if known[:3] != (schema_id, topic, encoding):
            raise Corrupt(f'channel {channel_id} is defined as {known[1]!r} and again as {topic!r} (schema '
                          f'{known[0]}/{schema_id}, encoding {known[2]!r}/{encoding!r})')


def decompress(compression: str, data: bytes | memoryview, size: int) -> memoryview:
    """A chunk's records decompressed (at most `size` bytes)."""
    if size > MAX_RECORD:
        raise Corrupt(f'chunk claims {size} uncompressed bytes')
    if compression == '':
        return memoryview(data)
    if compression == 'zstd':
        return memoryview(zstandard.ZstdDecompressor().decompress(data, max_output_size=size))
    if compression == 'lz4':
        return memoryview(lz4.frame.decompress(bytes(data)))
    raise InputError(f'unsupported chunk compression {compression!r}')


def read_string(buf: memoryview, pos: int, end: int) -> tuple[str, int]:
    """A length-prefixed string at `pos` and the position after it."""
    (length,) = U32.unpack_from(buf, pos)
    pos += 4
    if pos + length > end:
        raise Corrupt(f'a string of {length} bytes runs past its record')
    return bytes(buf[pos : pos + length]).decode(), pos + length


def read_string_map(buf: memoryview, pos: int, end: int) -> dict[str, str]:
    """A length-prefixed map of strings at `pos`."""
    (length,) = U32.unpack_from(buf, pos)
    pos += 4
    stop, out = pos + length, {}
    if stop > end:
        raise Corrupt(f'a map of {length} bytes runs past its record')
    while pos < stop:
        key, pos = read_string(buf, pos, stop)
        out[key], pos = read_string(buf, pos, stop)
    return out


def chunk_records(body: memoryview, offset: int) -> memoryview:
    """A chunk record's body (after opcode and length) decompressed and checked against its size and CRC."""
    if len(body) < CHUNK_HEAD.size + 4:
        raise Corrupt(f'the chunk at offset {offset} is shorter than its header')
    _, _, size, crc = CHUNK_HEAD.unpack_from(body, 0)
    compression, pos = read_string(body, CHUNK_HEAD.size, len(body))
    (records_len,) = U64.unpack_from(body, pos)
    pos += 8
    if pos + records_len > len(body):
        raise Corrupt(f'the chunk claims {records_len} bytes of records, more than it holds')
    data = decompress(compression, body[pos : pos + records_len], size)
    if len(data) != size:
        raise Corrupt(f'the chunk holds {len(data)} bytes of records, its header says {size}')
    if crc and zlib.crc32(data) != crc:
        raise Corrupt(f'CRC mismatch (stored {crc:#010x}, computed {zlib.crc32(data):#010x})')
    return data


def split_chunk(data: memoryview, offset: int, definitions: Definitions, lost: Lost) -> list[Split]:
    """Messages of a decompressed chunk (its schemas and channels added to `definitions`); a record that cannot
    be read ends the chunk (an error or a loss)."""
    out = []
    pos, end = 0, len(data)
    unpack_rec, unpack_msg = RECORD_HEAD.unpack_from, MESSAGE_FIELDS.unpack_from
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
                definitions.add(opcode, data, body, body + length)
            else:  # a flipped bit in a message's opcode looks like this, and every reader skips it
                lost(f'chunk at offset {offset}', f'a record of type {opcode:#x} at {pos} inside it (only '
                                                  'schemas, channels and messages belong there); skipped')
        except (Corrupt, struct.error, UnicodeDecodeError) as exc:
            lost(f'chunk at offset {offset}', f'{one_line(exc)}; {len(out)} messages before it are kept')
            return out
        pos = body + length
    return out


def check_counts(chunk: IndexedChunk, items: list[Split], lost: Lost) -> None:
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
        lost(f'chunk at offset {chunk.offset}', f'its messages and its message indexes disagree ({differ})')


def verify_records(data: memoryview, where: str, expected: dict[int, int] | None) -> None:
    """`--verify` of a copied chunk's decompressed records: every record walked, only schemas, channels and
    messages, the messages per channel as its message indexes say; InputError prefixed `where` otherwise."""
    counts: dict[int, int] = {}
    pos, end = 0, len(data)
    while pos < end:
        if pos + 9 > end:
            raise InputError(f'{where}: {end - pos} stray bytes after the last record')
        opcode, length = RECORD_HEAD.unpack_from(data, pos)
        if pos + 9 + length > end:
            raise InputError(f'{where}: record at {pos} claims {length} bytes, past the end of the chunk')
        if opcode == OP_MESSAGE:
            if length < MESSAGE_HEAD:
                raise InputError(f'{where}: message record at {pos} is shorter than its header')
            (channel_id,) = U16.unpack_from(data, pos + 9)
            counts[channel_id] = counts.get(channel_id, 0) + 1
        elif opcode not in (OP_SCHEMA, OP_CHANNEL):
            raise InputError(f'{where}: a record of type {opcode:#x} at {pos} inside it')
        pos += 9 + length
    if expected is not None and counts != expected:
        raise InputError(f'{where}: its message indexes list {sum(expected.values())} messages, it holds '
                         f'{sum(counts.values())}')
