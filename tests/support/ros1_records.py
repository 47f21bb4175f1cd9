"""ROS 1 bags (format 2.0) as edited lists of records, for the differential tests: written by hand from the
bag format (header length u32, name=value fields, data length u32, data), independent of rosbags and bagfault.

A bag is the version line, a bag header padded to 4096 bytes, a data section of items (chunks, each followed
by its index data records, and any top-level record an edit put there), then the index section: connection
records and one chunk info per chunk. Index data, chunk infos and the header's counts are derived when the
bag is written, unless an edit left them stale (a buggy writer's lie): `honest` derives them, `stale` keeps
those of the bag before the edits (at their new places), `none` writes index_pos 0 and no index section (a
bag whose recording was cut, before `rosbag reindex`).
"""

from __future__ import annotations

import bz2
import struct
from dataclasses import dataclass, field, replace
from typing import Literal

VERSION = b'#ROSBAG V2.0\n'
MESSAGE, BAG_HEADER, INDEX_DATA, CHUNK, CHUNK_INFO, CONNECTION = 0x02, 0x03, 0x04, 0x05, 0x06, 0x07
UNKNOWN = 0x99
STRING_MD5 = '992ce8a1687cec8c8bd883ec73ca41d1'  # std_msgs/String

IndexRule = Literal['honest', 'stale', 'none']


def fields(**values: bytes) -> bytes:
    return b''.join(struct.pack('<I', len(k) + 1 + len(v)) + k.encode() + b'=' + v for k, v in values.items())


def record(header: bytes, data: bytes) -> bytes:
    return struct.pack('<I', len(header)) + header + struct.pack('<I', len(data)) + data


