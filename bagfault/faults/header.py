"""std_msgs/Header stamp patched in the CDR bytes, without decoding the message."""

from __future__ import annotations

import struct
from typing import Any

NS = 1_000_000_000


def has_header(msgtype: str, store: Any) -> bool:
    """True when the type's first field is a std_msgs/msg/Header (stamp at a fixed offset)."""
    fields = store.fielddefs.get(msgtype, ((), ()))[1]
    return bool(fields) and fields[0][1][1] == 'std_msgs/msg/Header'


def shift_stamp(data: bytes | memoryview, offset_ns: int) -> bytes:
    """Add offset_ns to header.stamp (sec int32 at byte 4, nanosec uint32 at byte 8)."""
    raw = bytearray(data)
    fmt = '<iI' if raw[1] else '>iI'
    sec, nanosec = struct.unpack_from(fmt, raw, 4)
    total = sec * NS + nanosec + offset_ns
    struct.pack_into(fmt, raw, 4, total // NS, total % NS)
    return bytes(raw)
