"""Anchor assertions on bag time, exit codes, and every report format."""

from __future__ import annotations

import json
from xml.etree import ElementTree

import pytest
import xmlschema
from support.helpers import FIXTURES, NS, decoded
from support.html_check import figures, rendered

from bagfault import api
from bagfault.cli import main
from bagfault.demo import synthetic

START = synthetic.DEFAULT_START
EXPECTED_PASS_TIMES = {
    'odom_yaw_bias_activates': 5.0,
    'odom_yaw_bias_deactivates': 15.0,
    'odom_covariance_activates': 3.0,
    'odom_covariance_deactivates': 18.0,
    'odom_stays_above_10hz': 0.6,    # first 100 ms look with 30+ /odom messages (31 at 0.6 s: 10.3 Hz)
    'scan_stays_above_5hz': 1.4,     # look at 1.4 s sees the 15th /scan message at 10 Hz: 15 in 3 s = 5 Hz
}


@pytest.fixture(scope='module')
def reports(tmp_path_factory, scenarios):
    folder = tmp_path_factory.mktemp('reports')
    code = main(['run', str(scenarios / 'rover_multi.yaml'), str(FIXTURES / 'rover_20s.mcap'),
                 '-o', str(folder / 'out.mcap'), '--report', str(folder / 'r.md'), '--json', str(folder / 'r.json'),
                 '--junit', str(folder / 'r.xml'), '--html', str(folder / 'r.html')])
    return code, folder


def test_anchor_assertions_pass_at_their_times(reports):
    code, folder = reports
    assert code == 0
    data = json.loads((folder / 'r.json').read_text())
    assert {a['id']: (a['state'], a['t_s']) for a in data['assertions']} == {
        k: ('passed', v) for k, v in EXPECTED_PASS_TIMES.items()}
    events = decoded(folder / 'out.mcap', ['/fault_injection/assertion_events', '/fault_injection/scenario_status'])
    passed = {m.assertion_id: (t - START) / NS for t, m in events['/fault_injection/assertion_events']}
    assert passed == pytest.approx(EXPECTED_PASS_TIMES)
    for time, message in events['/fault_injection/assertion_events']:
        assert message.stamp.sec * NS + message.stamp.nanosec == time and message.state == 'passed'
    statuses = [(m.state, m.pending_count, m.passed_count) for _, m in events['/fault_injection/scenario_status']]
    assert statuses[0] == ('running', 5, 1) and statuses[-1] == ('passed', 0, 6)
    assert len(statuses) == 7  # one per change and one at the end


