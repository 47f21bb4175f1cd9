"""CARET architecture files and end-to-end path latency on bags; loading and response times follow
tier4/caret_analyze at commit 679f1ec9 (architecture_reader_yaml.py, architecture_loaded.py, response_time.py)."""

from __future__ import annotations

import json
import re
import textwrap

import numpy as np
import pytest
from support.caret import caret_target_messages
from support.helpers import CARET, FIXTURES, NS, SHARED, need
from support.html_check import figures

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
    records, truth = caret_target_messages(**kw)
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
    # /ping_node publishes /ping, not /chatter: caret_analyze's find_node_path fails and the path is not loaded
    assert architecture.paths == {}
    assert architecture.dropped == {'target_path': 'node /ping_node does not publish /chatter'}
    assert main(['latency', 'validate', str(tmp_path / 'seed_sample.yaml')]) == 2
    err = capsys.readouterr().err  # warnings go to stderr in every command
    assert 'warning: path target_path: node /ping_node does not publish /chatter; path dropped' in err
    assert 'warning: node /ping_node' in err
    with pytest.raises(LatencyError, match='path target_path was dropped: node /ping_node does not publish'):
        measure(tmp_path / 'seed_sample.yaml', [], path='target_path')


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


def test_unknown_context_type_drops_that_context_and_a_callback_chain_takes_its_place(tmp_path, caret_file):
    """caret_analyze's MessageContextsLoaded: an unknown type is a warning and that context only is dropped; the
    node's callbacks (subscription -> variable passing -> timer that publishes) give a callback_chain."""
    text = caret_file.read_text().replace('context_type: use_latest_message\n    subscription_topic_name: /topic3',
                                          'context_type: newest_wins\n    subscription_topic_name: /topic3', 1)
    text = text.replace('- node_name: /actuator_dummy_node\n  callback_groups', '- node_name: /renamed_node\n'
                        '  callback_groups', 1)
    path = tmp_path / 'arch.yaml'
    path.write_text(text)
    architecture = load_architecture(path)
    assert any("node /timer_driven_node: message_contexts[0]: unknown context_type 'newest_wins'" in w
               and 'context dropped' in w for w in architecture.warnings)
    hops = {node: context.context_type for node, _, _, context in architecture.hops(architecture.paths['target'])}
    assert hops['/timer_driven_node'] == 'callback_chain'
    assert architecture.paths['target'].problems == ['path goes through node /actuator_dummy_node, which is not '
                                                     'in nodes']
    with pytest.raises(LatencyError, match='path target cannot be measured'):
        measure(path, [], path='target')


def test_a_context_over_a_topic_its_node_does_not_have_is_dropped_with_a_warning(tmp_path, caret_file):
    """caret builds a context from the node's own subscription and publisher of those topics; with neither
    there is no context (and a callback chain, if any, takes its place): a warning, not a silent change."""
    text = caret_file.read_text().replace('context_type: use_latest_message\n    subscription_topic_name: /topic3',
                                          'context_type: use_latest_message\n    subscription_topic_name: /nowhere',
                                          1)
    path = tmp_path / 'arch.yaml'
    path.write_text(text)
    architecture = load_architecture(path)
    assert any('node /timer_driven_node: message_contexts[0]: the node does not subscribe to /nowhere; context '
               'dropped' in w for w in architecture.warnings), architecture.warnings
    assert load_architecture(caret_file).warnings == []  # the file as it is: no such warning


def test_a_hop_without_context_ends_the_measurement_at_its_input(caret_file, target_bag, tmp_path):
    """UNDEFINED context and no callback chain (the subscription callback publishes nothing): caret's record
    merge stops at that node, so the path is measured /topic1 -> /topic3 with a note."""
    text = caret_file.read_text().replace(
        'context_type: use_latest_message\n    subscription_topic_name: /topic3',
        'context_type: UNDEFINED\n    subscription_topic_name: /topic3', 1).replace(
        '  variable_passings:\n  - callback_name_write: /timer_driven_node/callback_1\n'
        '    callback_name_read: /timer_driven_node/callback_0\n', '')
    arch = tmp_path / 'undefined.yaml'
    arch.write_text(text)
    bag, _ = target_bag
    [result] = measure(arch, [bag]).results
    assert result.topics == ['/topic1', '/topic2', '/topic3']
    assert np.allclose(result.latency_ms, 30.0, atol=1.0)  # synthetic delays: 10 ms filter + 20 ms message-driven
    assert any('/timer_driven_node has no message context' in n and 'ends at its input /topic3' in n
               for n in result.notes)


