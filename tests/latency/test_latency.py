"""CARET architecture files and end-to-end path latency on bags."""

from __future__ import annotations

import json
import re
import textwrap

import numpy as np
import pytest
from helpers import CARET, FIXTURES, NS, SHARED, need

from bagfault import api
from bagfault.cli import main
from bagfault.demo import synthetic
from bagfault.errors import LatencyError
from bagfault.latency.architecture import load_architecture
from bagfault.latency.compute import TopicSeries, path_latency
from bagfault.latency.measure import measure
from bagfault.scenario import ScenarioError, parse_scenario

START = synthetic.DEFAULT_START


@pytest.fixture(scope='session')
def caret_file():
    """bagfault's own CARET architecture file for the synthetic target pipeline."""
    return FIXTURES / 'caret' / 'target_pipeline.yaml'


@pytest.fixture(scope='session')
def caret_sample():
    """CARET's own end-to-end sample architecture file (third-party data)."""
    return need(CARET / 'end_to_end_sample_architecture.yaml')


def write_target_bag(path, **kw):
    records, truth = synthetic.caret_target_messages(**kw)
    synthetic.write_mcap(path, records)
    return path, truth


@pytest.fixture(scope='module')
def target_bag(tmp_path_factory):
    return write_target_bag(tmp_path_factory.mktemp('caret') / 'target.mcap', duration=20.0)


@pytest.mark.parametrize('which', ['caret_file', 'caret_sample'])
def test_architecture_file_loads(which, request, capsys):
    caret_file = request.getfixturevalue(which)
    architecture = load_architecture(caret_file)
    assert list(architecture.paths) == ['target'] and not architecture.warnings
    path = architecture.paths['target']
    assert path.usable and path.topics == ['/topic1', '/topic2', '/topic3', '/topic4']
    hops = [(node, source, target, context.context_type) for node, source, target, context in architecture.hops(path)]
    assert hops == [('/filter_node', '/topic1', '/topic2', 'use_latest_message'),
                    ('/message_driven_node', '/topic2', '/topic3', 'use_latest_message'),
                    ('/timer_driven_node', '/topic3', '/topic4', 'use_latest_message')]
    callbacks = architecture.nodes['/timer_driven_node'].callbacks
    assert [c['construction_order'] for c in callbacks] == [0, 0]
    assert main(['latency', 'validate', str(caret_file)]) == 0
    assert 'hop /timer_driven_node: /topic3 -> /topic4 [use_latest_message]' in capsys.readouterr().out


def seed_sample(tmp_path):
    text = need(SHARED / 'seeds' / 'caret_architecture_file.md').read_text()
    block = re.search(r'```yaml\n(.*?)```', text, re.S)
    if block is None:
        pytest.skip('seed document absent')
    path = tmp_path / 'seed_sample.yaml'
    path.write_text(block.group(1))
    return path


def test_seed_sample_with_type_warns_naming_the_node_and_loads(tmp_path, capsys):
    architecture = load_architecture(seed_sample(tmp_path))
    assert "node /ping_node: callback 'subscription_callback_0' says 'type:'" in architecture.warnings[0]
    assert '/ping_node' in architecture.nodes
    path = architecture.paths['target_path']
    assert not path.usable
    assert path.problems == ['path goes through node /pong_node, which is not in nodes']
    assert main(['latency', 'validate', str(tmp_path / 'seed_sample.yaml')]) == 2
    out = capsys.readouterr().out
    assert 'path target_path: UNUSABLE' in out and 'warning: node /ping_node' in out


MALFORMED = {
    'missing top-level key': ('named_paths: []\nexecutors: []\n', "architecture: required key 'nodes' not found"),
    'null value': ('named_paths:\nexecutors: []\nnodes: []\n', "architecture: 'named_paths' value is None"),
    'not yaml': ('named_paths: [\n', 'invalid YAML'),
}


@pytest.mark.parametrize('case', MALFORMED)
def test_malformed_files_give_the_documented_message(tmp_path, case, capsys):
    text, message = MALFORMED[case]
    path = tmp_path / 'arch.yaml'
    path.write_text(text)
    with pytest.raises(LatencyError, match=re.escape(message)) as info:
        load_architecture(path)
    assert str(path) in str(info.value)
    assert main(['latency', 'validate', str(path)]) == 2
    assert capsys.readouterr().err.startswith(f'bagfault: error: {path}')


