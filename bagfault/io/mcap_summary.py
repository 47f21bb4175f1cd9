"""The summary section of an MCAP file, parsed with struct calls into the `mcap` library's record classes.

The `mcap` library reads a record field by field through a stream wrapper:
0.38 s for the 3000 chunk indexes of a 1.2 GB bag, more than half the time
of copying that bag's untouched chunks. This parser reads the section in
one call and unpacks each record with a few struct calls (about 20 ms);
`tests/io/test_mcap_summary.py` requires the same records as the library
on every file of the conformance set and the external bags.
"""

from __future__ import annotations

import struct
import zlib
from typing import IO

from mcap.records import Channel, ChunkIndex, Metadata, MetadataIndex, Schema, Statistics
from mcap.summary import Summary

from bagfault.io.mcap_layout import (
    FOOTER_LENGTH,
    INDEX_ENTRY,
    OP_CHANNEL,
    OP_CHUNK_INDEX,
    OP_FOOTER,
    OP_METADATA,
    OP_METADATA_INDEX,
    OP_SCHEMA,
    OP_STATISTICS,
    RECORD_HEAD,
    U16,
    U32,
    U64,
)

_CHUNK_TIMES = struct.Struct('<QQQQ')  # message start, message end, chunk start offset, chunk length
_CHUNK_SIZES = struct.Struct('<QQ')  # compressed, uncompressed
_STATISTICS = struct.Struct('<QHIIIIQQ')


class SummaryError(Exception):
    """The summary section cannot be parsed (a record runs past its end, a length that does not fit)."""


class _Fields:
    """A cursor over one record's body that refuses to read past it."""

    __slots__ = ('buf', 'end', 'pos')

    def __init__(self, buf: memoryview, pos: int, end: int) -> None:
        self.buf, self.pos, self.end = buf, pos, end

    def take(self, layout: struct.Struct) -> tuple[int, ...]:
        if self.pos + layout.size > self.end:
            raise SummaryError(f'a record at offset {self.pos} ends inside its fields')
        values = layout.unpack_from(self.buf, self.pos)
        self.pos += layout.size
        return values

    def raw(self) -> memoryview:
        (length,) = self.take(U32)
        if self.pos + length > self.end:
            raise SummaryError(f'a field of {length} bytes runs past its record')
        self.pos += length
        return self.buf[self.pos - length : self.pos]

    def text(self) -> str:
        return bytes(self.raw()).decode()

    def strings(self) -> dict[str, str]:
        (length,) = self.take(U32)
        end = self.pos + length
        if end > self.end:
            raise SummaryError(f'a map of {length} bytes runs past its record')
        inner, out = _Fields(self.buf, self.pos, end), {}
        while inner.pos < end:
            key = inner.text()
            out[key] = inner.text()
        self.pos = end
        return out

    def ids(self) -> dict[int, int]:
        (length,) = self.take(U32)
        if self.pos + length > self.end or length % INDEX_ENTRY.size:
            raise SummaryError(f'a map of {length} bytes does not fit its record')
        out = dict(entry for entry in INDEX_ENTRY.iter_unpack(self.buf[self.pos : self.pos + length]))
        self.pos += length
        return out


def read_footer(stream: IO[bytes], size: int) -> tuple[int, int]:
    """(summary start, summary CRC) from the footer before the closing magic; start 0 means no summary."""
    stream.seek(size - 8 - FOOTER_LENGTH)
    footer = stream.read(FOOTER_LENGTH)
    opcode, _, summary_start, _, crc = struct.unpack('<BQQQI', footer)
    if opcode != OP_FOOTER:
        raise SummaryError(f'no footer record before the closing magic (found type {opcode:#x})')
    return summary_start, crc


_LAST: list[tuple[bytes, Summary]] = []  # the last section parsed: a run's leading copy and its source read the same


def parse_summary(section: bytes | memoryview) -> Summary:
    """Schemas, channels, statistics, chunk and metadata indexes of a summary section (the bytes from the
    summary start to the footer); other records (summary offsets, attachment indexes, unknown ones) skipped.
    The same bytes twice in a row give the same records (not to be changed by the caller)."""
    data = bytes(section)
    if _LAST and _LAST[0][0] == data:
        return _LAST[0][1]
    summary = _parse(memoryview(data))
    _LAST[:] = [(data, summary)]
    return summary


