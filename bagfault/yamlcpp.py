"""Scalars as yaml-cpp converts them, for the reference formats its users read with `as<T>()`.

PyYAML (YAML 1.1) and yaml-cpp disagree on scalars: a quoted `'false'` is a
string to PyYAML, whose truthiness is True, but yaml-cpp's `as<bool>()`
reads it as false; `y`/`n` are booleans to yaml-cpp only. medkit's fault
manager and ros2_fault_injection read their files with yaml-cpp, so their
keys are converted here, by yaml-cpp's table (yaml-cpp src/convert.cpp,
`convert<bool>::decode`: y/n, yes/no, true/false, on/off, each all lower,
all upper or capitalised; anything else is a bad conversion), and numbers
by its stream conversion (`as_double`, `as_int`), from the scalar as written.
"""

from __future__ import annotations

import math
import re

BOOLEANS = (('y', 'n'), ('yes', 'no'), ('true', 'false'), ('on', 'off'))


def _flexible_case(text: str) -> bool:
    """yaml-cpp's IsFlexibleCase: 'true', 'TRUE' or 'True', never 'tRUE'."""
    if not text:
        return True
    rest = text[1:]
    return text == text.lower() or text == text.upper() or (text[0].isupper() and rest == rest.lower())


def as_bool(value: object) -> bool | None:
    """What `node.as<bool>()` gives for a value PyYAML loaded; None where yaml-cpp throws (bad conversion)."""
    if isinstance(value, bool):
        return value
    if not isinstance(value, str) or not _flexible_case(value):
        return None  # a number, a list, a map, null: not a bool to yaml-cpp
    lowered = value.lower()
    for true_name, false_name in BOOLEANS:
        if lowered == true_name:
            return True
        if lowered == false_name:
            return False
    return None


# -- numbers: yaml-cpp's convert<T>::decode (a std::stringstream with the base left open, no skipping of
# leading blanks, trailing blanks allowed) and its special values
_FLOAT = re.compile(r'[-+]?([0-9]+\.?[0-9]*|\.[0-9]+)([eE][-+]?[0-9]+)?\s*', re.ASCII)  # digits 0-9 only: not '١'
_INT = re.compile(r'([-+]?)(0[xX][0-9a-fA-F]+|0[0-7]*|[1-9][0-9]*)\s*', re.ASCII)
_INFINITY = ('.inf', '.Inf', '.INF', '+.inf', '+.Inf', '+.INF')
_NEGATIVE_INFINITY = ('-.inf', '-.Inf', '-.INF')
_NAN = ('.nan', '.NaN', '.NAN')
DOUBLE_MAX = 1.7976931348623157e308


def as_double(text: str) -> float | None:
    """What `node.as<double>()` gives for a scalar written as `text` (quoted or not: yaml-cpp does not care);
    None where it throws. `1e3` and `.5` are numbers; `inf`, `0x10`, `1_000`, ` 5` and `1e400` are not."""
    if _FLOAT.fullmatch(text):
        value = float(text)
        return value if abs(value) <= DOUBLE_MAX else None  # strtod's overflow is a failed extraction
    if text in _INFINITY:
        return math.inf
    if text in _NEGATIVE_INFINITY:
        return -math.inf
    if text in _NAN:
        return math.nan
    return None


def as_int(text: str, *, unsigned: bool = False, bits: int = 64) -> int | None:
    """What `node.as<long long>()` (or an unsigned type with `unsigned`) gives; None where it throws. The base
    follows the prefix (`0x10` is 16, `010` is 8); `1.0`, `1e3` and `08` are not integers."""
    match = _INT.fullmatch(text)
    if match is None:
        return None
    sign, digits = match.groups()
    if unsigned and sign == '-':
        return None
    value = int(digits, 16) if digits[:2].lower() == '0x' else int(digits, 8) if digits.startswith('0') \
        else int(digits)
    value = -value if sign == '-' else value
    low, high = (0, 2**bits - 1) if unsigned else (-(2**(bits - 1)), 2**(bits - 1) - 1)
    return value if low <= value <= high else None
