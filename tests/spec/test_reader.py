"""The one section reader (bagfault/spec/reader.py): each key by its declared type, unit, range and default,
read the anchor's way (yaml-cpp) or YAML's, every problem at its place."""

from __future__ import annotations

from typing import Any

import pytest

from bagfault.spec.reader import Reader
from bagfault.spec.sections import Key, Section
from bagfault.spec.yamlnodes import load_located

KEYS = (
    Key('name', 'string', 'A name.', required=True),
    Key('rate', 'number', 'A rate.', minimum=0, exclusive=True, maximum=100),
    Key('count', 'integer', 'A count.', default=10, minimum=1),
    Key('seed', 'integer', 'A seed.', minimum=0, maximum=2**64 - 1),
    Key('start', 'seconds', 'A time.', minimum=0, maximum=1e7),
    Key('period', 'seconds', 'A period.', minimum=0.01, maximum=1e7),
    Key('on', 'boolean', 'A flag.', default=False),
    Key('mode', 'string', 'A mode.', default='run', choices=('run', 'test')),
    Key('topics', 'list', 'Topics.', what='a list of topics'),
    Key('block', 'mapping', 'A block.'),
)
ANCHOR = Section('anchor', 'x', 'Read as the anchor reads it.', KEYS, reads='anchor', unknown='warn', noun='test')
OWN = Section('own', 'x', "bagfault's own.", KEYS)


def read(section: Section, text: str) -> tuple[dict[str, Any], list[tuple[str, str]], list[tuple[str, str]]]:
    """(values, problems, warnings) of a YAML mapping, each problem as (path, message)."""
    located = load_located(text)
    problems: list[tuple[str, str]] = []
    warnings: list[tuple[str, str]] = []
    reader = Reader(lambda p, m: problems.append(('.'.join(map(str, p)), m)),
                    lambda p, m: warnings.append(('.'.join(map(str, p)), m)), located.raw_text)
    result = reader.read(section, located.data, ())
    return (result.values if result is not None else {}), problems, warnings


def test_defaults_fill_what_is_not_written_and_a_missing_required_key_is_named() -> None:
    values, problems, _ = read(OWN, 'rate: 2.5\n')
    assert values == {'rate': 2.5, 'count': 10, 'on': False, 'mode': 'run'}
    assert problems == [('', "missing required key 'name'")]


def test_the_anchor_reads_scalars_as_yaml_cpp_does() -> None:
    """yaml-cpp's as<double>() reads a quoted '2' as 2 and as<bool>() reads yes/on; a string is the scalar as
    written (`name: on` is 'on', not True); a null is an absent key."""
    values, problems, _ = read(ANCHOR, "name: on\nrate: '2'\ncount: '0x10'\non: yes\nstart: ~\nseed: 7\n")
    assert problems == []
    assert values == {'name': 'on', 'rate': 2.0, 'count': 16, 'on': True, 'mode': 'run', 'seed': 7}


def test_bagfaults_own_sections_take_yaml_types_as_they_are() -> None:
    _, problems, _ = read(OWN, "name: n\nrate: '2'\non: yes\ncount: 2.0\n")
    assert problems == [('rate', "'2' is not a number"), ('count', '2.0 is not a positive integer')]
    # PyYAML (YAML 1.1) reads `yes` as true, so `on: yes` is a boolean here; yaml-cpp agrees


@pytest.mark.parametrize(('text', 'expected'), [
    ('rate: 0', ('rate', '0 must be greater than 0')),
    ('rate: 100.5', ('rate', '100.5 is above the maximum 100')),
    ('rate: .nan', ('rate', 'nan is not a finite number')),
    ('count: 0', ('count', '0 is not a positive integer')),
    ('seed: -1', ('seed', '-1 is not an integer from 0 to 18446744073709551615')),
    ('seed: 18446744073709551616', ('seed', '18446744073709551616 is not an integer from 0 to 18446744073709551615')),
    ('start: -1', ('start', '-1 is negative')),
    ('start: soon', ('start', "'soon' is not a number of seconds")),
    ('start: 1e8', ('start', '100000000.0 is not a time bagfault can schedule (0 to 1e+07 s)')),
    ('period: 0.001', ('period', '0.001 is below the minimum 0.01 s')),
    ('mode: live', ('mode', "'live' is not run or test")),
    ('on: maybe', ('on', "'maybe' is not true or false")),
    ('topics: /a', ('topics', 'must be a list of topics')),
    ('block: [1]', ('block', 'must be a mapping')),
    ('name: ""', ('name', 'must not be empty')),
    ('name: [a]', ('name', "['a'] is not a string")),
])
def test_each_value_outside_its_declaration_is_one_problem_at_its_key(text: str, expected: tuple[str, str]) -> None:
    values, problems, _ = read(OWN, f'name: n\n{text}\n' if not text.startswith('name') else f'{text}\n')
    assert problems == [expected]
    assert expected[0] not in values  # a refused value is not read, nor replaced by the default


