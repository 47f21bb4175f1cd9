"""std_msgs/Header stamp patched in the CDR bytes, without decoding the message."""

from __future__ import annotations

import struct
from typing import Any

from bagfault.errors import MalformedMessageError
from bagfault.units import NS

INT32_MIN, INT32_MAX = -(2**31), 2**31 - 1


def has_header(msgtype: str, store: Any) -> bool:
    """True when the type's first field is a std_msgs/msg/Header (stamp at a fixed offset)."""
    fields = store.fielddefs.get(msgtype, ((), ()))[1]
    return bool(fields) and fields[0][1][1] == 'std_msgs/msg/Header'


def shift_stamp(data: bytes | memoryview, offset_ns: int) -> bytes:
    """Add offset_ns to header.stamp (sec int32 at byte 4, nanosec uint32 at byte 8)."""
    raw = bytearray(data)
    if len(raw) < 12:
        raise MalformedMessageError(f'{len(raw)} bytes cannot hold a CDR header and a stamp')
    fmt = '<iI' if raw[1] else '>iI'
    sec, nanosec = struct.unpack_from(fmt, raw, 4)
    total = sec * NS + nanosec + offset_ns
    if not INT32_MIN <= total // NS <= INT32_MAX:
        raise MalformedMessageError(f'stamp {sec}.{nanosec:09d} shifted by {offset_ns / NS:g} s leaves the '
                                    'range of builtin_interfaces/Time')
    struct.pack_into(fmt, raw, 4, total // NS, total % NS)
    return bytes(raw)
