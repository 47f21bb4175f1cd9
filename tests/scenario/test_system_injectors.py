"""The process, clock and link injectors' keys, generated: every value is read as its rules say or refused in one
line naming where, never a crash; a fault sets exactly one action. Expected outcomes follow the rules as the
docs state them, written here independently of the coercion code."""

from __future__ import annotations

import re

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bagfault.errors import FieldValueError, ScenarioError
from bagfault.scenario import parse_scenario
from bagfault.schema import Key

TARGET = Key('target', 'target', '')
texts = st.one_of(st.text(max_size=12), st.sampled_from(['/controller', 'controller', '(', '[a-', 'planner.py',
                                                         '']))
values = st.one_of(st.none(), st.booleans(), st.integers(), st.floats(allow_nan=False), texts,
                   st.lists(texts, max_size=2),
                   st.dictionaries(st.sampled_from(['node', 'command', 'pid', 'x']), st.one_of(texts, st.integers()),
                                   max_size=2))


def expected_target(value: object) -> object:
    """The rule: 'system', or one key, node or command, with a non-empty string; a node name gets its leading
    slash; a command must compile as a regular expression. None: refused."""
    if value == 'system':
        return 'system'
    if not isinstance(value, dict) or len(value) != 1:
        return None
    [(kind, text)] = value.items()
    if kind not in ('node', 'command') or not isinstance(text, str) or not text:
        return None
    if kind == 'node':
        return {'node': text if text.startswith('/') else '/' + text}
    try:
        re.compile(text)
    except re.error:
        return None
    return {'command': text}


@settings(max_examples=300, deadline=None)
@given(values)
def test_a_target_is_read_as_its_rule_says_or_refused(value: object) -> None:
    expected = expected_target(value)
    if expected is None:
        with pytest.raises(FieldValueError):
            TARGET.coerce(value)
    else:
        assert TARGET.coerce(value) == expected


ACTIONS = {'process': ('pause', 'kill', 'cpu_limit'), 'clock': ('stall', 'jump_s', 'rate')}
SETTINGS = {'pause': 'true', 'kill': 'true', 'cpu_limit': '0.5', 'stall': 'true', 'jump_s': '-2.0', 'rate': '0.5'}


@settings(max_examples=120, deadline=None)
@given(st.sampled_from(sorted(ACTIONS)), st.data())
def test_a_system_fault_sets_exactly_one_action(kind: str, data: st.DataObject) -> None:
    chosen = data.draw(st.lists(st.sampled_from(ACTIONS[kind]), unique=True, max_size=3))
    config = ', '.join(f'{key}: {SETTINGS[key]}' for key in chosen)
    target = ', target: {node: /controller}' if kind == 'process' else ''
    text = (f'injectors:\n  - {{id: it, type: {kind}{target}}}\n'
            f'faults:\n  - {{id: f, injector_id: it, start: 1.0, duration: 1.0, config: {{{config}}}}}\n')
    if len(chosen) == 1:
        scenario = parse_scenario(text)
        assert scenario.faults[0].config.keys() == set(chosen)
    else:
        with pytest.raises(ScenarioError) as caught:
            parse_scenario(text)
        assert f'a {kind} fault sets exactly one of {", ".join(ACTIONS[kind])}' in str(caught.value)


@pytest.mark.parametrize(('text', 'said'), [
    ('injectors:\n  - {id: p, type: process, target: system}\nfaults:\n'
     '  - {id: f, injector_id: p, start: 1.0, config: {kill: true}}\n',
     'kill of the whole system without restart: true would end the run'),
    ('injectors:\n  - {id: p, type: process, target: system}\nfaults:\n'
     '  - {id: f, injector_id: p, start: 1.0, config: {pause: true, restart: true}}\n',
     'restart goes with kill: true'),
    ('injectors:\n  - {id: c, type: clock}\nfaults:\n  - {id: f, injector_id: c, start: 1.0, config: {stall: true}}\n',
     'a clock stall needs a duration'),
    ('injectors:\n  - {id: c, type: clock, input_topic: /a, output_topic: /b}\nfaults: []\n',
     "injector type 'clock' acts on the running system; it takes no input_topic"),
    ('injectors:\n  - {id: l, type: link, link_topic: /a, subscriber: system}\nfaults: []\n',
     'subscriber: name one process'),
    ('injectors:\n  - {id: p, type: process}\nfaults: []\n', "missing required key 'target'"),
])
def test_what_a_system_injector_refuses_is_one_line_naming_it(text: str, said: str) -> None:
    with pytest.raises(ScenarioError) as caught:
        parse_scenario(text)
    assert said in str(caught.value)


@pytest.mark.parametrize(('schedule', 'seconds'), [
    ('start: 1.0, duration: 0.5', 0.5),
    ('start: 1.0, duration: 10.0, repeat: {period: 2.0, on: 0.3}', 0.3),  # each activation lasts `on`
    ('start: 1.0, duration: 10.0, repeat: {period: 2.0, on: 2.0}', 10.0),  # on = period: one window
    ('start: 1.0, duration: 10.0, probability_per_second: 0.5, hold: 0.2', 0.2),
])
def test_a_stall_lasts_one_activation_of_its_schedule(schedule: str, seconds: float) -> None:
    """A stall holds /clock for one activation: with a repeat it lasts `on`, with random activations `hold`
    (by hand from the scheduler's rules: a repeat is on for `on` every `period`, whole when on >= period)."""
    from bagfault.live.clockwarp import stall_seconds

    scenario = parse_scenario('injectors:\n  - {id: c, type: clock}\n'
                              f'faults:\n  - {{id: f, injector_id: c, {schedule}, config: {{stall: true}}}}\n')
    assert stall_seconds(scenario.faults[0]) == seconds


def test_a_config_key_in_the_published_plugin_form_is_the_key_it_describes() -> None:
    """Plugins declared config keys as `ConfigField(key, 'double'|'int'|'bool'|..., description, default, min=,
    max=)` (the names `bagfault schema --json` prints); that form builds the one `Key`, checked alike."""
    from bagfault.errors import FieldValueError
    from bagfault.schema import ConfigField

    published = ConfigField('status_override', 'int', 'A status code.', 0, min=0, max=255)
    declared = Key('status_override', 'integer', 'A status code.', default=0, minimum=0, maximum=255)
    assert type(published) is Key and published == declared
    assert published.to_dict() == {
        'key': 'status_override', 'type': 'int', 'description': 'A status code.', 'default': 0, 'min': 0, 'max': 255,
        'required': False, 'choices': [], 'finite': True}
    assert published.coerce('7') == declared.coerce('7') == 7
    for key in (published, declared):
        with pytest.raises(FieldValueError, match='above the maximum 255'):
            key.coerce(256)
    assert ConfigField('gain', 'double', 'A gain.', 1.0).type == 'number'
    assert ConfigField('on', 'bool', 'A switch.').coerce('true') is True
    with pytest.raises(ValueError, match="unknown config key type 'float'"):
        ConfigField('gain', 'float', 'A gain.')
