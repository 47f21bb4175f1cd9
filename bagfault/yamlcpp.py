"""Scalars as yaml-cpp converts them, for the reference formats its users read with `as<T>()`.

PyYAML (YAML 1.1) and yaml-cpp disagree on scalars: a quoted `'false'` is a
string to PyYAML, whose truthiness is True, but yaml-cpp's `as<bool>()`
reads it as false; `y`/`n` are booleans to yaml-cpp only. medkit's fault
manager and ros2_fault_injection read their files with yaml-cpp, so their
keys are converted here, by yaml-cpp's table (yaml-cpp src/convert.cpp,
`convert<bool>::decode`: y/n, yes/no, true/false, on/off, each all lower,
all upper or capitalised; anything else is a bad conversion).
"""

from __future__ import annotations

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
