"""Every key of every section is declared once (bagfault/spec/sections.py): the parsers read exactly the keys the
schema documents, and the JSON Schema made from it accepts the files bagfault accepts and flags what it refuses."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from support.helpers import FIXTURES, ROOT

from bagfault.campaign import loader as campaign_loader
from bagfault.cli import main
from bagfault.fault_manager import config as fault_manager_config
from bagfault.report.schema import json_schema
from bagfault.scenario import loader as scenario_loader
from bagfault.spec import sections, system
from bagfault.spec.yamlnodes import load_located

jsonschema = pytest.importorskip('jsonschema')


def names(section: sections.Section) -> set[str]:
    return {k.name for k in section.keys}


@pytest.mark.parametrize(('section', 'parsed'), [
    (sections.SCENARIO, scenario_loader.TOP_KEYS),
    (sections.INJECTOR, scenario_loader.INJECTOR_KEYS),
    (sections.TOPIC, scenario_loader.ENDPOINT_KEYS),
    (sections.FAULT, scenario_loader.FAULT_KEYS),
    (sections.SYSTEM, system.KEYS),
    (sections.READY, system.READY_KEYS),
    (sections.FAULT_MANAGER, fault_manager_config.TOP_KEYS),
    (sections.CAMPAIGN, campaign_loader.KEYS),
    (sections.SEARCH, campaign_loader.SEARCH_KEYS),
], ids=lambda x: x.name if isinstance(x, sections.Section) else '')
def test_the_declared_keys_are_the_keys_the_parser_reads(section: sections.Section, parsed: set[str]) -> None:
    assert names(section) == set(parsed)


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