def test_architecture_loading_leniency(tmp_path, caret_file, target_bag):
    """As caret_analyze: a service callback is ignored, a duplicate path name keeps the first, a path over a
    topic its node does not publish is dropped with a warning, a one-node path is measured inside the node."""
    text = caret_file.read_text().replace('  callbacks:\n  - callback_name: /filter_node/callback_0',
                                          '  callbacks:\n  - {callback_name: /filter_node/srv, callback_type: '
                                          'service_callback, service_name: /srv, symbol: srv}\n'
                                          '  - callback_name: /filter_node/callback_0', 1)
    text = text.replace('named_paths:\n', """named_paths:
- path_name: inside_filter
  node_chain:
  - {node_name: /filter_node, subscribe_topic_name: /topic1, publish_topic_name: /topic2}
- path_name: inside_filter
  node_chain:
  - {node_name: /message_driven_node, subscribe_topic_name: /topic2, publish_topic_name: /topic3}
- path_name: wrong_topic
  node_chain:
  - {node_name: /sensor_dummy_node, publish_topic_name: /topic9}
  - {node_name: /filter_node, subscribe_topic_name: /topic9}
""", 1)
    arch = tmp_path / 'lenient.yaml'
    arch.write_text(text)
    architecture = load_architecture(arch)
    assert list(architecture.paths) == ['inside_filter', 'target']
    assert 'path inside_filter is defined more than once; the first is used' in architecture.warnings
    assert 'path wrong_topic: node /sensor_dummy_node does not publish /topic9; path dropped' in \
        architecture.warnings
    assert [c['callback_name'] for c in architecture.nodes['/filter_node'].callbacks] == ['/filter_node/callback_0']
    bag, _ = target_bag
    inside = measure(arch, [bag], path='inside_filter').results[0]
    assert inside.topics == ['/topic1', '/topic2'] and np.allclose(inside.latency_ms, 10.0, atol=1.0)  # the filter's 10 ms


def test_fixed_delays_give_60_ms_for_every_sample(caret_file, target_bag, tmp_path, capsys):
    bag, truth = target_bag
    report = measure(caret_file, [bag])
    [result] = report.results
    assert result.latency_ms.size == 200 == len(truth)
    assert np.all(np.abs(result.latency_ms - 60.0) <= 1.0)
    assert result.dropped == 0
    assert np.allclose(result.cases['best'][1], 60.0) and np.allclose(result.cases['worst'][1], 60.0)
    assert np.allclose(result.cases['worst-with-external-latency'][1], 160.0)  # one 100 ms input period more
    assert main(['latency', str(caret_file), str(bag), '--json', str(tmp_path / 'l.json'), '--html',
                 str(tmp_path / 'l.html')]) == 0
    out = capsys.readouterr().out
    assert 'path target: /topic1 -> /topic2 -> /topic3 -> /topic4  (200 inputs, 0 dropped)' in out
    assert re.search(r'latency\s+200\s+60\.000\s+60\.000\s+60\.000\s+60\.000\s+60\.000\s+60\.000', out)
    data = json.loads((tmp_path / 'l.json').read_text())
    assert data['paths'][0]['latency_ms']['p95'] == pytest.approx(60.0)
    drawn = figures(tmp_path / 'l.html')
    assert set(drawn) == {'latency:target', 'histogram:target'}
    assert np.allclose(drawn['latency:target']['data'][0]['y'], 60.0, atol=1.0)
    assert len(drawn['histogram:target']['data'][0]['x']) == 200


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
    # caret's ResponseMapAll by hand: records (0,0.1) (1,1.1) (2,-) (3,3.2) (4,4.3); the dropped input takes the
    # next end (3.2); entries ending at the earliest end (0.1) go
    cases = {name: values.tolist() for name, (_, values) in result.cases.items()}
    assert cases['all'] == pytest.approx([100, 1200, 200, 300])
    assert cases['best'] == pytest.approx([100, 200, 300])           # latest input per output
    assert cases['worst'] == pytest.approx([100, 1200, 300])         # earliest input per output
    assert cases['worst-with-external-latency'] == pytest.approx([2200, 1300])  # output - input before the earliest
    assert result.dropped == 1


def test_stamp_origin_applies_to_the_response_time_cases(tmp_path):
    architecture = hop_architecture(tmp_path, 'use_latest_message')
    ms = 1_000_000  # inputs received at 10, 20, 30 ms with stamps 5 ms earlier; outputs at 12, 24, 35 ms
    series = {'/a': TopicSeries(np.array([10, 20, 30]) * ms, np.array([5, 15, 25]) * ms),
              '/b': TopicSeries(np.array([12, 24, 35]) * ms)}
    received = path_latency(architecture, architecture.paths['p'], series)
    stamped = path_latency(architecture, architecture.paths['p'], series, stamp_origin=True)
    assert stamped.latency_ms.tolist() == [7.0, 9.0, 10.0] and received.latency_ms.tolist() == [2.0, 4.0, 5.0]
    assert received.cases['best'][1].tolist() == [4.0, 5.0] and stamped.cases['best'][1].tolist() == [9.0, 10.0]
    assert stamped.cases['worst-with-external-latency'][1].tolist() == [20.0]  # 35 - 15


def hop_architecture(folder, context):
    """Three nodes, one hop /a -> /b with the given context."""
    path = folder / 'arch.yaml'
    path.write_text((FIXTURES / 'caret' / 'one_hop.yaml').read_text().replace('CONTEXT', context))
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
