"""Field paths into decoded messages: `pose.pose.position.x`, `ranges[*]`, `position[2]`,
`transforms[*].transform.translation.z`.

A path is checked against the message definition before a run starts
(`resolve`), so a typo fails early with the closest valid path; reading and
writing then work on the decoded rosbags objects, vectorised for numeric
arrays.
"""

from __future__ import annotations

import difflib
import re
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from bagfault.errors import FieldPathError

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

NUMERIC = {
    'bool', 'byte', 'char', 'int8', 'uint8', 'int16', 'uint16', 'int32', 'uint32', 'int64', 'uint64',
    'float32', 'float64', 'octet',
}
FLOATS = {'float32', 'float64'}
_SEGMENT = re.compile(r'([A-Za-z_][A-Za-z0-9_]*)(?:\[(\*|\d+)\])?')
BASE, NAME, ARRAY, SEQUENCE = 1, 2, 3, 4


@dataclass(frozen=True)
class Segment:
    """One step of a path: a field name and an optional index (None, an int, or '*')."""

    name: str
    index: int | str | None = None


@dataclass(frozen=True)
class FieldPath:
    """A parsed path and, once resolved, the primitive type of its leaf."""

    text: str
    segments: tuple[Segment, ...]
    leaf: str = ''
    many: bool = False

    @classmethod
    def parse(cls, text: str) -> FieldPath:
        """Split 'a.b[2].c' into segments; raise FieldPathError on bad syntax."""
        if not isinstance(text, str) or not text.strip():
            raise FieldPathError('empty field path')
        segments = []
        for part in text.strip().split('.'):
            match = _SEGMENT.fullmatch(part)
            if not match:
                raise FieldPathError(f'{text!r}: {part!r} is not a field name (use name, name[3] or name[*])')
            index = match.group(2)
            segments.append(Segment(match.group(1), None if index is None else '*' if index == '*' else int(index)))
        return cls(text.strip(), tuple(segments))

    def resolve(self, msgtype: str, store: Typestore) -> FieldPath:
        """Check the path against a type; return it with its leaf type known."""
        current: Any = (NAME, msgtype)
        many = False
        for number, segment in enumerate(self.segments):
            if current[0] != NAME:
                raise FieldPathError(self._unknown(msgtype, store, f'{self._prefix(number)} is not a message'))
            typename = current[1]
            fields = dict(store.fielddefs[typename][1])
            if segment.name not in fields:
                close = difflib.get_close_matches(segment.name, list(fields), n=1)
                hint = f" (fields: {', '.join(fields)})" if not close else ''
                raise FieldPathError(self._unknown(msgtype, store, f'{typename} has no field {segment.name!r}{hint}'))
            desc: Any = fields[segment.name]
            kind, args = int(desc[0]), desc[1]
            if segment.index is not None:
                if kind not in (ARRAY, SEQUENCE):
                    raise FieldPathError(f'{self.text!r}: {segment.name} in {typename} is not an array')
                sub, size = args
                if isinstance(segment.index, int) and kind == ARRAY and segment.index >= size:
                    raise FieldPathError(f'{self.text!r}: {segment.name} has {size} elements')
                many = many or segment.index == '*'
                current = (int(sub[0]), sub[1])
            elif kind in (ARRAY, SEQUENCE):
                sub, _ = args
                if int(sub[0]) != BASE or number != len(self.segments) - 1:
                    raise FieldPathError(f'{self.text!r}: {segment.name} is an array; write {segment.name}[*] or '
                                         f'{segment.name}[N]')
                many = True
                current = (BASE, sub[1])
            else:
                current = (kind, args)
        if current[0] != BASE:
            raise FieldPathError(self._unknown(msgtype, store, f'{self.text!r} ends at a message, not a number'))
        leaf = current[1][0] if isinstance(current[1], tuple) else current[1]
        return FieldPath(self.text, self.segments, leaf, many)

    def _prefix(self, count: int) -> str:
        return '.'.join(s.name for s in self.segments[:count]) or self.segments[0].name

    def _unknown(self, msgtype: str, store: Typestore, reason: str) -> str:
        close = difflib.get_close_matches(self.text, leaf_paths(msgtype, store), n=1, cutoff=0.5)
        suggestion = f'; closest valid path: {close[0]}' if close else ''
        return f'{self.text!r} is not a field of {msgtype}: {reason}{suggestion}'

    @property
    def numeric(self) -> bool:
        """True when the leaf is a number (or bool)."""
        return self.leaf in NUMERIC

    def read(self, message: Any) -> np.ndarray:
        """All values the path addresses, as float64 (one for scalar paths)."""
        values: list[Any] = []
        _collect(message, self.segments, values)
        if len(values) == 1 and isinstance(values[0], np.ndarray):
            return values[0].astype(np.float64, copy=False).ravel()
        out = []
        for value in values:
            if isinstance(value, np.ndarray):
                out.extend(value.astype(np.float64).ravel().tolist())
            else:
                out.append(float(value))
        return np.asarray(out, dtype=np.float64)

    def update(self, message: Any, func: Any) -> None:
        """Replace every addressed value v by func(v) (numpy arrays are changed as a whole)."""
        _apply(message, self.segments, func)


def _collect(obj: Any, segments: tuple[Segment, ...], out: list[Any]) -> None:
    segment, rest = segments[0], segments[1:]
    value = getattr(obj, segment.name)
    if segment.index is None:
        items = [value]
    elif segment.index == '*':
        items = [value] if isinstance(value, np.ndarray) and not rest else list(value)
    else:
        items = [value[segment.index]]
    for item in items:
        if rest:
            _collect(item, rest, out)
        else:
            out.append(item)


def _apply(obj: Any, segments: tuple[Segment, ...], func: Any) -> None:
    segment, rest = segments[0], segments[1:]
    value = getattr(obj, segment.name)
    if not rest:
        if segment.index is None or (segment.index == '*' and isinstance(value, np.ndarray)):
            setattr(obj, segment.name, func(value))
        elif segment.index == '*':
            setattr(obj, segment.name, [func(v) for v in value])
        else:
            assert isinstance(segment.index, int)
            value = value.copy() if isinstance(value, np.ndarray) else list(value)
            value[segment.index] = func(value[segment.index])
            setattr(obj, segment.name, value)
        return
    if segment.index is None:
        _apply(value, rest, func)
    elif segment.index == '*':
        for item in value:
            _apply(item, rest, func)
    else:
        _apply(value[segment.index], rest, func)


def leaf_paths(msgtype: str, store: Typestore, depth: int = 6, *, numeric: bool = False) -> list[str]:
    """Every leaf path of a type (arrays as [*]), for suggestions; only numbers with numeric=True."""
    out: list[str] = []

    def walk(typename: str, prefix: str, level: int) -> None:
        if level > depth or typename not in store.fielddefs:
            return
        for name, desc in store.fielddefs[typename][1]:
            if name == 'structure_needs_at_least_one_member':  # rosbags' stand-in for empty messages
                continue
            kind, args = int(desc[0]), cast('Any', desc[1])
            path = f'{prefix}{name}'
            if kind == BASE:
                if not numeric or args[0] in NUMERIC:
                    out.append(path)
            elif kind == NAME:
                walk(args, path + '.', level + 1)
            else:
                sub, _ = args
                if int(sub[0]) == BASE:
                    if not numeric or sub[1][0] in NUMERIC:
                        out.append(f'{path}[*]')
                else:
                    walk(sub[1], f'{path}[*].', level + 1)

    walk(msgtype, '', 0)
    return out
