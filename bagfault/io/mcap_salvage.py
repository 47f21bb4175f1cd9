"""An MCAP file read record by record, front to back: a file without chunk index, or one cut short (--salvage).

Every record of the data section is read once in file order (top-level
messages, chunks after a DataEnd, records of unknown type, which the
specification lets readers skip), and what the file declares is checked
against what it holds: each chunk's message indexes, the DataEnd record's
CRC. The messages are kept in memory, in the order found.
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass, field
from typing import IO, TYPE_CHECKING

from bagfault.errors import one_line
from bagfault.io.mcap_chunks import (
    READ_ERRORS,
    Corrupt,
    Definitions,
    Split,
    chunk_records,
    read_string,
    read_string_map,
    split_chunk,
)
from bagfault.io.mcap_layout import (
    MESSAGE_FIELDS,
    MESSAGE_HEAD,
    OP_CHANNEL,
    OP_CHUNK,
    OP_DATA_END,
    OP_FOOTER,
    OP_MESSAGE,
    OP_MESSAGE_INDEX,
    OP_METADATA,
    OP_SCHEMA,
    RECORD_HEAD,
    U32,
)

if TYPE_CHECKING:
    from bagfault.io.mcap_chunks import Lost


@dataclass
class Walked:
    """What the walk found: the messages (position: the order found) and the `rosbag2` metadata records."""

    messages: list[Split] = field(default_factory=list)
    rosbag2: list[dict[str, str]] = field(default_factory=list)


def walk_records(file: IO[bytes], data_end: int, definitions: Definitions, lost: Lost) -> Walked:
    """Every record up to `data_end`; a part that cannot be read ends the walk as a loss after the messages
    read before it (schemas and channels go to `definitions`)."""
    walked = Walked()
    try:
        _walk(file, data_end, definitions, lost, walked)
    except (Corrupt, *READ_ERRORS) as exc:
        lost(f'after {len(walked.messages)} messages', f'{one_line(exc)}')
    return walked


def _walk(file: IO[bytes], data_end: int, definitions: Definitions, lost: Lost, walked: Walked) -> None:
    messages = walked.messages
    file.seek(0)
    crc = zlib.crc32(file.read(8))
    position = 8
    chunk: tuple[int, dict[int, int]] | None = None  # the last chunk: offset, messages per channel
    indexed: dict[int, int] = {}  # entries of the message indexes that follow it, per channel
    while position < data_end:
        head = file.read(9)
        if len(head) < 9:
            raise Corrupt(f'{len(head)} stray bytes at offset {position}, after the last record')
        opcode, length = RECORD_HEAD.unpack(head)
        if position + 9 + length > data_end:
            raise Corrupt(f'the record at offset {position} claims {length} bytes, past the end of the data '
                          'section')
        body = memoryview(file.read(length))
        if opcode != OP_MESSAGE_INDEX and chunk is not None:
            _check_declared(*chunk, indexed, lost)
            chunk, indexed = None, {}
        if opcode == OP_DATA_END:
            (declared,) = U32.unpack_from(body) if length >= 4 else (0,)
            if declared and declared != crc:
                raise Corrupt(f'the data section CRC does not match (stored {declared:#010x}, computed '
                              f'{crc:#010x})')
        crc = zlib.crc32(body, zlib.crc32(head, crc))
        if opcode == OP_MESSAGE:
            if length < MESSAGE_HEAD:
                raise Corrupt(f'the message record at offset {position} is shorter than its header')
            channel_id, _seq, log_time, publish_time = MESSAGE_FIELDS.unpack_from(body)
            messages.append((log_time, publish_time, channel_id, len(messages), body[MESSAGE_HEAD:]))
        elif opcode in (OP_SCHEMA, OP_CHANNEL):
            definitions.add(opcode, body, 0, length)
        elif opcode == OP_CHUNK:
            found: dict[int, int] = {}
            for log_time, publish_time, channel_id, _, data in split_chunk(chunk_records(body, position), position,
                                                                           definitions, lost):
                messages.append((log_time, publish_time, channel_id, len(messages), data))
                found[channel_id] = found.get(channel_id, 0) + 1
            chunk = (position, found)
        elif opcode == OP_MESSAGE_INDEX and chunk is not None and length >= 6:
            channel_id, entries = struct.unpack_from('<HI', body)
            indexed[channel_id] = indexed.get(channel_id, 0) + entries // 16
        elif opcode == OP_METADATA:
            name, at = read_string(body, 0, length)
            if name == 'rosbag2':
                walked.rosbag2.append(read_string_map(body, at, length))
        elif opcode == OP_FOOTER:
            raise Corrupt(f'a Footer record at offset {position}, inside the data section')
        position += 9 + length
    if chunk is not None:
        _check_declared(*chunk, indexed, lost)


def _check_declared(offset: int, found: dict[int, int], indexed: dict[int, int], lost: Lost) -> None:
    """A chunk's messages per channel against the message indexes after it (none: nothing declared)."""
    if indexed and indexed != found:
        differ = ', '.join(f'channel {cid}: {indexed.get(cid, 0)} indexed, {found.get(cid, 0)} found'
                           for cid in sorted(set(found) | set(indexed)) if found.get(cid, 0) != indexed.get(cid, 0))
        lost(f'chunk at offset {offset}', f'its messages and its message indexes disagree ({differ})')
