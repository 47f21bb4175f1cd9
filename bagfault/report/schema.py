"""`bagfault schema`: the config keys of injector types, as text or JSON."""

from __future__ import annotations

import json
from typing import Any

from bagfault.errors import UsageError
from bagfault.injectors.registry import injector_types


def schema_dict(type_name: str | None = None) -> dict[str, Any]:
    """{type: {description, message_types, live_only, options, fields}}."""
    types = injector_types()
    if type_name is not None and type_name not in types:
        raise UsageError(f'unknown injector type {type_name!r} (known: {", ".join(sorted(types))})')
    selected = [type_name] if type_name else sorted(types)
    return {
        name: {
            'description': types[name].description,
            'message_types': list(types[name].message_types),
            'live_only': types[name].live_only,
            'options': [f.to_dict() for f in types[name].options],
            'fields': [f.to_dict() for f in types[name].fields],
        }
        for name in selected
    }


def render_schema(type_name: str | None = None, *, as_json: bool = False) -> str:
    """Human table or JSON of one or all injector types."""
    data: dict[str, Any] = schema_dict(type_name)
    if as_json:
        return json.dumps(data, indent=2, sort_keys=True)
    lines = []
    for name, entry in data.items():
        kinds = ', '.join(entry['message_types']) or 'any message type'
        live = ' (live mode only)' if entry['live_only'] else ''
        lines.append(f'{name}: {entry["description"]}{live}')
        lines.append(f'  messages: {kinds}')
        for title in ('options', 'fields'):
            fields = entry[title]
            if not fields:
                continue
            lines.append('  injector options:' if title == 'options' else '  fault config keys:')
            for field in fields:
                limits = []
                if field['min'] is not None:
                    limits.append(f'min {field["min"]}')
                if field['max'] is not None:
                    limits.append(f'max {field["max"]}')
                if field['choices']:
                    limits.append('one of ' + ' | '.join(field['choices']))
                if field['required']:
                    limits.append('required')
                extra = f' [{", ".join(limits)}]' if limits else ''
                default = '' if field['default'] in (None, '') else f' (default {field["default"]})'
                lines.append(f'    {field["key"]:<36} {field["type"]:<16} {field["description"]}{default}{extra}')
        lines.append('')
    return '\n'.join(lines).rstrip()


def _row(field: dict[str, Any]) -> str:
    limits = []
    if field['min'] is not None:
        limits.append(f'≥ {field["min"]}')
    if field['max'] is not None:
        limits.append(f'≤ {field["max"]}')
    if field['choices']:
        limits.append(' \\| '.join(f'`{c}`' for c in field['choices']))
    default = '' if field['default'] in (None, '') else f'`{field["default"]}`'
    required = 'yes' if field['required'] else ''
    text = field['description'].replace('|', '\\|')
    return f'| `{field["key"]}` | {field["type"]} | {required} | {default} | {", ".join(limits)} | {text} |'


HEADER = '| key | type | required | default | range | meaning |\n|---|---|---|---|---|---|'


def render_markdown() -> str:
    """Every injector type's options and fault config keys, and every assertion type's keys, as markdown tables
    (the docs site's scenario reference is generated from this)."""
    from bagfault.assertions.registry import ASSERTION_TYPES  # noqa: PLC0415

    lines = ['## Injector types', '']
    for name, entry in schema_dict().items():
        kinds = ', '.join(f'`{k}`' for k in entry['message_types']) or 'any message type'
        live = ' Live mode only.' if entry['live_only'] else ''
        lines += [f'### `{name}`', '', f'{entry["description"]}{live} Messages: {kinds}.', '']
        for title, key in (('Injector options', 'options'), ('Fault `config` keys', 'fields')):
            if entry[key]:
                lines += [f'{title}:', '', HEADER, *(_row(f) for f in entry[key]), '']
    lines += ['## Assertion types', '', 'Every assertion has `id` and `type`; the keys of each type:', '']
    for name in sorted(ASSERTION_TYPES):
        cls = ASSERTION_TYPES[name]
        within = ' It takes `within` (seconds).' if cls.takes_within else ''
        lines += [f'### `{name}`', '', f'{cls.description}{within}', '', HEADER,
                  *(_row(f.to_dict()) for f in cls.fields), '']
    return '\n'.join(lines)
