"""Where bytes sit in an MCAP file bagfault writes: its magic, its header, the padding before copied runs.

Light to import (the `mcap` library's record classes, nothing that
compresses): the leading copy's guess places chunks with it before the run's
heavy imports (`engine/lead.py`), and the writer writes by it.
"""

from __future__ import annotations

import struct

from mcap.data_stream import RecordBuilder

from bagfault import __version__

MAGIC = b'\x89MCAP0\r\n'
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
