"""The one reader of YAML sections: a mapping checked against its declaration in spec/sections.py.

Every parser of a scenario, campaign or fault manager section reads its keys
here, so a key's type, unit, range, default and whether it is required are
said once (the declaration) and checked one way, with each problem reported
at its place. Two dialects, declared per section:

- `anchor`: sections ros2_fault_injection reads too. Scalars are read as its
  yaml-cpp reads them (`as<double>()` of the scalar as written, so `'2'` is 2;
  `yes`/`on` are true; a string is the text as written, so `id: on` is `on`),
  a null value is an absent key, and an unknown key is a warning (the anchor
  ignores it).
- `medkit`: ros2_medkit's correlation block, read as its config_parser.cpp
  reads it: yaml-cpp scalars, 32-bit unsigned integers, a boolean key that
  holds a list or mapping reads as its default (`get_bool`).
- `caret`: caret_analyze's architecture file, read as its Util.get_value
  reads it: a required key missing is "required key 'x' not found", a null
  one "'x' value is None"; an optional null is absent; other keys ignored.
- `yaml`: bagfault's own sections. YAML's types as they are; an unknown key
  is an error.

What a parser does beyond one key at a time (a command line split, a
schedule's `on` within its `period`) stays in the parser.
"""

from __future__ import annotations

import copy
import difflib
import math
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

from bagfault.yamlcpp import as_bool, as_double, as_int

if TYPE_CHECKING:
    from collections.abc import Callable, Collection

    from bagfault.spec.sections import Key, Section
    from bagfault.spec.yamlnodes import PathKey

    Report = Callable[[PathKey, str], None]
    RawText = Callable[[PathKey, object], str]


@dataclass
class Read:
    """A section's values: each key read (given and valid, or its default), and which keys were written."""

    values: dict[str, Any] = field(default_factory=dict)
    given: set[str] = field(default_factory=set)
    refused: set[str] = field(default_factory=set)  # given, but not a value of its key

    def __contains__(self, key: object) -> bool:
        return key in self.values

    def get(self, key: str, default: Any = None) -> Any:
        """The value read for `key`, or `default` when it has none."""
        return self.values.get(key, default)


