"""Every key of every section is declared once (bagfault/spec/sections.py): the parsers read exactly the keys the
schema documents, and the JSON Schema made from it accepts the files bagfault accepts and flags what it refuses."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import pytest
import yaml
from support.helpers import FIXTURES, ROOT

from bagfault.campaign import loader as campaign_loader
from bagfault.cli import main
from bagfault.errors import CampaignError
from bagfault.injectors.registry import get_injector_type
from bagfault.report.schema import json_schema
from bagfault.spec import sections
from bagfault.spec.yamlnodes import format_path, load_located

jsonschema = pytest.importorskip('jsonschema')


SCENARIO_BASE = {
    'injectors': [{'id': 'i', 'type': 'imu', 'input_topic': '/a', 'output_topic': '/b'},
                  {'id': 's', 'type': 'trigger_service', 'trigger_service': {'proxy_service': '/p',
                                                                             'target_service': '/t'}}],
    'faults': [{'id': 'f', 'injector_id': 'i', 'repeat': {'period': 1.0, 'on': 0.5},
                'report': {'code': 'IMU_BIAS'}},
               {'id': 'g', 'injector_id': 'i', 'after': {'fault': 'f'}}],
    'system_under_test': {'command': 'true', 'ready': [{'delay': 1.0}]},
    'fault_manager': {'overrides': [{'source': '/x'}], 'diagnostics': {'codes': {}},
                      'conditions': [{'topic': '/a', 'when': {'field': 'x', 'above': 1.0}, 'code': 'C'}],
                      'snapshots': {}, 'clear': [{'code': 'C', 'at': 1.0}]},
    'explore': {'faults': [{'id': 'x', 'injector_id': 'i', 'start': [0.0, 1.0],
                            'config': {'drop_probability': [0.0, 1.0]}}]},
}
PLACES = {  # each section and where it sits in SCENARIO_BASE
    'scenario': (), 'injector': ('injectors', 0), 'trigger_service': ('injectors', 1, 'trigger_service'),
    'fault': ('faults', 0), 'repeat': ('faults', 0, 'repeat'), 'report': ('faults', 0, 'report'),
    'after': ('faults', 1, 'after'), 'system_under_test': ('system_under_test',),
    'ready': ('system_under_test', 'ready', 0), 'fault_manager': ('fault_manager',),
    'override': ('fault_manager', 'overrides', 0), 'diagnostics': ('fault_manager', 'diagnostics'),
    'condition': ('fault_manager', 'conditions', 0), 'when': ('fault_manager', 'conditions', 0, 'when'),
    'snapshots': ('fault_manager', 'snapshots'), 'clear': ('fault_manager', 'clear', 0),
    'explore': ('explore',), 'explore_fault': ('explore', 'faults', 0),
}


def at(data: object, place: tuple[object, ...]) -> dict[str, object]:
    for step in place:
        data = data[step]  # type: ignore[index]
    assert isinstance(data, dict)
    return data


@pytest.mark.parametrize('section', [s for s in sections.SCENARIO_SECTIONS if s.unknown != 'ignore'],
                         ids=lambda s: s.name)
def test_every_section_of_a_scenario_knows_exactly_its_declared_keys(section: sections.Section, tmp_path: Path,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    """A key the declaration lacks is named at its place, with the declared keys as the known ones (an injector
    also knows its type's options); the same file without it is valid."""
    data = copy.deepcopy(SCENARIO_BASE)
    path = tmp_path / 'scenario.yaml'
    path.write_text(yaml.safe_dump(data))
    assert main(['validate', '--strict', str(path)]) == 0
    if section.name == 'topic':
        data['injectors'][0] = {'id': 'i', 'type': 'imu', 'topic': {'input_topic': '/a', 'output_topic': '/b'}}
        place: tuple[object, ...] = ('injectors', 0, 'topic')
    else:
        place = PLACES[section.name]
    at(data, place)['zz_undeclared'] = 1
    path.write_text(yaml.safe_dump(data))
    capsys.readouterr()
    assert main(['validate', '--strict', str(path)]) == 2
    known = {k.name for k in section.keys}
    if section.name == 'injector':
        known |= {f.name for f in get_injector_type('imu').options}
    where = format_path((*place, 'zz_undeclared'))  # type: ignore[arg-type]
    line = next(x for x in capsys.readouterr().err.splitlines() if f'{where}: ' in x)
    assert "key 'zz_undeclared'" in line
    assert set(line.split('(known: ')[1].split(')')[0].split(', ')) == known


@pytest.mark.parametrize('section', [sections.CAMPAIGN, sections.SEARCH, sections.UNTIL], ids=lambda s: s.name)
def test_every_section_of_a_campaign_knows_exactly_its_declared_keys(section: sections.Section,
                                                                     tmp_path: Path) -> None:
    data = {'campaign': 'c', 'scenario': 'missing.yaml', 'bags': ['a.mcap'],
            'search': {'parameter': 'faults.f.duration', 'low': 0.1, 'high': 0.9, 'tolerance': 0.2,
                       'until': {'assertion': 'a'}}}
    place = {'campaign': (), 'search': ('search',), 'until': ('search', 'until')}[section.name]
    at(data, place)['zz_undeclared'] = 1
    path = tmp_path / 'campaign.yaml'
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(CampaignError) as caught:
        campaign_loader.load_campaign(path)
    line = next(x for x in str(caught.value).splitlines() if 'zz_undeclared' in x)
    assert f"{format_path((*place, 'zz_undeclared'))}: unknown key" in line
    assert set(line.split('(known: ')[1].split(')')[0].split(', ')) == {k.name for k in section.keys}


def validator(kind: str) -> jsonschema.Draft202012Validator:
    schema = json_schema(kind)
    jsonschema.Draft202012Validator.check_schema(schema)
    return jsonschema.Draft202012Validator(schema)


def as_yaml_cpp_reads(path: Path) -> object:
    return load_located(path.read_text()).data


SCENARIOS = [*sorted((FIXTURES / 'scenarios').glob('*.yaml')),
             ROOT / 'examples' / 'closed_loop' / 'test_imu_drift.bagfault.yaml']


@pytest.mark.parametrize('path', SCENARIOS, ids=lambda p: p.name)
def test_every_scenario_bagfault_ships_passes_the_json_schema(path: Path) -> None:
    errors = [e.message for e in validator('scenario').iter_errors(as_yaml_cpp_reads(path))]
    assert errors == []


@pytest.mark.parametrize(('text', 'where'), [
    ('injector: {id: i, type: imu, input_topic: /a, output_topic: /b}\nfaults: []\nfautls: []\n', 'fautls'),
    ('injector: {id: i, type: imu, input_topic: /a, output_topic: /b}\n'
     'faults: [{id: f, injector_id: i, start: soon}]\n', 'soon'),
    ('injector: {id: i, type: imu, input_topic: /a, output_topic: /b}\nfaults: [{injector_id: i}]\n', "'id'"),
    ('injector: {id: i, type: imu, input_topic: /a, output_topic: /b}\nfaults: []\n'
     'assertions: [{id: a, type: topic_hz, topic: /b, min_hz: 5.0, window: 1.0}]\n', "'message_type'"),
    ('injector: {id: i, type: imu, input_topic: /a, output_topic: /b}\n'
     'faults: [{id: f, injector_id: i, config: {drop_probability: 2.0}}]\n', '2.0'),
    ('injector: {id: i, type: imu, input_topic: /a, output_topic: /b, on_malformed: ignore}\nfaults: []\n',
     'ignore'),
    ('injector: {id: i, type: imu, input_topic: /a, output_topic: /b}\n'
     'explore: {faults: [{id: x, injector_id: i, start: [0, 1, 2]}]}\n', '[0, 1, 2]'),
    ('injector: {id: i, type: imu, input_topic: /a, output_topic: /b}\n'
     'explore: {faults: [{id: x, injector_id: i, duration: [0, 1]}]}\n', '0'),
])
def test_the_json_schema_flags_what_bagfault_warns_about_or_refuses(text: str, where: str, tmp_path: Path) -> None:
    path = tmp_path / 'bad.yaml'
    path.write_text(text)
    errors = [e.message for e in validator('scenario').iter_errors(as_yaml_cpp_reads(path))]
    assert any(where in e for e in errors), errors
    assert main(['validate', '--strict', str(path)]) == 2  # and bagfault says no too (warnings refused)


def test_a_campaign_file_and_its_mistakes(tmp_path: Path) -> None:
    good = {'campaign': 'c', 'scenario': 's.yaml', 'mode': 'test', 'bags': ['a.mcap'],
            'sweep': {'faults.f.config.x': [1, 2]}, 'seeds': [1, 2],
            'search': {'parameter': 'faults.f.duration', 'low': 0.1, 'high': 0.9, 'tolerance': 0.2, 'repeat': 2,
                       'until': {'assertion': 'a', 'state': 'passed'}}, 'keep': 'none'}
    check = validator('campaign')
    assert [e.message for e in check.iter_errors(good)] == []
    assert any("'mode'" in e.message or "'ray'" in e.message for e in check.iter_errors({**good, 'mode': 'ray'}))
    assert any('repat' in e.message for e in check.iter_errors(
        {**good, 'search': {**good['search'], 'repat': 3}}))


def test_schema_prints_every_section_and_emits_the_json_schema(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(['schema']) == 0
    text = capsys.readouterr().out
    for section in (*sections.SCENARIO_SECTIONS, *sections.CAMPAIGN_SECTIONS):
        assert f'{section.where}: ' in text
    assert 'topic_hz: ' in text and 'message_type' in text.split('topic_hz: ')[1].split('\n\n')[0]
    assert main(['schema', '--json-schema', 'campaign']) == 0
    emitted = json.loads(capsys.readouterr().out)
    assert emitted['title'] == 'bagfault campaign file' and 'search' in emitted['$defs']


def test_the_anchors_own_scenario_files_pass_the_json_schema(anchors: Path) -> None:
    check = validator('scenario')
    files = sorted(anchors.rglob('*.yaml'))
    assert len(files) >= 9
    assert {p.name: [e.message for e in check.iter_errors(as_yaml_cpp_reads(p))] for p in files} == {
        p.name: [] for p in files}


def test_the_docs_reference_has_a_table_of_every_section_and_every_key() -> None:
    """docs/reference/scenario.md is generated from the declarations (docs/hooks.py): each section of scenario,
    campaign and CARET architecture files is a heading followed by one row per key."""
    from bagfault.report.schema import render_markdown

    text = render_markdown()
    for section in (*sections.SCENARIO_SECTIONS, *sections.CAMPAIGN_SECTIONS, *sections.ARCHITECTURE_SECTIONS):
        body = text.split(f'### `{section.where}`\n', 1)[1].split('\n### ', 1)[0]
        rows = [line.split(' | ')[0].removeprefix('| `').removesuffix('`') for line in body.splitlines()
                if line.startswith('| `')]
        assert rows == [k.name for k in section.keys], section.where
    assert '| `node_chain` | list | yes |' in text and '| `default_window_ms` | integer |  | `500` | ≥ 1, ≤ 4294967295' in text