def stamp(time_ns: int) -> bytes:
    return struct.pack('<II', time_ns // 10**9, time_ns % 10**9)


@dataclass(frozen=True)
class Rec:
    """One record: its header fields (op first) and its data."""

    op: int
    header: bytes  # the fields other than op
    data: bytes

    def encode(self) -> bytes:
        return record(fields(op=bytes([self.op])) + self.header, self.data)

    def message(self) -> tuple[int, int] | None:
        """(conn, time) of a message data record."""
        if self.op != MESSAGE:
            return None
        values = parse_fields(self.header)
        sec, nsec = struct.unpack('<II', values[b'time'])
        return struct.unpack('<I', values[b'conn'])[0], sec * 10**9 + nsec


def parse_fields(header: bytes) -> dict[bytes, bytes]:
    values = {}
    at = 0
    while at < len(header):
        (length,) = struct.unpack_from('<I', header, at)
        name, _, value = header[at + 4:at + 4 + length].partition(b'=')
        values[name] = value
        at += 4 + length
    return values


def message_record(conn: int, time_ns: int, text: str) -> Rec:
    raw = text.encode()
    return Rec(MESSAGE, fields(conn=struct.pack('<I', conn), time=stamp(time_ns)), struct.pack('<I', len(raw)) + raw)


def connection_record(conn: int, topic: str) -> Rec:
    data = fields(topic=topic.encode(), type=b'std_msgs/String', md5sum=STRING_MD5.encode(),
                  message_definition=b'string data\n')
    return Rec(CONNECTION, fields(conn=struct.pack('<I', conn), topic=topic.encode()), data)


@dataclass(frozen=True)
class Chunk:
    """A chunk: its records, compression, and (when an edit left them stale) the content its index describes."""

    records: tuple[Rec, ...]
    compression: Literal['none', 'bz2'] = 'none'
    stale_index_of: tuple[Rec, ...] | None = None


Item = Rec | Chunk


@dataclass
class Bag:
    """A bag to write: the data section's items, the connections, the rule its index follows."""

    items: list[Item]
    connections: tuple[Rec, ...] = field(default=())
    index: IndexRule = 'honest'
    stale_index: bytes = b''  # the index section of the unedited bag
    stale_counts: tuple[int, int] = (0, 0)  # its header's conn_count, chunk_count
    chunk_count_lie: int = 0  # added to the header's chunk_count
    tail: bytes = b''
    cut: int | None = None

    def write(self) -> bytes:
        body = bytearray()
        start = len(VERSION) + 4096
        infos: list[bytes] = []
        for item in self.items:
            if isinstance(item, Rec):
                body += item.encode()
                continue
            position = start + len(body)
            inner = b''.join(r.encode() for r in item.records)
            payload = bz2.compress(inner) if item.compression == 'bz2' else inner
            body += record(fields(op=bytes([CHUNK]), compression=item.compression.encode(),
                                  size=struct.pack('<I', len(inner))), payload)
            described = item.records if item.stale_index_of is None else item.stale_index_of
            entries: dict[int, list[bytes]] = {}
            offset = 0
            times: list[int] = []
            for rec in described:
                found = rec.message()
                if found is not None:
                    entries.setdefault(found[0], []).append(stamp(found[1]) + struct.pack('<I', offset))
                    times.append(found[1])
                offset += len(rec.encode())
            for conn, listed in sorted(entries.items()):
                body += record(fields(op=bytes([INDEX_DATA]), ver=struct.pack('<I', 1), conn=struct.pack('<I', conn),
                                      count=struct.pack('<I', len(listed))), b''.join(listed))
            counts = b''.join(struct.pack('<II', conn, len(listed)) for conn, listed in sorted(entries.items()))
            infos.append(record(fields(op=bytes([CHUNK_INFO]), ver=struct.pack('<I', 1),
                                       chunk_pos=struct.pack('<Q', position), start_time=stamp(min(times, default=0)),
                                       end_time=stamp(max(times, default=0)), count=struct.pack('<I', len(entries))),
                                counts))
        index_pos = start + len(body)
        if self.index == 'honest':
            index = b''.join(c.encode() for c in self.connections) + b''.join(infos)
            conn_count, chunk_count = len(self.connections), len(infos)
        elif self.index == 'stale':
            index, (conn_count, chunk_count) = self.stale_index, self.stale_counts
        else:
            index, index_pos, conn_count, chunk_count = b'', 0, 0, 0
        header = fields(op=bytes([BAG_HEADER]), index_pos=struct.pack('<Q', index_pos),
                        conn_count=struct.pack('<I', conn_count),
                        chunk_count=struct.pack('<I', max(0, chunk_count + self.chunk_count_lie)))
        padding = 4096 - 8 - len(header)
        out = VERSION + record(header, b' ' * padding) + bytes(body) + index + self.tail
        return out if self.cut is None else out[:self.cut]


def index_section(bag: bytes) -> tuple[bytes, tuple[int, int]]:
    """The index section of a written bag and its header's (conn_count, chunk_count)."""
    (header_length,) = struct.unpack_from('<I', bag, len(VERSION))
    values = parse_fields(bag[len(VERSION) + 4:len(VERSION) + 4 + header_length])
    (index_pos,) = struct.unpack('<Q', values[b'index_pos'])
    return bag[index_pos:], (struct.unpack('<I', values[b'conn_count'])[0],
                             struct.unpack('<I', values[b'chunk_count'])[0])


def source(*, topics: int = 2, per_chunk: int = 5, chunks: int = 3,
           compression: Literal['none', 'bz2'] = 'none') -> Bag:
    """A small bag: `topics` std_msgs/String connections (each defined in the first chunk that uses it, as
    rosbag writes them), `chunks` chunks of `per_chunk` messages 10 ms apart, connections in turn."""
    connections = tuple(connection_record(conn, f'/topic{conn}') for conn in range(topics))
    items: list[Item] = []
    count = 0
    defined: set[int] = set()
    for _ in range(chunks):
        inner: list[Rec] = []
        for _ in range(per_chunk):
            conn = count % topics
            if conn not in defined:
                defined.add(conn)
                inner.append(connections[conn])
            inner.append(message_record(conn, 10**9 + count * 10**7, f'm{count}'))
            count += 1
        items.append(Chunk(tuple(inner), compression))
    built = Bag(items, connections)
    built.stale_index, built.stale_counts = index_section(built.write())
    return built


def edited_chunk(chunk: Chunk, records: list[Rec], *, stale_index: bool) -> Chunk:
    """The chunk with new content; its index describes the old content when `stale_index`."""
    old = chunk.records if chunk.stale_index_of is None else chunk.stale_index_of
    return replace(chunk, records=tuple(records), stale_index_of=old if stale_index else chunk.stale_index_of)