@dataclass
class Reader:
    """Where problems go (`problem` for errors, `warn` for what the anchor accepts) and the scalars as written."""

    problem: Report
    warn: Report | None = None
    raw: RawText | None = None

    def read(self, section: Section, node: object, path: PathKey, *, extra: Collection[str] = (),
             judge_unknown: bool = True, required: Collection[str] = ()) -> Read | None:
        """Check `node` against `section`; None (and a problem) when it is not a mapping. `extra` are keys the
        caller reads itself (an injector type's options); `judge_unknown=False` leaves other keys unjudged;
        `required` are keys required here besides the declared ones (a timer callback's period)."""
        caret = section.reads == 'caret'
        yaml_cpp = section.reads in ('anchor', 'medkit')
        if node is None and yaml_cpp:
            node = {}
        needed = [k.name for k in section.keys if k.required or k.name in required]
        if not isinstance(node, dict):
            self.problem(path, _not_a_mapping(needed, caret=caret))
            return None
        if judge_unknown:
            self._unknown(section, node, path, extra)
        result = Read()
        for key in section.keys:
            self._read_key(section, key, node, path, needed, result)
        return result

    def _read_key(self, section: Section, key: Key, node: dict[Any, Any], path: PathKey, needed: list[str],
                  result: Read) -> None:
        """One declared key of `node` into `result`: read, refused, missing or its default."""
        caret = section.reads == 'caret'
        value = node.get(key.name)
        if caret and key.name in needed and key.name in node and value is None:
            self.problem(path, f'{key.name!r} value is None')
            return
        if key.name not in node or _absent(section, key, value, needed):
            self._missing(key, path, needed, result, caret=caret)
            return
        result.given.add(key.name)
        ok, read = self.value(section, key, value, (*path, key.name))
        if ok:
            result.values[key.name] = read
        else:
            result.refused.add(key.name)

    def _missing(self, key: Key, path: PathKey, needed: list[str], result: Read, *, caret: bool) -> None:
        """A key not given: a problem when it is required, else its default (a copy: a list or mapping of its
        own)."""
        if key.name in needed:
            self.problem(path, f'required key {key.name!r} not found' if caret else
                         f'missing required key {key.name!r}')
        elif key.default is not None:
            result.values[key.name] = copy.copy(key.default)

    def value(self, section: Section, key: Key, value: object, path: PathKey) -> tuple[bool, Any]:
        """One key's value read by its declaration: (True, value), or (False, None) with the problem told."""
        anchor = section.reads in ('anchor', 'medkit')  # yaml-cpp's scalars
        if key.choices:
            return self._choice(key, value, path)
        kind = key.type
        if kind == 'string':
            return self._string(key, value, path, anchor=anchor)
        if kind == 'boolean':
            return self._boolean(section, key, value, path)
        if kind in ('number', 'integer', 'seconds'):
            return self._number(key, value, path, anchor=anchor)
        if kind == 'dimension':
            return self.dimension(key, value, path)
        if kind in ('list', 'mapping') and not isinstance(value, list if kind == 'list' else dict):
            self.problem(path, f'must be {key.what or "a " + kind}')
            return False, None
        return True, value

    def _choice(self, key: Key, value: object, path: PathKey) -> tuple[bool, Any]:
        """One of the key's choices, as given."""
        if value not in key.choices:
            self.problem(path, f'{value!r} is not {_listing(list(key.choices), "or")}')
            return False, None
        return True, value

    def _boolean(self, section: Section, key: Key, value: object, path: PathKey) -> tuple[bool, Any]:
        """A boolean as the section's reader takes one (yaml-cpp's words for the anchor's and medkit's)."""
        anchor = section.reads in ('anchor', 'medkit')
        read = as_bool(value) if anchor else (value if isinstance(value, bool) else None)
        if read is not None:
            return True, read
        if section.reads == 'medkit':
            self.problem(path, f"{value!r} is not a boolean as medkit's yaml-cpp reads one (true/false, yes/no, "
                               'on/off, y/n)')
        else:
            tail = f' ({key.what})' if key.what else \
                ' (nor yes/no, y/n, on/off, as yaml-cpp reads booleans)' if anchor else ''
            self.problem(path, f'{value!r} is not true or false{tail}')
        return False, None

    def _unknown(self, section: Section, node: dict[Any, Any], path: PathKey, extra: Collection[str]) -> None:
        if section.unknown == 'ignore':
            return
        names = {k.name for k in section.keys} | set(extra)
        known = ', '.join(sorted(names))
        noun = f'{section.noun} ' if section.noun else ''
        for name in node:
            if name in names:
                continue
            close = closest(str(name), sorted(names))
            hint = f'did you mean {close!r}? ' if close else ''
            if section.unknown == 'warn':
                (self.warn or self.problem)((*path, name), f'unknown {noun}key {name!r} is ignored ({hint}known: '
                                                           f'{known})')
            else:
                self.problem((*path, name), f'unknown {noun}key {name!r} ({hint}known: {known})')

    def _string(self, key: Key, value: object, path: PathKey, *, anchor: bool) -> tuple[bool, Any]:
        if isinstance(value, (dict, list)) or (not anchor and not isinstance(value, str)):
            self.problem(path, f'must be {key.what}' if key.what else f'{value!r} is not a string')
            return False, None
        text = value if isinstance(value, str) else self.raw_text(path, value)
        if not text:
            self.problem(path, f'must be {key.what}' if key.what else 'must not be empty')
            return False, None
        return True, text

    def _number(self, key: Key, value: object, path: PathKey, *, anchor: bool) -> tuple[bool, Any]:
        """A number by its key: the type first, then finite and within the declared range."""
        integer = key.type == 'integer'
        number = self._parsed(key, value, path, anchor=anchor)
        message = _range_problem(key, value, number)
        if message is not None:
            self.problem(path, message)
            return False, None
        assert number is not None
        return True, int(number) if integer else float(number)

    def _parsed(self, key: Key, value: object, path: PathKey, *, anchor: bool) -> float | int | None:
        """The number a value is, as the section's reader takes one; None when it is none."""
        if isinstance(value, (bool, dict, list)) or value is None:
            return None
        if anchor and isinstance(value, (int, float, str)):
            return self._yaml_cpp_number(key, value, path)
        if isinstance(value, int) or (isinstance(value, float) and key.type != 'integer'):
            return value
        return None

    def _yaml_cpp_number(self, key: Key, value: object, path: PathKey) -> float | int | None:
        """The scalar's text as yaml-cpp's as<double> or as<int> reads it (an unsigned type where the minimum is
        not negative, 32 bits where the maximum fits)."""
        text = self.raw_text(path, value)
        if key.type != 'integer':
            return as_double(text)
        unsigned = key.minimum is not None and key.minimum >= 0
        bits = 32 if key.maximum is not None and key.maximum < 2**32 else 64  # uint32_t, not size_t
        return as_int(text, unsigned=unsigned, bits=bits)

    def dimension(self, key: Key, value: object, path: PathKey) -> tuple[bool, Any]:
        """A number, or a `[low, high]` pair `bagfault explore` draws from (low the weakest; a tuple): each end
        a number of the key's range, low below high."""
        plain = replace(key, type='seconds' if key.unit.startswith('seconds') else 'number')
        if not isinstance(value, list):
            if isinstance(value, (dict, str)) or value is None:
                self.problem(path, f'{value!r} is not a number or a [low, high] range')
                return False, None
            return self._number(plain, value, path, anchor=False)
        return self._range(plain, value, path)

    def _range(self, plain: Key, value: list[Any], path: PathKey) -> tuple[bool, Any]:
        """A `[low, high]` pair of numbers of the key's range, low below high."""
        if len(value) != 2:
            self.problem(path, f'{value!r} is not a [low, high] range: give two numbers')
            return False, None
        ends = [self._number(plain, end, (*path, i), anchor=False) for i, end in enumerate(value)]
        if not all(ok for ok, _ in ends):
            return False, None
        low, high = (end for _, end in ends)
        if low == high:
            self.problem(path, f'[{low:g}, {high:g}] is an empty range: write {low:g} for a fixed value')
            return False, None
        if low > high:
            self.problem(path, f'[{low:g}, {high:g}] is inverted: low, the weakest value, comes first and is the '
                               'smaller')
            return False, None
        return True, (low, high)

    def raw_text(self, path: PathKey, value: object) -> str:
        """The scalar as the file writes it."""
        return self.raw(path, value) if self.raw is not None else str(value)


