"""Config field schema shared by scenario validation, live updates and `bagfault schema`.

Each injector type declares its fault config keys as `ConfigField`s. The same
declaration checks a YAML value, a runtime parameter change and feeds any UI,
so a value accepted in one place is accepted in all of them.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any

from bagfault.errors import FieldValueError

FIELD_TYPES = ('double', 'int', 'bool', 'string', 'non_empty_string', 'special_float', 'list', 'target')

SPECIAL_FLOATS = {
    'inf': math.inf,
    '+inf': math.inf,
    '.inf': math.inf,
    '-inf': -math.inf,
    '-.inf': -math.inf,
    'nan': math.nan,
    '.nan': math.nan,
}


@dataclass(frozen=True)
class ConfigField:
    """One config key of an injector type.

    Attributes:
        key: Name of the key inside a fault's `config` map.
        type: One of FIELD_TYPES.
        description: What the key does, with its unit.
        default: Value used when the key is absent.
        min: Smallest accepted value (numbers only), inclusive.
        max: Largest accepted value (numbers only), inclusive.
        required: Every fault of this injector type must set the key.
        choices: The only accepted values (strings), empty when any value goes.
        finite: Numbers must be finite (False: inf and nan are accepted, as ros2_fault_injection accepts them).

    """

    key: str
    type: str
    description: str
    default: Any = None
    min: float | None = None
    max: float | None = None
    required: bool = False
    choices: tuple[str, ...] = ()
    finite: bool = True

    def coerce(self, value: object) -> Any:
        """Return value converted to the field's type, or raise FieldValueError."""
        coerced = _to_number(value) if self.type == 'double' and not self.finite else _COERCE[self.type](value)
        if isinstance(coerced, (int, float)) and not isinstance(coerced, bool):
            if self.min is not None and coerced < self.min:
                raise FieldValueError(f'{_show(value)} is below the minimum {_show(self.min)}')
            if self.max is not None and coerced > self.max:
                raise FieldValueError(f'{_show(value)} is above the maximum {_show(self.max)}')
        if self.choices and coerced not in self.choices:
            raise FieldValueError(f'{_show(value)} is not one of {", ".join(self.choices)}')
        return coerced

    def to_dict(self) -> dict[str, Any]:
        """JSON-friendly form, stable keys."""
        default = self.default
        if isinstance(default, float) and not math.isfinite(default):
            default = str(default)
        return {
            'key': self.key,
            'type': self.type,
            'description': self.description,
            'default': default,
            'min': self.min,
            'max': self.max,
            'required': self.required,
            'choices': list(self.choices),
            'finite': self.finite,
        }


def _show(value: object) -> str:
    if isinstance(value, float) and value.is_integer() and abs(value) < 1e15:
        return f'{value:.1f}'
    return repr(value) if isinstance(value, str) else str(value)


def _to_double(value: object) -> float:
    if isinstance(value, bool):
        raise FieldValueError(f'{_show(value)} is not a number')
    if isinstance(value, (int, float)):
        if not math.isfinite(value):
            raise FieldValueError(f'{_show(value)} is not a finite number')
        return float(value)
    if isinstance(value, str):
        try:
            parsed = float(value)
        except ValueError:
            raise FieldValueError(f'{_show(value)} is not a number') from None
        if not math.isfinite(parsed):
            raise FieldValueError(f'{_show(value)} is not a finite number')
        return parsed
    raise FieldValueError(f'{_show(value)} is not a number')


def _to_number(value: object) -> float:
    """A double that may be inf or nan (the anchor's std::stod reads 'inf' and 'nan')."""
    if isinstance(value, float) and not math.isfinite(value):
        return value
    if isinstance(value, str) and value.strip().lower() in SPECIAL_FLOATS:
        return SPECIAL_FLOATS[value.strip().lower()]
    return _to_double(value)


def _to_int(value: object) -> int:
    if isinstance(value, bool):
        raise FieldValueError(f'{_show(value)} is not an integer')
    if isinstance(value, int):
        return value
    if isinstance(value, float) and value.is_integer():
        return int(value)
    if isinstance(value, str):
        try:
            return int(value.strip())
        except ValueError:
            pass
    raise FieldValueError(f'{_show(value)} is not an integer')


def _to_bool(value: object) -> bool:
    if isinstance(value, bool):
        return value
    if isinstance(value, str) and value.lower() in {'true', 'false'}:
        return value.lower() == 'true'
    raise FieldValueError(f"{_show(value)} is not 'true' or 'false'")