def test_unknown_keys_are_errors_in_bagfaults_sections_and_warnings_in_the_anchors() -> None:
    _, problems, warnings = read(OWN, 'name: n\nrat: 1\n')
    known = 'block, count, mode, name, on, period, rate, seed, start, topics'
    assert problems == [('rat', f"unknown key 'rat' (did you mean 'rate'? known: {known})")] and warnings == []
    _, problems, warnings = read(ANCHOR, 'name: n\nrat: 1\n')
    assert warnings == [('rat', f"unknown test key 'rat' is ignored (did you mean 'rate'? known: {known})")]
    assert problems == []
    _, problems, _ = read(OWN, 'name: n\nzzz: 1\n')  # nothing close: no guess
    assert problems == [('zzz', f"unknown key 'zzz' (known: {known})")]


def test_a_section_that_is_not_a_mapping_names_its_required_keys() -> None:
    problems: list[str] = []
    assert Reader(lambda p, m: problems.append(m)).read(OWN, [1, 2], ('x',)) is None
    assert problems == ['must be a mapping with name']


def test_a_default_list_is_a_fresh_list_each_time() -> None:
    section = Section('s', 's', 'With a list default.', (Key('items', 'list', 'Items.', default=[]),))
    first = Reader(print).read(section, {}, ())
    second = Reader(print).read(section, {}, ())
    assert first is not None and second is not None
    first.get('items').append(1)
    assert second.get('items') == [] and section.keys[0].default == []


def test_caret_words_for_a_required_key_missing_or_null_and_an_optional_null_is_absent() -> None:
    """caret_analyze's Util.get_value: "required key 'x' not found", "'x' value is None"."""
    section = Section('c', 'c', 'caret-like.', (Key('name', 'any', 'Name.', required=True),
                                                 Key('items', 'list', 'Items.', default=[])), reads='caret',
                      unknown='ignore')
    problems: list[str] = []
    reader = Reader(lambda p, m: problems.append(m))
    assert reader.read(section, {'items': None, 'other': 1}, ()) is not None
    assert reader.read(section, {'name': None}, ()) is not None
    assert reader.read(section, 'text', ()) is None
    assert problems == ["required key 'name' not found", "'name' value is None", "required key 'name' not found"]
    read = reader.read(section, {'name': 'n', 'items': None}, (), required=('items',))
    assert read is not None and problems[-1] == "'items' value is None"


def test_medkit_reads_uint32_and_a_boolean_that_is_no_scalar_as_its_default() -> None:
    """config_parser.cpp: get_uint32 is as<uint32_t>() (a quoted number counts, 2^32 does not); get_bool gives
    the default for a node that is not a scalar."""
    section = Section('m', 'm', 'medkit-like.', (Key('window_ms', 'integer', 'Window.', minimum=1,
                                                     maximum=2**32 - 1),
                                                 Key('mute', 'boolean', 'Mute.', default=True)), reads='medkit')
    values, problems, _ = read(section, "window_ms: '4294967295'\nmute: [false]\n")
    assert problems == [] and values == {'window_ms': 2**32 - 1, 'mute': True}
    _, problems, _ = read(section, "window_ms: '4294967296'\nmute: maybe\n")
    assert problems == [('window_ms', "'4294967296' is not an integer from 1 to 4294967295"),
                        ('mute', "'maybe' is not a boolean as medkit's yaml-cpp reads one (true/false, yes/no, "
                                 'on/off, y/n)')]