def _parse(buf: memoryview) -> Summary:
    summary = Summary()
    pos, total = 0, len(buf)
    while pos < total:
        if pos + 9 > total:
            raise SummaryError(f'a record header at offset {pos} runs past the summary')
        opcode, length = RECORD_HEAD.unpack_from(buf, pos)
        body, end = pos + 9, pos + 9 + length
        if end > total:
            raise SummaryError(f'a record of {length} bytes at offset {pos} runs past the summary')
        fields = _Fields(buf, body, end)
        if opcode == OP_CHUNK_INDEX:
            start, stop, offset, chunk_length = fields.take(_CHUNK_TIMES)
            index_offsets = fields.ids()
            (index_length,) = fields.take(U64)
            compression = fields.text()
            compressed, uncompressed = fields.take(_CHUNK_SIZES)
            summary.chunk_indexes.append(ChunkIndex(
                message_start_time=start, message_end_time=stop, chunk_start_offset=offset,
                chunk_length=chunk_length, message_index_offsets=index_offsets, message_index_length=index_length,
                compression=compression, compressed_size=compressed, uncompressed_size=uncompressed))
        elif opcode == OP_SCHEMA:
            (schema_id,) = fields.take(U16)
            name, encoding = fields.text(), fields.text()
            summary.schemas[schema_id] = Schema(id=schema_id, name=name, encoding=encoding,
                                                data=bytes(fields.raw()))
        elif opcode == OP_CHANNEL:
            channel_id, schema_id = fields.take(U16) + fields.take(U16)
            topic, encoding = fields.text(), fields.text()
            summary.channels[channel_id] = Channel(id=channel_id, schema_id=schema_id, topic=topic,
                                                   message_encoding=encoding, metadata=fields.strings())
        elif opcode == OP_STATISTICS:
            count, schemas, channels, attachments, metadata, chunks, first, last = fields.take(_STATISTICS)
            summary.statistics = Statistics(
                message_count=count, schema_count=schemas, channel_count=channels, attachment_count=attachments,
                metadata_count=metadata, chunk_count=chunks, message_start_time=first, message_end_time=last,
                channel_message_counts=fields.ids())
        elif opcode == OP_METADATA_INDEX:
            offset, record_length = fields.take(_CHUNK_SIZES)
            summary.metadata_indexes.append(MetadataIndex(offset=offset, length=record_length, name=fields.text()))
        pos = end
    return summary


def read_summary(stream: IO[bytes], size: int) -> tuple[int, Summary | None]:
    """(summary start, the summary section parsed, its CRC checked) of an MCAP file of `size` bytes; (0, None)
    when the footer says it has none."""
    summary_start, section = read_section(stream, size)
    return (summary_start, parse_summary(section)) if summary_start else (0, None)


def raw_records(section: bytes | memoryview, opcode: int) -> list[bytes]:
    """The whole records (opcode and length included) of one type in a summary section, as written."""
    buf = memoryview(section)
    found, pos, total = [], 0, len(buf)
    while pos + 9 <= total:
        kind, length = RECORD_HEAD.unpack_from(buf, pos)
        end = pos + 9 + length
        if end > total:
            raise SummaryError(f'a record of {length} bytes at offset {pos} runs past the summary')
        if kind == opcode:
            found.append(bytes(buf[pos:end]))
        pos = end
    return found


def read_section(stream: IO[bytes], size: int) -> tuple[int, bytes]:
    """(summary start, the summary section's bytes up to the footer, its CRC checked); (0, b'') when the footer
    says there is none."""
    summary_start, crc = read_footer(stream, size)
    footer = size - 8 - FOOTER_LENGTH
    if not summary_start:
        return 0, b''
    if not 8 < summary_start <= footer:
        raise SummaryError(f'the footer points the summary at offset {summary_start}, outside the file')
    stream.seek(summary_start)
    covered = stream.read(footer + FOOTER_LENGTH - 4 - summary_start)  # up to the footer's CRC
    if crc and zlib.crc32(covered) != crc:
        raise SummaryError(f'summary CRC mismatch (stored {crc:#010x}, computed {zlib.crc32(covered):#010x})')
    return summary_start, covered[: footer - summary_start]


def read_metadata(stream: IO[bytes], index: MetadataIndex) -> Metadata:
    """The metadata record a metadata index points at."""
    stream.seek(index.offset)
    data = memoryview(stream.read(index.length))
    if len(data) < 9 or data[0] != OP_METADATA:
        raise SummaryError(f'the metadata index {index.name!r} points at offset {index.offset}, not at a metadata '
                           'record')
    (length,) = U64.unpack_from(data, 1)
    fields = _Fields(data, 9, min(9 + length, len(data)))
    return Metadata(name=fields.text(), metadata=fields.strings())