def _to_string(value: object) -> str:
    if isinstance(value, (dict, list)) or value is None:
        raise FieldValueError(f'{_show(value)} is not a string')
    if isinstance(value, bool):
        return 'true' if value else 'false'
    return str(value)


def _to_non_empty_string(value: object) -> str:
    text = _to_string(value)
    if not text:
        raise FieldValueError('must not be empty')
    return text


def _to_special_float(value: object) -> float:
    if isinstance(value, str) and value.strip().lower() in SPECIAL_FLOATS:
        return SPECIAL_FLOATS[value.strip().lower()]
    if isinstance(value, float) and not math.isfinite(value):
        return value
    try:
        return _to_double(value)
    except FieldValueError:
        raise FieldValueError(f'{_show(value)} is not a number, inf, -inf or nan') from None


def _to_list(value: object) -> list[Any]:
    if not isinstance(value, list):
        raise FieldValueError(f'{_show(value)} is not a list')
    return value


def _to_target(value: object) -> str | dict[str, str]:
    """A process of the system under test: 'system' (its whole tree), {node: NAME} (the process hosting that
    node) or {command: REGEX} (processes whose command line matches)."""
    if value == 'system':
        return 'system'
    if not (isinstance(value, dict) and len(value) == 1 and next(iter(value)) in ('node', 'command')):
        raise FieldValueError(f"{_show(value)} is not 'system', {{node: NAME}} or {{command: REGEX}}")
    [(kind, text)] = value.items()
    if not isinstance(text, str) or not text:
        raise FieldValueError(f'{kind}: {_show(text)} is not a non-empty string')
    if kind == 'node':
        return {'node': text if text.startswith('/') else '/' + text}
    try:
        re.compile(text)
    except re.error as exc:
        raise FieldValueError(f'command: {text!r} is not a regular expression ({exc})') from None
    return {'command': text}


_COERCE = {
    'double': _to_double,
    'int': _to_int,
    'bool': _to_bool,
    'string': _to_string,
    'non_empty_string': _to_non_empty_string,
    'special_float': _to_special_float,
    'list': _to_list,
    'target': _to_target,
}


def double(key: str, description: str, default: float = 0.0, **kw: Any) -> ConfigField:
    """Declare a floating point field."""
    return ConfigField(key, 'double', description, default, **kw)


def integer(key: str, description: str, default: int = 0, **kw: Any) -> ConfigField:
    """Declare an integer field."""
    return ConfigField(key, 'int', description, default, **kw)


def boolean(key: str, description: str, default: bool = False, **kw: Any) -> ConfigField:
    """Declare a boolean field."""
    return ConfigField(key, 'bool', description, default, **kw)


def string(key: str, description: str, default: str = '', **kw: Any) -> ConfigField:
    """Declare a free text field."""
    return ConfigField(key, 'string', description, default, **kw)


def probability(key: str, description: str) -> ConfigField:
    """Declare a probability in [0, 1] (nan accepted, as the anchor's range check lets it through; it never wins
    the largest of the active faults, so it drops nothing)."""
    return ConfigField(key, 'double', description, 0.0, min=0.0, max=1.0, finite=False)


def stddev(key: str, description: str, **kw: Any) -> ConfigField:
    """Declare a non-negative standard deviation."""
    return ConfigField(key, 'double', description, 0.0, min=0.0, **kw)


DROP_PROBABILITY = probability(
    'drop_probability', 'Probability that an incoming message is dropped (0..1).'
)
MAX_DELAY_MS = 3_600_000  # an hour: delayed messages wait in memory (delay x rate of them)
DELAY_MS = integer(
    'delay_ms', 'Delay added before the message is forwarded, in milliseconds (at most an hour).', 0, min=0,
    max=MAX_DELAY_MS,
)


def choice(key: str, description: str, choices: tuple[str, ...]) -> ConfigField:
    """Declare a string field with a fixed set of values; the first is the default."""
    return ConfigField(key, 'string', description, choices[0], choices=choices)


# Injector keys every topic injector accepts.
LIVE_OPTIONS = (
    ConfigField('message_type', 'non_empty_string',
                'Type of input_topic (pkg/msg/Name): checked against the bag, lets `validate` check field paths '
                'early, and tells live mode the type before any publisher appears.'),
    choice('reliability', 'QoS reliability of the live subscription and publisher.', ('reliable', 'best_effort')),
    choice('durability', 'QoS durability of the live subscription and publisher.', ('volatile', 'transient_local')),
    choice('on_malformed', 'A message an active fault cannot take (truncated, inconsistent sizes): forward it '
                           'untouched, drop it, or stop with an error; counted in the summary and report.',
           ('forward', 'drop', 'error')),
)
