"""Record-aware damage for the fuzz test: each mutation hits one structural field of a bag file (a record's
opcode or length, an offset, a count, an index entry, a truncation at a record boundary), chosen by a seeded
`random.Random`, so a failing variant is reproduced by its seed alone.

MCAP records are walked from the specification (opcode u8, length u64); a mutation inside the summary may
recompute the summary CRC so that the damaged summary is self-consistent, as a buggy writer leaves it. ROS 1
records are walked from the bag format (header length, name=value fields, data length). SQLite files are
damaged by page: the database header's page count, a b-tree page header, a truncation at a page boundary.
"""

from __future__ import annotations

import random
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path

MAGIC = b'\x89MCAP0\r\n'
FOOTER = 29


@dataclass(frozen=True)
class Mutation:
    """What was done, for the failure message."""

    kind: str
    where: int
    detail: str = ''

    def __str__(self) -> str:
        return f'{self.kind} at {self.where}{": " + self.detail if self.detail else ""}'


def _flip(data: bytearray, start: int, size: int, rng: random.Random, low_bits: int | None = None) -> int:
    """Flip one bit of the little-endian field data[start:start+size] (within its low `low_bits` bits)."""
    bits = size * 8 if low_bits is None else min(low_bits, size * 8)
    bit = rng.randrange(bits)
    data[start + bit // 8] ^= 1 << (bit % 8)
    return bit


# -- MCAP -------------------------------------------------------------------------------------------------------
def mcap_records(data: bytes) -> list[tuple[int, int, int]]:
    """(offset, opcode, length) of every top-level record from the header to the footer."""
    out, position = [], 8
    while position + 9 <= len(data) - 8:
        opcode, length = struct.unpack_from('<BQ', data, position)
        out.append((position, opcode, length))
        if opcode == 0x02:
            break
        position += 9 + length
    return out


def _fix_summary_crc(data: bytearray) -> None:
    footer = len(data) - 8 - FOOTER
    summary_start = struct.unpack_from('<Q', data, footer + 9)[0]
    if summary_start and struct.unpack_from('<I', data, footer + 25)[0]:
        struct.pack_into('<I', data, footer + 25, zlib.crc32(data[summary_start:footer + 25]))


def mutate_mcap(original: bytes, rng: random.Random, *, inside_chunks: bool) -> tuple[bytes, Mutation]:
    """One structural mutation; `inside_chunks` also allows flipping a record opcode inside an uncompressed
    chunk (a copied chunk carries that on unless --verify reads it)."""
    data = bytearray(original)
    records = mcap_records(original)
    kinds = ['truncate', 'opcode', 'length', 'chunk', 'chunk_index', 'statistics', 'message_index', 'footer']
    if inside_chunks and any(o == 0x06 and _compression(original, p) == b'' for p, o, _ in records):
        kinds.append('in_chunk')
    kind = rng.choice(kinds)
    by_opcode: dict[int, list[tuple[int, int, int]]] = {}
    for record in records:
        by_opcode.setdefault(record[1], []).append(record)
    if kind == 'truncate':
        position = rng.choice([p for p, _, _ in records[1:]])
        return bytes(data[:position]), Mutation(kind, position)
    if kind == 'opcode':
        position, opcode, _ = rng.choice(records[1:])
        bit = _flip(data, position, 1, rng)
        return bytes(data), Mutation(kind, position, f'opcode {opcode:#x} bit {bit}')
    if kind == 'length':
        position, opcode, _ = rng.choice(records[1:])
        bit = _flip(data, position + 1, 8, rng, low_bits=40)
        return bytes(data), Mutation(kind, position, f'record {opcode:#x} bit {bit}')
    if kind == 'footer':
        footer = len(data) - 8 - FOOTER
        bit = _flip(data, footer + 9, 8, rng, low_bits=40)
        return bytes(data), Mutation(kind, footer, f'summary start bit {bit}')
    if kind == 'chunk' and 0x06 in by_opcode:
        position, _, _ = rng.choice(by_opcode[0x06])
        field, size = rng.choice([(9, 8), (17, 8), (25, 8), (33, 4), (37, 4)])  # start, end, size, crc, name length
        bit = _flip(data, position + field, size, rng, low_bits=40)
        return bytes(data), Mutation(kind, position, f'chunk field at +{field} bit {bit}')
    if kind == 'in_chunk':
        position = rng.choice([p for p, o, _ in records if o == 0x06 and _compression(original, p) == b''])
        name_length = struct.unpack_from('<I', data, position + 9 + 28)[0]
        inner = position + 9 + 32 + name_length + 8
        end = position + 9 + struct.unpack_from('<Q', data, position + 1)[0]
        starts = []
        while inner + 9 <= end:
            starts.append(inner)
            inner += 9 + struct.unpack_from('<Q', data, inner + 1)[0]
        target = rng.choice(starts)
        struct.pack_into('<I', data, position + 9 + 24, 0)  # no CRC, as rosbag2 writes chunks
        if rng.random() < 0.5:
            bit = _flip(data, target, 1, rng)
            detail = f'opcode bit {bit} of the record at {target}'
        else:
            bit = _flip(data, target + 1, 8, rng, low_bits=12)
            detail = f'length bit {bit} of the record at {target}'
        return bytes(data), Mutation(kind, position, detail)
    # summary and message index records: a count, an offset or an index entry
    opcode = {'chunk_index': 0x08, 'statistics': 0x0B, 'message_index': 0x07}.get(kind, 0x08)
    if opcode not in by_opcode:
        opcode = 0x08 if 0x08 in by_opcode else records[-1][1]
    position, _, length = rng.choice(by_opcode.get(opcode, records[1:]))
    if length < 8:
        bit = _flip(data, position, 1, rng)
        return bytes(data), Mutation('opcode', position, f'bit {bit}')
    field = 9 + rng.randrange(0, max(1, length - 8))
    bit = _flip(data, position + field, 8, rng, low_bits=32)
    consistent = rng.random() < 0.5 and opcode != 0x07
    if consistent:
        _fix_summary_crc(data)
    return bytes(data), Mutation(kind, position, f'field at +{field} bit {bit}{" (summary CRC made consistent)" if consistent else ""}')


def _compression(data: bytes, position: int) -> bytes:
    name_length = struct.unpack_from('<I', data, position + 9 + 28)[0]
    return bytes(data[position + 9 + 32:position + 9 + 32 + name_length])


# -- ROS 1 ------------------------------------------------------------------------------------------------------
def ros1_records(data: bytes) -> list[tuple[int, dict[bytes, tuple[int, int]], int]]:
    """(offset, {field name: (value offset, value length)}, data length offset) of every record."""
    out, position = [], 13
    while position + 4 <= len(data):
        header_length = struct.unpack_from('<I', data, position)[0]
        fields, at = {}, position + 4
        while at + 4 <= position + 4 + header_length:
            length = struct.unpack_from('<I', data, at)[0]
            name, _, _ = bytes(data[at + 4:at + 4 + length]).partition(b'=')
            fields[name] = (at + 4 + len(name) + 1, length - len(name) - 1)
            at += 4 + length
        data_at = position + 4 + header_length
        if data_at + 4 > len(data):
            break
        out.append((position, fields, data_at))
        position = data_at + 4 + struct.unpack_from('<I', data, data_at)[0]
    return out


def mutate_ros1(original: bytes, rng: random.Random) -> tuple[bytes, Mutation]:
    """Truncation at a record, a record's header or data length, its op, or a count or offset field."""
    data = bytearray(original)
    records = ros1_records(original)
    kind = rng.choice(['truncate', 'header_length', 'data_length', 'op', 'field', 'field'])
    position, fields, data_at = rng.choice(records)
    if kind == 'truncate':
        return bytes(data[:position]), Mutation(kind, position)
    if kind == 'header_length':
        bit = _flip(data, position, 4, rng, low_bits=20)
        return bytes(data), Mutation(kind, position, f'bit {bit}')
    if kind == 'data_length':
        bit = _flip(data, data_at, 4, rng, low_bits=24)
        return bytes(data), Mutation(kind, position, f'bit {bit}')
    if kind == 'op' and b'op' in fields:
        at, _ = fields[b'op']
        bit = _flip(data, at, 1, rng, low_bits=4)
        return bytes(data), Mutation(kind, position, f'bit {bit}')
    numeric = [name for name in (b'index_pos', b'conn_count', b'chunk_count', b'size', b'count', b'chunk_pos',
                                 b'start_time', b'end_time', b'conn', b'ver') if name in fields]
    if not numeric:
        bit = _flip(data, data_at, 4, rng, low_bits=24)
        return bytes(data), Mutation('data_length', position, f'bit {bit}')
    name = rng.choice(numeric)
    at, size = fields[name]
    bit = _flip(data, at, size, rng, low_bits=min(32, size * 8))
    return bytes(data), Mutation('field', position, f'{name.decode()} bit {bit}')


# -- SQLite (rosbag2 .db3) --------------------------------------------------------------------------------------
def mutate_sqlite(original: bytes, rng: random.Random) -> tuple[bytes, Mutation]:
    """A truncation at a page boundary, the header's page count, or a b-tree page header field."""
    data = bytearray(original)
    page_size = struct.unpack_from('>H', data, 16)[0]
    page_size = 65536 if page_size == 1 else page_size
    pages = len(data) // page_size
    kind = rng.choice(['truncate', 'page_count', 'btree', 'btree'])
    if kind == 'truncate' and pages > 1:
        page = rng.randrange(1, pages)
        return bytes(data[:page * page_size]), Mutation(kind, page * page_size)
    if kind == 'page_count':
        bit = _flip(data, 28, 4, rng, low_bits=8)
        return bytes(data), Mutation(kind, 28, f'bit {bit}')
    page = rng.randrange(pages)
    start = page * page_size + (100 if page == 0 else 0)
    field, size = rng.choice([(0, 1), (3, 2), (5, 2), (8, 4)])  # type, cell count, content start, right child
    bit = _flip(data, start + field, size, rng)
    return bytes(data), Mutation('btree', start, f'page {page} header +{field} bit {bit}')


def mutate_metadata(text: str, rng: random.Random) -> tuple[str, Mutation]:
    """rosbag2 metadata.yaml: the message count, a file listed twice, a file that does not exist."""
    kind = rng.choice(['count', 'twice', 'missing'])
    lines = text.splitlines()
    if kind == 'count':
        at = next(i for i, line in enumerate(lines) if line.strip().startswith('message_count:'))
        key, _, value = lines[at].partition(':')
        lines[at] = f'{key}: {int(value) + rng.choice([-5, -1, 1, 30])}'
        return '\n'.join(lines) + '\n', Mutation(kind, at, lines[at].strip())
    at = next(i for i, line in enumerate(lines) if line.strip().startswith('relative_file_paths:'))
    entry = lines[at + 1]
    if kind == 'twice':
        lines.insert(at + 1, entry)
    else:
        lines.insert(at + 1, entry.replace(entry.strip()[2:], 'gone_0.db3'))
    return '\n'.join(lines) + '\n', Mutation(kind, at)


def storage_of(folder: Path) -> Path:
    """The first storage file of a rosbag2 folder."""
    return sorted(p for p in folder.iterdir() if p.suffix in ('.db3', '.mcap'))[0]
