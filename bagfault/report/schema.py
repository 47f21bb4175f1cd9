"""`bagfault schema`: the config keys of injector types, as text or JSON."""

from __future__ import annotations

import json
from typing import TYPE_CHECKING, Any

from bagfault.errors import UsageError
from bagfault.injectors.registry import injector_types

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

    from bagfault.schema import Key


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
            'needs': getattr(types[name], 'needs', ''),  # an injector acting on the running system: what it needs
            'options': [f.to_dict() for f in types[name].options],
            'fields': [f.to_dict() for f in types[name].fields],
        }
        for name in selected
    }


def _bound(value: float) -> str:
    """A bound as written: 2**64 - 1 whole, 1e7 short."""
    return str(value) if isinstance(value, int) else f'{value:g}'


def _limits(minimum: float | None, maximum: float | None, choices: Sequence[str], *, required: bool = False,
            markdown: bool = False, exclusive: bool = False) -> list[str]:
    """A key's range, choices and whether it is required, as the text tables or the markdown tables say it
    (`exclusive`: the minimum itself is refused)."""
    out = [] if minimum is None else [_lower(minimum, markdown=markdown, exclusive=exclusive)]
    if maximum is not None:
        out.append(f'{"≤" if markdown else "max"} {_bound(maximum)}')
    if choices:
        out.append(' \\| '.join(f'`{c}`' for c in choices) if markdown else 'one of ' + ' | '.join(choices))
    if required:
        out.append('required')
    return out


def _lower(minimum: float, *, markdown: bool, exclusive: bool) -> str:
    """A key's lower bound as the text or markdown tables say it."""
    if exclusive:
        return f'> {_bound(minimum)}' if markdown else f'above {_bound(minimum)}'
    return f'{"≥" if markdown else "min"} {_bound(minimum)}'


def render_schema(type_name: str | None = None, *, as_json: bool = False) -> str:
    """Human table or JSON of one or all injector types."""
    data: dict[str, Any] = schema_dict(type_name)
    if as_json:
        return json.dumps(data, indent=2, sort_keys=True)
    lines = []
    for name, entry in data.items():
        lines += _type_lines(name, entry)
    return '\n'.join(lines).rstrip()


def _type_lines(name: str, entry: dict[str, Any]) -> list[str]:
    """One injector type as text: what it acts on, its options and its fault config keys."""
    kinds = ', '.join(entry['message_types']) or 'any message type'
    live = ' (live mode only)' if entry['live_only'] and not entry['needs'] else ''
    lines = [f'{name}: {entry["description"]}{live}',
             f'  needs: {entry["needs"]}' if entry['needs'] else f'  messages: {kinds}']
    for title in ('options', 'fields'):
        if entry[title]:
            lines.append('  injector options:' if title == 'options' else '  fault config keys:')
            lines += [_field_line(field) for field in entry[title]]
    return [*lines, '']


def _field_line(field: dict[str, Any]) -> str:
    """An option or config key as a line of text: name, type, meaning, default and limits."""
    limits = _limits(field['min'], field['max'], field['choices'], required=field['required'])
    extra = f' [{", ".join(limits)}]' if limits else ''
    default = '' if field['default'] in (None, '') else f' (default {field["default"]})'
    return f'    {field["key"]:<36} {field["type"]:<16} {field["description"]}{default}{extra}'


def _row(field: dict[str, Any]) -> str:
    limits = _limits(field['min'], field['max'], field['choices'], markdown=True)
    default = '' if field['default'] in (None, '') else f'`{field["default"]}`'
    required = 'yes' if field['required'] else ''
    text = field['description'].replace('|', '\\|')
    return f'| `{field["key"]}` | {field["type"]} | {required} | {default} | {", ".join(limits)} | {text} |'


HEADER = '| key | type | required | default | range | meaning |\n|---|---|---|---|---|---|'


def render_markdown() -> str:
    """Every injector type's options and fault config keys, and every assertion type's keys, as markdown tables
    (the docs site's scenario reference is generated from this)."""
    from bagfault.assertions.registry import ASSERTION_TYPES  # noqa: PLC0415
    from bagfault.spec.sections import ARCHITECTURE_SECTIONS, CAMPAIGN_SECTIONS, SCENARIO_SECTIONS  # noqa: PLC0415

    lines = ['## Sections', '']
    for section in (*SCENARIO_SECTIONS, *CAMPAIGN_SECTIONS):
        lines += _section_rows(section)
    lines += ['## CARET architecture files', '', 'The keys `path_latency` and `bagfault latency` read, as '
              "caret_analyze's architecture reader requires them (other keys are ignored).", '']
    for section in ARCHITECTURE_SECTIONS:
        lines += _section_rows(section)
    lines += ['## Injector types', '']
    for name, entry in schema_dict().items():
        lines += _type_markdown(name, entry)
    lines += ['## Assertion types', '', 'Every assertion has `id` and `type`; the keys of each type:', '']
    for name in sorted(ASSERTION_TYPES):
        cls = ASSERTION_TYPES[name]
        within = ' It takes `within` (seconds).' if cls.takes_within else ''
        lines += [f'### `{name}`', '', f'{cls.description}{within}', '', HEADER,
                  *(_row(f.to_dict()) for f in cls.fields), '']
    return '\n'.join(lines)


