"""A key of a file's section or of a type's config, declared once: type, unit, range, default, meaning.

Every section of a scenario or campaign file (spec/sections.py), every
injector type's fault config and options and every assertion type's keys
are declared as `Key`s. The one declaration checks a value and feeds
`bagfault schema`, its `--json` and `--json-schema`, so a value accepted in
one place is accepted in all of them. Two readings of it remain, one per
reference: spec/reader.py reads a section's scalars as the file's other
reader does (yaml-cpp's nodes for the anchor's sections), `coerce` a config
value as the anchor's fault_config_schema.cpp and a runtime parameter change
take it (`scenario/validator.anchor_refusal` adds the anchor's own refusals).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any, Literal, get_args

from bagfault.errors import FieldValueError

KeyType = Literal['string', 'number', 'integer', 'boolean', 'list', 'mapping', 'string_or_list', 'seconds', 'any',
                  'dimension', 'non_empty_string', 'special_float', 'target']
# dimension: a number, or [low, high] that `bagfault explore` draws from; special_float: a number, inf, -inf or
# nan; target: a process of the system under test ('system', {node: NAME}, {command: REGEX})
PUBLIC_TYPES: dict[str, str] = {'number': 'double', 'integer': 'int', 'boolean': 'bool'}  # a config key's type as
# `bagfault schema --json` has always named it (a published format)
KEY_TYPES = frozenset(get_args(KeyType))
PUBLISHED = ('double', 'int', 'bool', 'string', 'non_empty_string', 'special_float', 'list', 'target')  # config types

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
class Key:
    """One key: of a section (read by spec/reader.py) or of a type's config (checked by `coerce`)."""

    name: str
    type: KeyType
    description: str
    unit: str = ''
    default: Any = None
    required: bool = False
    minimum: float | None = None  # inclusive (unless `exclusive`)
    maximum: float | None = None  # inclusive
    choices: tuple[str, ...] = ()  # the only accepted values, empty when any value goes
    section: str = ''  # the section its value is (a mapping, or a list of mappings)
    what: str = ''  # what a valid value is, for messages ('a list of topics')
    exclusive: bool = False  # the minimum itself is refused (a period must be above 0)
    finite: bool = True  # a number must be finite (False: inf and nan pass, as ros2_fault_injection lets them)

    def coerce(self, value: object) -> Any:
        """A config value converted to the key's type, or FieldValueError."""
        coerced = _to_number(value) if self.type == 'number' and not self.finite else _COERCE[self.type](value)
        if isinstance(coerced, (int, float)) and not isinstance(coerced, bool):
            self._check_range(value, coerced)
        if self.choices and coerced not in self.choices:
            raise FieldValueError(f'{_show(value)} is not one of {", ".join(self.choices)}')
        return coerced

    def _check_range(self, value: object, number: float) -> None:
        """FieldValueError when the number (`value` as written) is below the minimum or above the maximum."""
        if self.minimum is not None and number < self.minimum:
            raise FieldValueError(f'{_show(value)} is below the minimum {_show(self.minimum)}')
        if self.maximum is not None and number > self.maximum:
            raise FieldValueError(f'{_show(value)} is above the maximum {_show(self.maximum)}')

    def to_dict(self) -> dict[str, Any]:
        """A config key as `bagfault schema --json` prints it (stable keys, the published type names)."""
        default = self.default
        if isinstance(default, float) and not math.isfinite(default):
            default = str(default)
        return {
            'key': self.name,
            'type': PUBLIC_TYPES.get(self.type, self.type),
            'description': self.description,
            'default': default,
            'min': self.minimum,
            'max': self.maximum,
            'required': self.required,
            'choices': list(self.choices),
            'finite': self.finite,
        }


class ConfigField(Key):
    """A config key in the form plugins have declared them since bagfault's first release (`key`, the published
    type names double/int/bool, `min`, `max`): what it makes is the plain `Key` it describes, equal to it."""

    def __new__(cls, key: str, type: str, description: str, default: Any = None,  # type: ignore[misc]
                min: float | None = None, max: float | None = None,  # the published names
                required: bool = False, choices: tuple[str, ...] = (), finite: bool = True) -> Key:
        kind = {public: own for own, public in PUBLIC_TYPES.items()}.get(type, type)
        if kind not in KEY_TYPES:
            raise ValueError(f'{key}: unknown config key type {type!r} (known: {", ".join(sorted(PUBLISHED))})')
        return Key(key, kind, description, default=default, minimum=min,  # type: ignore[arg-type]
                   maximum=max, required=required, choices=choices, finite=finite)


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
    'number': _to_double,
    'integer': _to_int,
    'boolean': _to_bool,
    'string': _to_string,
    'non_empty_string': _to_non_empty_string,
    'special_float': _to_special_float,
    'list': _to_list,
    'target': _to_target,
}


def double(key: str, description: str, default: float = 0.0, **kw: Any) -> Key:
    """Declare a floating point config key."""
    return Key(key, 'number', description, default=default, **kw)


def integer(key: str, description: str, default: int = 0, **kw: Any) -> Key:
    """Declare an integer config key."""
    return Key(key, 'integer', description, default=default, **kw)


def boolean(key: str, description: str, default: bool = False, **kw: Any) -> Key:
    """Declare a boolean config key."""
    return Key(key, 'boolean', description, default=default, **kw)


def string(key: str, description: str, default: str = '', **kw: Any) -> Key:
    """Declare a free text config key."""
    return Key(key, 'string', description, default=default, **kw)


def probability(key: str, description: str) -> Key:
    """Declare a probability in [0, 1] (nan accepted, as the anchor's range check lets it through; it never wins
    the largest of the active faults, so it drops nothing)."""
    return Key(key, 'number', description, default=0.0, minimum=0.0, maximum=1.0, finite=False)


def stddev(key: str, description: str, **kw: Any) -> Key:
    """Declare a non-negative standard deviation."""
    return Key(key, 'number', description, default=0.0, minimum=0.0, **kw)


DROP_PROBABILITY = probability(
    'drop_probability', 'Probability that an incoming message is dropped (0..1).'
)
MAX_DELAY_MS = 3_600_000  # an hour: delayed messages wait in memory (delay x rate of them)
DELAY_MS = integer(
    'delay_ms', 'Delay added before the message is forwarded, in milliseconds (at most an hour).', 0, minimum=0,
    maximum=MAX_DELAY_MS,
)


def choice(key: str, description: str, choices: tuple[str, ...]) -> Key:
    """Declare a string config key with a fixed set of values; the first is the default."""
    return Key(key, 'string', description, default=choices[0], choices=choices)


# Injector keys every topic injector accepts.
LIVE_OPTIONS = (
    Key('message_type', 'non_empty_string',
        'Type of input_topic (pkg/msg/Name): checked against the bag, lets `validate` check field paths '
        'early, and tells live mode the type before any publisher appears.'),
    choice('reliability', 'QoS reliability of the live subscription and publisher.', ('reliable', 'best_effort')),
    choice('durability', 'QoS durability of the live subscription and publisher.', ('volatile', 'transient_local')),
    choice('on_malformed', 'A message an active fault cannot take (truncated, inconsistent sizes): forward it '
                           'untouched, drop it, or stop with an error; counted in the summary and report.',
           ('forward', 'drop', 'error')),
)