def test_changing_within_to_4_fails_at_the_look_after_4_seconds(tmp_path, scenarios, capsys):
    text = (scenarios / 'rover_multi.yaml').read_text()
    scenario = tmp_path / 'late.yaml'
    late = text.replace('state: active, within: 6.0', 'state: active, within: 4.0')
    assert late != text
    scenario.write_text(late)
    code = main(['run', str(scenario), str(FIXTURES / 'rover_20s.mcap'), '-o', str(tmp_path / 'o.mcap'),
                 '--json', str(tmp_path / 'r.json')])
    assert code == 1
    assert 'FAIL  odom_yaw_bias_activates' in capsys.readouterr().out
    data = json.loads((tmp_path / 'r.json').read_text())
    failed = next(a for a in data['assertions'] if a['id'] == 'odom_yaw_bias_activates')
    # judged at the anchor's first 100 ms look past `within` (fault_assertion_runner.cpp): 4.1 s
    assert (failed['state'], failed['t_s'], failed['stamp_ns']) == ('failed', 4.1, START + 41 * NS // 10)
    assert failed['message'] == 'fault odom_yaw_bias did not reach active within 4 s (deadline 4.100 s)'
    assert data['verdict'] == 'failed' and data['final_status'] == 'failed'
    events = decoded(tmp_path / 'o.mcap', ['/fault_injection/assertion_events'])['/fault_injection/assertion_events']
    assert [(t, m.state) for t, m in events if m.assertion_id == 'odom_yaw_bias_activates'] == [
        (START + 41 * NS // 10, 'failed')]


def test_end_of_bag_fails_what_is_pending(tmp_path):
    scenario = tmp_path / 's.yaml'
    scenario.write_text('injector: {id: o, type: odom, input_topic: /odom_raw, output_topic: /odom}\n'
                        'faults: [{id: never, injector_id: o, config: {x_bias: 1}}]\n'
                        'assertions: [{id: a, type: fault_event, fault_id: never, state: active}]\n')
    result = api.run(scenario, [FIXTURES / 'rover_20s.mcap'], tmp_path / 'o.mcap')
    [a] = result.assertions
    assert a.state == 'failed' and a.time == START + 19_990_000_000
    assert a.message == 'fault never did not reach active: not observed before the end of the bag'


def test_json_report_has_stable_documented_keys(reports):
    _, folder = reports
    data = json.loads((folder / 'r.json').read_text())
    assert set(data) == {
        'schema_version', 'tool', 'mode', 'verdict', 'scenario', 'seed', 'inputs', 'output', 'time', 'messages',
        'fault_events', 'fault_windows', 'injectors', 'assertions', 'assertion_counts', 'assertion_events',
        'final_status', 'notes', 'warnings', 'bagfault_mark'}
    documented = (FIXTURES.parent.parent / 'docs' / 'reference' / 'report.md').read_text()
    for key in data:
        assert f'`{key}`' in documented
    assert data['fault_windows'][0] == {'fault_id': 'odom_covariance_inflation', 'start_s': 3.0, 'end_s': 18.0}
    assert data['assertion_counts'] == {'passed': 6, 'failed': 0, 'pending': 0}


SCHEMAS = ('junit.xsd', 'junit-10.xsd')  # the common one the tests ship, and Jenkins' (the xunit plugin's)


def valid_everywhere(path):
    for name in SCHEMAS:
        xmlschema.XMLSchema(str(FIXTURES / name)).validate(str(path))


def test_junit_validates_and_lists_every_assertion(reports, tmp_path, scenarios):
    _, folder = reports
    valid_everywhere(folder / 'r.xml')
    text = (folder / 'r.xml').read_text()
    assert text.count('<testcase ') == 6 and '<failure' not in text
    root = ElementTree.fromstring(text)
    suite_time = float(root.find('testsuite').get('time'))
    report = json.loads((folder / 'r.json').read_text())
    assert 0 < suite_time < 60 and suite_time == report['time']['wall_s']   # wall time, not the 20 s of bag time
    properties = {p.get('name'): p.get('value') for p in root.find('testsuite').iter('property')}
    assert properties['scenario'] == str(scenarios / 'rover_multi.yaml')
    source = (scenarios / 'rover_multi.yaml').read_text().splitlines()
    for case in root.iter('testcase'):
        assert set(case.keys()) == {'name', 'classname', 'time'}  # all junit-10 allows
        where, line, _ = case.find('system-out').text.split(':', 2)  # 'file:line: message'
        assert where == str(scenarios / 'rover_multi.yaml')
        assert f"id: {case.get('name')}" in source[int(line) - 1]  # the line that names it
        assert 0 <= float(case.get('time')) <= suite_time
    scenario = tmp_path / 'late.yaml'
    scenario.write_text((scenarios / 'rover_multi.yaml').read_text().replace('min_hz: 10.0', 'min_hz: 60.0'))
    assert main(['run', str(scenario), str(FIXTURES / 'rover_20s.mcap'), '-o', str(tmp_path / 'o.mcap'),
                 '--junit', str(tmp_path / 'r.xml')]) == 1
    valid_everywhere(tmp_path / 'r.xml')
    failed = (tmp_path / 'r.xml').read_text()
    assert failed.count('<failure ') == 1 and 'failures="1"' in failed
    assert 'did not reach 60 Hz (best 50.33 Hz over 3 s)' in failed  # 151 messages in [t - 3, t] at 50 Hz
    assert f'{scenario}:' in failed  # the failure's text says where


def test_junit_with_file_and_line_on_each_testcase(tmp_path, scenarios):
    """--junit-file-line: the attributes GitHub's and GitLab's readers link; valid under the common schema, refused
    by Jenkins' junit-10 (so they are not the default)."""
    out = tmp_path / 'r.xml'
    assert main(['run', str(scenarios / 'rover_multi.yaml'), str(FIXTURES / 'rover_20s.mcap'), '-o',
                 str(tmp_path / 'o.mcap'), '--junit', str(out), '--junit-file-line']) == 0
    xmlschema.XMLSchema(str(FIXTURES / 'junit.xsd')).validate(str(out))
    assert not xmlschema.XMLSchema(str(FIXTURES / 'junit-10.xsd')).is_valid(str(out))
    source = (scenarios / 'rover_multi.yaml').read_text().splitlines()
    for case in ElementTree.parse(out).getroot().iter('testcase'):
        assert case.get('file') == str(scenarios / 'rover_multi.yaml')
        assert f"id: {case.get('name')}" in source[int(case.get('line')) - 1]


def test_junit_of_a_run_that_cannot_start(tmp_path, scenarios, capsys):
    """Exit 2 still writes the JUnit file: one testcase with an error saying why, in the same schema."""
    scenario = scenarios / 'rover_multi.yaml'
    missing = tmp_path / 'missing.mcap'
    assert main(['run', str(scenario), str(missing), '-o', str(tmp_path / 'o.mcap'),
                 '--junit', str(tmp_path / 'r.xml')]) == 2
    reason = capsys.readouterr().err.strip().removeprefix('bagfault: error: ')
    valid_everywhere(tmp_path / 'r.xml')
    [case] = ElementTree.parse(tmp_path / 'r.xml').getroot().iter('testcase')
    error = case.find('error')
    assert (error.text, error.get('message')) == (f'{scenario}: {reason}', reason) and str(missing) in reason
    assert sorted(p.name for p in tmp_path.iterdir()) == ['r.xml']   # nothing else written
    # --junit naming the scenario itself is the problem: it is reported and the scenario is left as it was
    before = scenario.read_bytes()
    assert main(['run', str(scenario), str(FIXTURES / 'rover_20s.mcap'), '-o', str(tmp_path / 'p.mcap'),
                 '--junit', str(scenario)]) == 2
    assert scenario.read_bytes() == before and 'would replace' in capsys.readouterr().err


def test_markdown_report(reports):
    _, folder = reports
    text = (folder / 'r.md').read_text()
    assert text.startswith('# bagfault report: rover_multi.yaml')
    assert '**PASSED**: 6 passed, 0 failed' in text
    assert '| 5.000 | odom_position_bias | odom | active | scheduled | `config={x_bias=1.0, y_bias=-0.25}` |' in text
    assert '| PASS | odom_yaw_bias_activates | fault_event | 5.000 |' in text


def test_html_renders_in_headless_chromium_with_its_plots(reports, tmp_path):
    _, folder = reports
    page = folder / 'r.html'
    body = rendered(page, tmp_path / 'profile')
    drawn = figures(page)
    assert body['errors'] == '0' and int(body['figures']) == len(drawn) >= 5
    assert {'timeline', 'rates', 'field:/odom:pose.pose.position.x'} <= set(drawn)
    field = drawn['field:/odom:pose.pose.position.x']
    before, after, difference = field['data']
    # odom_position_bias adds x_bias 1.0 while active: the difference is 1.0 inside its window, 0 outside
    window = next(s for s in field['layout']['shapes'] if s['name'] == 'odom_position_bias')
    inside = [d for t, d in zip(difference['x'], difference['y'], strict=True) if window['x0'] < t < window['x1']]
    outside = [d for t, d in zip(difference['x'], difference['y'], strict=True)
               if t < window['x0'] - 0.2 or t > window['x1'] + 0.2]
    assert inside and all(abs(d - 1.0) < 1e-6 for d in inside) and all(abs(d) < 1e-6 for d in outside)
    html = page.read_text()
    assert '<script src' not in html and 'https://' not in html.split('<body')[1]


def test_check_on_the_recording_gives_the_same_results(reports, tmp_path, scenarios, capsys):
    _, folder = reports
    code = main(['check', str(scenarios / 'rover_multi.yaml'), str(folder / 'out.mcap'),
                 '--json', str(tmp_path / 'c.json'), '--junit', str(tmp_path / 'c.xml')])
    assert code == 0
    ran = json.loads((folder / 'r.json').read_text())['assertions']
    checked = json.loads((tmp_path / 'c.json').read_text())
    assert checked['mode'] == 'check' and checked['output'] is None
    assert [(a['id'], a['state'], a['t_s']) for a in checked['assertions']] == [
        (a['id'], a['state'], a['t_s']) for a in ran]


def test_check_without_fault_events_fails_with_exit_1(tmp_path, scenarios, capsys):
    code = main(['check', str(scenarios / 'rover_multi.yaml'), str(FIXTURES / 'rover_20s.mcap')])
    out = capsys.readouterr().out
    assert code == 1
    assert 'FAIL  odom_yaw_bias_activates' in out
    assert 'FAIL  odom_stays_above_10hz' in out  # the raw bag has no /odom topic


def test_check_missing_recording_is_exit_2(tmp_path, scenarios, capsys):
    assert main(['check', str(scenarios / 'rover_multi.yaml'), str(tmp_path / 'none.mcap')]) == 2


def test_markdown_folds_fault_updated_events_into_counts():
    """A fault re-reported every 0.1 s for 20 s gives ~200 fault_updated events: counted, not 200 rows."""
    from bagfault.report.markdown import fault_manager_section

    events = ([{'t_s': 1.0, 'event_type': 'fault_confirmed', 'fault_code': 'A', 'status': 'CONFIRMED',
                'auto_cleared_codes': []}]
              + [{'t_s': 1.0 + i / 10, 'event_type': 'fault_updated', 'fault_code': 'A', 'status': 'CONFIRMED',
                  'auto_cleared_codes': []} for i in range(1, 198)]
              + [{'t_s': 30.0, 'event_type': 'fault_cleared', 'fault_code': 'A', 'status': 'CLEARED',
                  'auto_cleared_codes': []}])
    summary = {'confirmed': [], 'muted_count': 0, 'cluster_count': 0, 'faults': [], 'events': events,
               'clusters': [], 'muted': [], 'snapshots': []}
    text = '\n'.join(fault_manager_section(summary))
    assert text.count('| fault_') == 2 and 'fault_updated events (folded): A 197' in text