def _type_markdown(name: str, entry: dict[str, Any]) -> list[str]:
    """One injector type as markdown: what it acts on, and tables of its options and fault config keys."""
    kinds = ', '.join(f'`{k}`' for k in entry['message_types']) or 'any message type'
    live = ' Live mode only.' if entry['live_only'] and not entry['needs'] else ''
    acts = f'Needs {entry["needs"]}.' if entry['needs'] else f'Messages: {kinds}.'
    lines = [f'### `{name}`', '', f'{entry["description"]}{live} {acts}', '']
    for title, part in (('Injector options', 'options'), ('Fault `config` keys', 'fields')):
        if entry[part]:
            lines += [f'{title}:', '', HEADER, *(_row(f) for f in entry[part]), '']
    return lines


def _section_rows(section: Any) -> list[str]:
    """One section as a markdown table."""
    lines = [f'### `{section.where}`', '', section.description, '', HEADER]
    for key in section.keys:
        limits = _limits(key.minimum, key.maximum, key.choices, markdown=True, exclusive=key.exclusive)
        unit = f' ({key.unit})' if key.unit else ''
        default = '' if key.default is None else f'`{key.default}`'
        lines.append(f'| `{key.name}` | {key.type} | {"yes" if key.required else ""} | {default} | '
                     f'{", ".join(limits)} | {key.description.replace("|", "/")}{unit} |')
    return [*lines, '']


# -- every section, and a JSON Schema of scenario and campaign files ---------------------------------------------
KEY_JSON: dict[str, dict[str, Any]] = {  # by Key.type
    'string': {'type': 'string'}, 'number': {'type': 'number'}, 'integer': {'type': 'integer'},
    'boolean': {'type': 'boolean'}, 'seconds': {'type': 'number'}, 'list': {'type': 'array'},
    'mapping': {'type': 'object'}, 'any': {},
    'string_or_list': {'anyOf': [{'type': 'string'}, {'type': 'array', 'items': {'type': 'string'}}]},
    'dimension': {'anyOf': [{'type': 'number'}, {'type': 'array', 'items': {'type': 'number'}, 'minItems': 2,
                                                 'maxItems': 2}]},
    'non_empty_string': {'type': 'string', 'minLength': 1},
    'special_float': {'anyOf': [{'type': 'number'}, {'enum': ['inf', '+inf', '-inf', '.inf', '-.inf', 'nan', '.nan']}]},
    'target': {'anyOf': [{'const': 'system'},
                         {'type': 'object', 'properties': {'node': {'type': 'string', 'minLength': 1}},
                          'required': ['node'], 'additionalProperties': False},
                         {'type': 'object', 'properties': {'command': {'type': 'string', 'minLength': 1}},
                          'required': ['command'], 'additionalProperties': False}]},
}
OPEN_SECTIONS = ('injector',)  # its keys depend on its type


def _field_json(field: Key) -> dict[str, Any]:
    """A type's config key or option (no unit, no exclusive bound; an empty default left out, inf as text)."""
    out = {**KEY_JSON[field.type], 'description': field.description}
    if field.minimum is not None:
        out['minimum'] = field.minimum
    if field.maximum is not None:
        out['maximum'] = field.maximum
    if field.choices:
        out['enum'] = list(field.choices)
    default = field.to_dict()['default']
    if default not in (None, ''):
        out['default'] = default
    return out


def _key_json(key: Any, ref: Callable[[str], dict[str, Any]]) -> dict[str, Any]:
    out = dict(KEY_JSON[key.type])
    if key.section:
        item = ref(key.section)
        out = {'type': 'array', 'items': item} if key.type == 'list' else item
    text = key.description + (f' ({key.unit})' if key.unit else '')
    out['description'] = text
    bounds = {}
    if key.minimum is not None:
        bounds['exclusiveMinimum' if key.exclusive else 'minimum'] = key.minimum
    if key.maximum is not None:
        bounds['maximum'] = key.maximum
    if key.type == 'dimension':  # the number, or each end of [low, high]
        out['anyOf'] = [{'type': 'number', **bounds}, {**out['anyOf'][1], 'items': {'type': 'number', **bounds}}]
    else:
        out.update(bounds)
    if key.choices:
        out['enum'] = list(key.choices)
    if key.default is not None:
        out['default'] = key.default
    return out