def _not_a_mapping(needed: list[str], *, caret: bool) -> str:
    """The problem of a section that is no mapping (as caret says it: its first required key not found)."""
    if caret and needed:
        return f'required key {needed[0]!r} not found'
    return 'must be a mapping' + (f' with {_listing(needed, "and")}' if needed else '')


def _absent(section: Section, key: Key, value: object, needed: list[str]) -> bool:
    """A key given a value its reader takes for no value: yaml-cpp's null (and caret's for an optional key), or
    medkit's yaml-cpp reading a mapping or list where a boolean goes (its as<bool> fallback)."""
    if value is None and (section.reads in ('anchor', 'medkit') or
                          (section.reads == 'caret' and key.name not in needed)):
        return True
    return section.reads == 'medkit' and key.type == 'boolean' and isinstance(value, (dict, list))


def _range_problem(key: Key, value: object, number: float | None) -> str | None:
    """What is wrong with a number read for `key`, None when nothing is."""
    if key.type == 'integer':
        return _integer_problem(key, value, number)
    seconds = key.type == 'seconds'
    if number is None:
        return f'{value!r} is not a number of seconds' if seconds else f'{value!r} is not a number'
    high = key.maximum
    if not math.isfinite(number) or (high is not None and number > high):
        if seconds:
            return f'{value} is not a time bagfault can schedule (0 to {high:g} s)'
        return f'{value} is not a finite number' if not math.isfinite(number) else \
            f'{value} is above the maximum {high:g}'
    return _below_problem(key, value, number, ' s' if seconds else '')


def _below_problem(key: Key, value: object, number: float, unit: str) -> str | None:
    """A finite number below the key's minimum (or at it, where the minimum is excluded)."""
    low = key.minimum
    if low is None:
        return None
    if key.exclusive and number <= low:
        return f'{value} must be greater than {low:g}{unit if low else ""}'
    if number < low:
        return f'{value} is negative' if low == 0 else f'{value} is below the minimum {low:g}{unit}'
    return None


def _within(key: Key, number: float) -> bool:
    """Whether `number` lies in the key's range (its minimum excluded where the key says so)."""
    low, high = key.minimum, key.maximum
    if low is not None and (number < low or (key.exclusive and number <= low)):
        return False
    return high is None or number <= high


def _integer_problem(key: Key, value: object, number: float | None) -> str | None:
    """What is wrong with an integer read for `key` (its range named as the message says it), None if nothing."""
    low, high = key.minimum, key.maximum
    if number is not None and _within(key, number):
        return None
    if low == 1 and high is None:
        return f'{value!r} is not a positive integer'
    if low is not None and high is not None:
        return f'{value!r} is not an integer from {_number(low)} to {_number(high)}'
    return f'{value!r} is not an integer' + (f' of at least {_number(low)}' if low is not None else '')


def closest(word: str, candidates: list[str]) -> str | None:
    """The candidate a misspelt key most likely means, if any."""
    match = difflib.get_close_matches(word, candidates, n=1, cutoff=0.6)
    return match[0] if match else None


def key_hint(word: str, keys: list[str]) -> str:
    """What follows an unknown key's message: ' (did you mean ...?)', else ' (keys: ...)'."""
    close = closest(word, keys)
    return f' (did you mean {close!r}?)' if close else f' (keys: {", ".join(keys)})'


def _number(bound: float) -> str:
    """A declared bound as written (2**64 - 1 whole, not rounded through a float)."""
    return str(bound) if isinstance(bound, int) else f'{bound:g}'


def _listing(words: list[str], last: str) -> str:
    """'a', 'a and b', 'a, b and c'."""
    return words[0] if len(words) == 1 else f'{", ".join(words[:-1])} {last} {words[-1]}'
