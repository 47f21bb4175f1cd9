"""Byte offsets of scalar fields inside CDR messages, for patching without decoding.

A message's layout depends only on the lengths of the strings and sequences
that come before a field. `FieldLayout.of` walks one message with the type
definition and notes where the wanted scalars are and where (and how long)
every variable-length field before them was; `FieldLayout.rows_matching`
then checks, vectorised, which other messages of a batch share that layout,
so their fields can be read and written as numpy columns.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Any

import numpy as np

SIZES = {'bool': 1, 'byte': 1, 'char': 1, 'octet': 1, 'int8': 1, 'uint8': 1, 'int16': 2, 'uint16': 2,
         'int32': 4, 'uint32': 4, 'float32': 4, 'int64': 8, 'uint64': 8, 'float64': 8}
FORMATS = {'float32': 'f4', 'float64': 'f8', 'int8': 'i1', 'uint8': 'u1', 'int16': 'i2', 'uint16': 'u2',
           'int32': 'i4', 'uint32': 'u4', 'int64': 'i8', 'uint64': 'u8'}
BASE, NAME, ARRAY, SEQUENCE = 1, 2, 3, 4


class LayoutError(ValueError):
    """The message does not hold the fields as plain scalars."""


def _align(position: int, size: int) -> int:
    return position + (-position % size)


@dataclass(frozen=True)
class FieldLayout:
    """Where scalar fields sit in messages of one layout (offsets from the start of the bytes)."""

    length: int
    little: bool
    fields: dict[str, tuple[int, str]]
    checks: tuple[tuple[int, int], ...]

    @classmethod
    def of(cls, data: bytes | memoryview, msgtype: str, store: Any, paths: list[str]) -> FieldLayout:
        """Layout of `paths` (dotted paths to scalar numbers) in one serialized message."""
        little = bool(data[1])
        walker = _Walker(memoryview(data)[4:], little, store, set(paths))
        walker.walk(msgtype, '')
        missing = set(paths) - set(walker.found)
        if missing:
            raise LayoutError(f'fields not found as plain scalars: {", ".join(sorted(missing))}')
        fields = {path: (4 + offset, kind) for path, (offset, kind) in walker.found.items()}
        return cls(len(data), little, fields, tuple((4 + p, v) for p, v in walker.checks))

    def rows_matching(self, rows: np.ndarray) -> np.ndarray:
        """Which rows (n x length bytes) share this layout."""
        ok = rows[:, 1] == (1 if self.little else 0)
        for position, value in self.checks:
            found = rows[:, position:position + 4].copy().view('<u4' if self.little else '>u4').ravel()
            ok &= found == value
        return ok  # type: ignore[no-any-return]

    def column(self, rows: np.ndarray, path: str) -> np.ndarray:
        """A field of every row as float64."""
        offset, kind = self.fields[path]
        dtype = np.dtype(('<' if self.little else '>') + FORMATS[kind])
        return rows[:, offset:offset + dtype.itemsize].copy().view(dtype).ravel().astype(np.float64)

    def store(self, rows: np.ndarray, path: str, values: np.ndarray) -> None:
        """Write a column back (values already in the field's range)."""
        offset, kind = self.fields[path]
        dtype = np.dtype(('<' if self.little else '>') + FORMATS[kind])
        rows[:, offset:offset + dtype.itemsize] = values.astype(dtype).view(np.uint8).reshape(len(values),
                                                                                            dtype.itemsize)


class _Walker:
    """Follows the CDR encoding of a message far enough to find the wanted fields."""

    def __init__(self, body: memoryview, little: bool, store: Any, wanted: set[str]) -> None:
        self.body = body
        self.order = '<' if little else '>'
        self.store = store
        self.wanted = wanted
        self.found: dict[str, tuple[int, str]] = {}
        self.checks: list[tuple[int, int]] = []
        self.position = 0

    def _count(self) -> int:
        self.position = _align(self.position, 4)
        value: int = struct.unpack_from(self.order + 'I', self.body, self.position)[0]
        self.checks.append((self.position, value))
        self.position += 4
        return value

    def _skip_base(self, kind: str, count: int = 1) -> None:
        if kind == 'string':
            for _ in range(count):
                length = self._count()  # moves position past the length field first
                self.position += length
            return
        size = SIZES.get(kind)
        if size is None:
            raise LayoutError(f'unsupported type {kind}')
        if count:
            self.position = _align(self.position, size) + size * count

    def walk(self, typename: str, prefix: str) -> None:
        for name, (kind, args) in self.store.fielddefs[typename][1]:
            if self.wanted <= set(self.found):
                return
            path = f'{prefix}{name}'
            kind = int(kind)
            if kind == BASE:
                base = args[0]
                if path in self.wanted:
                    if base not in FORMATS:
                        raise LayoutError(f'{path} is a {base}, not a number')
                    self.position = _align(self.position, SIZES[base])
                    self.found[path] = (self.position, base)
                    self.position += SIZES[base]
                else:
                    self._skip_base(base)
            elif kind == NAME:
                self.walk(args, path + '.')
            else:
                (sub_kind, sub_args), size = args
                count = size if kind == ARRAY else self._count()
                if int(sub_kind) == BASE:
                    self._skip_base(sub_args[0], count)
                else:
                    for _ in range(count):
                        self.walk(sub_args, path + '[].')