def _section_json(section: Any, ref: Callable[[str], dict[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {'type': 'object', 'description': section.description,
                           'properties': {k.name: _key_json(k, ref) for k in section.keys}}
    required = [k.name for k in section.keys if k.required]
    if required:
        out['required'] = required
    if section.name not in OPEN_SECTIONS and section.unknown != 'ignore':
        out['additionalProperties'] = False
    return out


def json_schema(kind: str) -> dict[str, Any]:
    """A JSON Schema (2020-12) of a scenario or a campaign file, for editors (the YAML language server): every
    section's keys, each injector type's options, each assertion type's keys, every fault config key."""
    from bagfault.spec.sections import CAMPAIGN_SECTIONS, SCENARIO_SECTIONS  # noqa: PLC0415

    if kind not in ('scenario', 'campaign'):
        raise UsageError(f'--json-schema {kind}: give scenario or campaign')
    sections = SCENARIO_SECTIONS if kind == 'scenario' else CAMPAIGN_SECTIONS

    def ref(name: str) -> dict[str, Any]:
        return {'$ref': f'#/$defs/{name}'}

    defs = {s.name: _section_json(s, ref) for s in sections}
    if kind == 'scenario':
        _typed_injectors(defs)
        _typed_assertions(defs['assertion'])
    top = defs.pop(sections[0].name)
    return {'$schema': 'https://json-schema.org/draft/2020-12/schema', 'title': f'bagfault {kind} file',
            **top, '$defs': defs}


def _typed_injectors(defs: dict[str, Any]) -> None:
    """The injector section's types and each type's options; the fault's config keys of every type."""
    types = sorted(injector_types().items())
    injector = defs['injector']
    injector['properties']['type'] = {'anyOf': [{'enum': [name for name, _ in types]}, {'type': 'string'}],
                                      'description': injector['properties']['type']['description']}
    injector['allOf'] = [{'if': {'properties': {'type': {'const': name}}, 'required': ['type']},
                          'then': {'properties': {f.name: _field_json(f) for f in cls.options}}}
                         for name, cls in types if cls.options]
    config: dict[str, Any] = {}
    for _, injector_type in types:
        for f in injector_type.fields:
            config.setdefault(f.name, _field_json(f))
    defs['fault']['properties']['config'] = {'type': 'object', 'properties': config,
                                             'description': "The fault config keys of its injector's type."}


def _typed_assertions(assertion: dict[str, Any]) -> None:
    """The assertion section's types, and each type's keys (and `within` where it takes one)."""
    from bagfault.assertions.registry import ASSERTION_TYPES  # noqa: PLC0415

    assertion['properties']['type'] = {'anyOf': [{'enum': sorted(ASSERTION_TYPES)}, {'type': 'string'}],
                                       'description': assertion['properties']['type']['description']}
    rules = []
    for name, cls in sorted(ASSERTION_TYPES.items()):
        fields = cls.fields
        then: dict[str, Any] = {'properties': {f.name: _field_json(f) for f in fields}}
        if cls.takes_within:
            then['properties']['within'] = {'type': 'number', 'minimum': 0,
                                            'description': 'Deadline, seconds from time zero.'}
        required = [f.name for f in fields if f.required]
        if required:
            then['required'] = required
        rules.append({'if': {'properties': {'type': {'const': name}}, 'required': ['type']}, 'then': then})
    assertion['allOf'] = rules


def render_sections() -> str:
    """Every section of scenario and campaign files: each key with its type, unit, default, range, whether
    required, and meaning (`bagfault schema`)."""
    from bagfault.spec.sections import CAMPAIGN_SECTIONS, SCENARIO_SECTIONS  # noqa: PLC0415

    lines = []
    for section in (*SCENARIO_SECTIONS, *CAMPAIGN_SECTIONS):
        lines.append(f'{section.where}: {section.description}')
        for key in section.keys:
            limits = _limits(key.minimum, key.maximum, key.choices, required=key.required, exclusive=key.exclusive)
            extra = f' [{", ".join(limits)}]' if limits else ''
            unit = f' ({key.unit})' if key.unit else ''
            default = '' if key.default is None else f' (default {key.default})'
            lines.append(f'    {key.name:<28} {key.type:<16} {key.description}{unit}{default}{extra}')
        lines.append('')
    return '\n'.join(lines).rstrip()


def render_assertions() -> str:
    """Every assertion type's keys, as text."""
    from bagfault.assertions.registry import ASSERTION_TYPES  # noqa: PLC0415

    lines = []
    for name in sorted(ASSERTION_TYPES):
        cls = ASSERTION_TYPES[name]
        lines.append(f'{name}: {cls.description}' + (' Takes `within` (seconds).' if cls.takes_within else ''))
        for f in (x.to_dict() for x in cls.fields):
            extra = ' [required]' if f['required'] else ''
            default = '' if f['default'] in (None, '') else f' (default {f["default"]})'
            lines.append(f'    {f["key"]:<28} {f["type"]:<16} {f["description"]}{default}{extra}')
        lines.append('')
    return '\n'.join(lines).rstrip()
