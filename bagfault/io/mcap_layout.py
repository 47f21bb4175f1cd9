"""Where bytes sit in an MCAP file: its magic, the records' opcodes and fixed fields, the padding bagfault writes
before copied runs. The one home of these constants for the readers and the writer.

Light to import (the `mcap` library's record classes, nothing that
compresses): the leading copy's guess places chunks with it before the run's
heavy imports (`engine/lead.py`), and the writer writes by it.
"""

from __future__ import annotations

import struct

from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode

from bagfault import __version__

MAGIC = b'\x89MCAP0\r\n'
# the specification's opcodes (the `mcap` library's), as plain ints for the readers' inner loops
OP_FOOTER, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE = int(Opcode.FOOTER), int(Opcode.SCHEMA), int(Opcode.CHANNEL), \
    int(Opcode.MESSAGE)
OP_CHUNK, OP_MESSAGE_INDEX, OP_CHUNK_INDEX = int(Opcode.CHUNK), int(Opcode.MESSAGE_INDEX), int(Opcode.CHUNK_INDEX)
OP_STATISTICS, OP_METADATA, OP_METADATA_INDEX = int(Opcode.STATISTICS), int(Opcode.METADATA), int(Opcode.METADATA_INDEX)
OP_DATA_END = int(Opcode.DATA_END)
RECORD_HEAD = struct.Struct('<BQ')  # every record: opcode, length of what follows
U16, U32, U64 = struct.Struct('<H'), struct.Struct('<I'), struct.Struct('<Q')
MESSAGE_FIELDS = struct.Struct('<HIQQ')  # a message record's channel id, sequence, log time, publish time
MESSAGE_HEAD = MESSAGE_FIELDS.size  # 22 bytes before a message's data
INDEX_HEAD = struct.Struct('<BQHI')  # a message index record: opcode, length, channel id, entries length
CHUNK_HEAD = struct.Struct('<QQQI')  # a chunk record's start time, end time, uncompressed size, CRC
INDEX_ENTRY = struct.Struct('<HQ')  # a chunk index's entry per channel: its id, its message index's offset
FOOTER_LENGTH = 1 + 8 + 8 + 8 + 4  # opcode, length, summary start, summary offset start, summary CRC
MAX_RECORD = 1 << 32  # the mcap library's record size limit
ALIGN = 64 << 10  # the kernel copies bytes moved by a multiple of this as fast as `cp` (0.37 s for the 300 s bag),
# bytes moved by any other amount a third slower (0.48-0.53 s; docs/notes/performance.md, Alignment)
ALIGN_FROM = 1 << 20  # runs of copied chunks shorter than this stay where they fall: a padding costs more than it saves
PADDING_OPCODE = 0xA1  # a record of zeros before an aligned run: an application opcode (0x80-0xFF), which every
# reader skips (`mcap`, rosbags, the MCAP C++ reader of rosbag2 and the TypeScript one of Foxglove)


def header_library() -> str:
    """What an output's header names as its writer."""
    return f'bagfault {__version__}'


def record_bytes(record: object) -> bytes:
    """One record as the file holds it (opcode, length, fields), packed by the `mcap` library."""
    builder = RecordBuilder()
    record.write(builder)  # type: ignore[attr-defined]
    data: bytes = builder.end()  # type: ignore[no-untyped-call]
    return data


def padding_length(at: int, source: int, length: int) -> int:
    """Bytes of padding before `length` input bytes from `source` copied at output offset `at`, so that they land a
    multiple of ALIGN from where they are: 0, or a whole record (its opcode and length, 9 bytes, at least)."""
    if length < ALIGN_FROM:
        return 0
    gap = (source - at) % ALIGN
    return gap + ALIGN if 0 < gap < 9 else gap


def padding_record(length: int) -> bytes:
    """A padding record `length` bytes long, opcode and length included."""
    return struct.pack('<BQ', PADDING_OPCODE, length - 9) + bytes(length - 9)