def test_unknown_context_type_and_missing_node(tmp_path, caret_file):
    text = caret_file.read_text().replace('context_type: use_latest_message\n    subscription_topic_name: /topic3',
                                          'context_type: newest_wins\n    subscription_topic_name: /topic3', 1)
    text = text.replace('- node_name: /actuator_dummy_node\n  callback_groups', '- node_name: /renamed_node\n'
                        '  callback_groups', 1)
    path = tmp_path / 'arch.yaml'
    path.write_text(text)
    architecture = load_architecture(path)
    assert any("node /timer_driven_node: message_contexts[0]: unknown context_type 'newest_wins'" in w
               for w in architecture.warnings)
    problems = architecture.paths['target'].problems
    assert any(p.startswith('node /timer_driven_node was skipped') for p in problems)
    assert 'path goes through node /actuator_dummy_node, which is not in nodes' in problems
    with pytest.raises(LatencyError, match='path target cannot be measured'):
        measure(path, [], path='target')


def test_fixed_delays_give_60_ms_for_every_sample(caret_file, target_bag, tmp_path, capsys):
    bag, truth = target_bag
    report = measure(caret_file, [bag])
    [result] = report.results
    assert result.latency_ms.size == 200 == len(truth)
    assert np.all(np.abs(result.latency_ms - 60.0) <= 1.0)
    assert result.dropped == 0
    assert np.allclose(result.best[1], 60.0) and np.allclose(result.worst[1], 160.0)
    assert main(['latency', str(caret_file), str(bag), '--json', str(tmp_path / 'l.json'), '--html',
                 str(tmp_path / 'l.html')]) == 0
    out = capsys.readouterr().out
    assert 'path target: /topic1 -> /topic2 -> /topic3 -> /topic4  (200 inputs, 0 dropped)' in out
    assert re.search(r'latency\s+200\s+60\.000\s+60\.000\s+60\.000\s+60\.000\s+60\.000\s+60\.000', out)
    data = json.loads((tmp_path / 'l.json').read_text())
    assert data['paths'][0]['latency_ms']['p95'] == pytest.approx(60.0)
    html = (tmp_path / 'l.html').read_text()
    assert html.count('data-kind="line"') == 1 and html.count('data-kind="histogram"') == 1


def test_random_delays_match_the_generators_truth(caret_file, tmp_path):
    bag, truth = write_target_bag(tmp_path / 'jitter.mcap', duration=10.0, jitter_ms=(15.0, 5.0, 25.0), seed=3)
    [result] = measure(caret_file, [bag]).results
    expected = np.array([(t4 - t1) / 1e6 for t4, t1 in truth])
    assert np.array_equal(result.latency_ms, expected) and expected.std() > 3.0


def test_repeated_stamps_with_inherit_unique_stamp(caret_file, tmp_path):
    bag, truth = write_target_bag(tmp_path / 'timer.mcap', duration=5.0, timer_hz=25.0)
    text = caret_file.read_text().replace('context_type: use_latest_message', 'context_type: inherit_unique_stamp')
    arch = tmp_path / 'stamp.yaml'
    arch.write_text(text)
    for file in (caret_file, arch):
        [result] = measure(file, [bag]).results
        expected = np.array([(t4 - t1) / 1e6 for t4, t1 in truth])
        assert np.array_equal(result.latency_ms, expected)
    assert len({t1 for _, t1 in truth}) < len(truth)  # /topic4 really repeats stamps


def test_stamp_matching_takes_the_latest_input_with_the_stamp(tmp_path):
    architecture = hop_architecture(tmp_path, 'inherit_unique_stamp')
    path = architecture.paths['p']
    ms = 1_000_000
    series = {
        '/a': TopicSeries(np.array([0, 10, 20, 30]) * ms, np.array([1, 2, 1, 3]) * ms),   # stamp 1 twice
        '/b': TopicSeries(np.array([25, 35, 40]) * ms, np.array([1, 3, 9]) * ms),
    }
    result = path_latency(architecture, path, series)
    assert result.latency_ms.tolist() == [5.0, 5.0]  # stamp 1 -> input at 20 (not 0); stamp 9 has no input
    assert result.dropped == 2


def test_response_time_cases_follow_caret(tmp_path):
    architecture = hop_architecture(tmp_path, 'use_latest_message')
    tenth = 100_000_000  # 0.1 s: inputs at 0, 1, 2, 3, 4 s; outputs at 0.1, 1.1, 3.2, 4.3 s (2 s is dropped)
    series = {'/a': TopicSeries(np.array([0, 10, 20, 30, 40]) * tenth),
              '/b': TopicSeries(np.array([1, 11, 32, 43]) * tenth)}
    result = path_latency(architecture, architecture.paths['p'], series)
    assert result.latency_ms.tolist() == pytest.approx([100, 100, 200, 300])
    assert result.best[1].tolist() == pytest.approx([100, 100, 200, 300])
    assert result.worst[1].tolist() == pytest.approx([1100, 2200, 1300])   # first output - previous answered input
    assert result.all_cases[1].tolist() == pytest.approx([100, 100, 1200, 200, 300])  # input 2.0 was dropped
    assert result.dropped == 1


HOP = """
named_paths:
  - path_name: p
    node_chain:
      - {node_name: /src, publish_topic_name: /a, subscribe_topic_name: UNDEFINED}
      - {node_name: /mid, publish_topic_name: /b, subscribe_topic_name: /a}
      - {node_name: /dst, subscribe_topic_name: /b}
executors: []
nodes:
  - {node_name: /src}
  - node_name: /mid
    message_contexts: [{context_type: CONTEXT, subscription_topic_name: /a, publisher_topic_name: /b}]
  - {node_name: /dst}
"""


def hop_architecture(folder, context):
    """Three nodes, one hop /a -> /b with the given context."""
    path = folder / 'arch.yaml'
    path.write_text(HOP.replace('CONTEXT', context))
    return load_architecture(path)


def latency_scenario(caret_file, max_ms):
    return textwrap.dedent(f"""
        injector: {{id: late, type: topic, input_topic: /topic4, output_topic: /topic4}}
        faults:
          - {{id: topic4_late, injector_id: late, start: 5.0, duration: 5.0, config: {{delay_ms: 50}}}}
        assertions:
          - {{id: latency, type: path_latency, architecture: {caret_file}, path: target, statistic: max,
             max_ms: {max_ms}, during: topic4_late, min_samples: 40}}
          - {{id: latency_outside, type: path_latency, architecture: {caret_file}, path: target, statistic: max,
             max_ms: 61}}
    """)


def test_delaying_the_last_topic_moves_the_latency_by_the_delay(caret_file, target_bag, tmp_path):
    bag, _ = target_bag
    out = tmp_path / 'out.mcap'
    result = api.run(parse_scenario(latency_scenario(caret_file, 80)), [bag], out)
    states = {a.id: a for a in result.assertions}
    assert states['latency'].state == 'failed'
    assert states['latency'].message.startswith('max of path target during topic4_late = 110.000 ms (max 80 ms, '
                                                '50 samples')
    assert states['latency_outside'].state == 'failed'
    report = measure(caret_file, [out])
    [path] = report.results
    during = (path.input_times >= START + 5 * NS) & (path.input_times < START + 10 * NS)
    assert np.all(np.abs(path.latency_ms[during] - 110.0) <= 1.0) and during.sum() == 50
    assert np.all(np.abs(path.latency_ms[~during] - 60.0) <= 1.0)
    windows = report.to_dict()['paths'][0]['by_fault']['topic4_late']
    assert (windows['before']['max'], windows['during']['min'], windows['after']['max']) == pytest.approx(
        (60.0, 110.0, 60.0))
    passed = api.run(parse_scenario(latency_scenario(caret_file, 120)), [bag], tmp_path / 'ok.mcap')
    assert {a.id: a.state for a in passed.assertions}['latency'] == 'passed'


def test_path_latency_assertion_is_validated(caret_file):
    with pytest.raises(ScenarioError) as info:
        parse_scenario(textwrap.dedent(f"""
            injector: {{id: i, type: topic, input_topic: /topic4, output_topic: /x}}
            assertions:
              - {{id: a, type: path_latency, architecture: {caret_file}, path: nope, max_ms: 1, statistic: p42}}
              - {{id: b, type: path_latency, architecture: /no/such/file.yaml, path: target, max_ms: 1}}
        """))
    text = str(info.value)
    assert "no path 'nope' (paths: target)" in text and "'p42' is not one of" in text
    assert 'architecture file not found' in text
