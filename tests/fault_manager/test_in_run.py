"""The fault manager inside runs: report sources, /fault_manager/events, snapshots, assertions (medkit semantics
as selfpatch/ros2_medkit has them at commit 505bc2d5)."""

from __future__ import annotations

import json
import textwrap

import pytest
from mcap.reader import make_reader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from support.helpers import NS, make_bag

from bagfault import api
from bagfault.cli import main
from bagfault.demo import synthetic
from bagfault.scenario import ScenarioError, parse_scenario

START = synthetic.DEFAULT_START
DIAG = 'diagnostic_msgs/msg/DiagnosticArray'


def diagnostics_bag(path, error_from: float, duration: float = 10.0):
    """/imu 50 Hz and /diagnostics 10 Hz; the IMU monitor reports ERROR from `error_from` s on."""
    ts = synthetic.store()
    T = ts.types
    imu = synthetic.Stream('/imu', 'sensor_msgs/msg/Imu', 50.0)
    diag = synthetic.Stream('/diagnostics', DIAG, 10.0)

    def records():
        items = [(t, 0, imu, synthetic.imu(ts, t, (t - START) / NS)) for t in synthetic.sample_times(50.0, duration)]
        for t in synthetic.sample_times(10.0, duration):
            error = (t - START) / NS >= error_from - 1e-9
            status = T['diagnostic_msgs/msg/DiagnosticStatus'](
                level=2 if error else 0, name='imu_monitor: drift', message='gyro drift' if error else 'ok',
                hardware_id='imu0', values=[])
            header = T['std_msgs/msg/Header'](stamp=T['builtin_interfaces/msg/Time'](sec=t // NS, nanosec=t % NS),
                                              frame_id='')
            items.append((t, 1, diag, T[DIAG](header=header, status=[status])))
        for t, _, stream, message in sorted(items, key=lambda x: (x[0], x[1])):
            yield stream, t, message

    synthetic.write_mcap(path, records())
    return path


def scenario(within: float) -> str:
    return textwrap.dedent(f"""
        injector: {{id: imu, type: imu, input_topic: /imu, output_topic: /imu_out}}
        faults:
          - {{id: imu_bias, injector_id: imu, start: 5.0, duration: 3.0, config: {{angular_velocity_z_bias: 0.3}}}}
        fault_manager:
          diagnostics: {{codes: {{'imu_monitor: drift': IMU_DRIFT}}}}
        assertions:
          - {{id: detected, type: fault_status, code: IMU_DRIFT, status: CONFIRMED, after: imu_bias, within: {within}}}
          - {{id: one_fault, type: fault_count, min: 1, max: 1}}
    """)


@pytest.fixture(scope='module')
def bag(tmp_path_factory):
    return diagnostics_bag(tmp_path_factory.mktemp('diag') / 'in.mcap', error_from=5.8)


def test_detected_within_one_second_passes(tmp_path, bag):
    result = api.run(parse_scenario(scenario(1.0)), [bag], tmp_path / 'out.mcap')
    detected = {a.id: a for a in result.assertions}['detected']
    assert detected.state == 'passed' and detected.time == START + 5_800_000_000
    assert detected.message == 'IMU_DRIFT reached CONFIRMED at 5.800 s, 0.800 s after imu_bias activated'
    assert {a.id: a.state for a in result.assertions}['one_fault'] == 'passed'


def test_detected_within_half_a_second_fails(tmp_path, bag):
    result = api.run(parse_scenario(scenario(0.5)), [bag], tmp_path / 'out.mcap')
    detected = {a.id: a for a in result.assertions}['detected']
    assert detected.state == 'failed' and detected.time == START + 5_500_000_000
    assert detected.message == ('IMU_DRIFT did not reach CONFIRMED within 0.5 s after imu_bias activated at '
                                '5.000 s (never reported)')


def test_fault_manager_events_decode_with_only_the_files_definitions(tmp_path, bag):
    api.run(parse_scenario(scenario(1.0)), [bag], tmp_path / 'out.mcap')
    with (tmp_path / 'out.mcap').open('rb') as handle:
        reader = make_reader(handle)
        rows = list(reader.iter_messages(topics=['/fault_manager/events']))
    schema = rows[0][0]
    assert schema.name == 'ros2_medkit_msgs/msg/FaultEvent'
    store = get_typestore(Stores.EMPTY)
    store.register(get_types_from_msg(schema.data.decode(), schema.name))
    events = [(m.log_time, store.deserialize_cdr(m.data, schema.name)) for _, _, m in rows]
    time, first = events[0]
    assert (first.event_type, first.fault.fault_code, first.fault.status, first.fault.severity) == (
        'fault_confirmed', 'IMU_DRIFT', 'CONFIRMED', 2)
    assert time == START + 5_800_000_000 == first.timestamp.sec * NS + first.timestamp.nanosec
    assert first.fault.reporting_sources == ['/diagnostics/imu0'] and first.fault.occurrence_count == 1
    assert {e.event_type for _, e in events[1:]} == {'fault_updated'}  # every later ERROR report


def test_injected_fault_report_with_period_and_healing(tmp_path, bag):
    text = textwrap.dedent("""
        injector: {id: imu, type: imu, input_topic: /imu, output_topic: /imu_out}
        faults:
          - id: imu_bias
            injector_id: imu
            start: 2.0
            duration: 3.0
            config: {angular_velocity_z_bias: 0.3}
            report: {code: IMU_BIAS, severity: WARN, report_period: 0.5}
        fault_manager: {confirmation_threshold: -3, healing_enabled: true, healing_threshold: 2}
        assertions:
          - {id: confirmed, type: fault_status, code: IMU_BIAS, status: CONFIRMED, after: imu_bias, within: 1.1}
          - {id: healed, type: fault_status, code: IMU_BIAS, status: HEALED, within: 6.1}
          - {id: never_cleared, type: fault_status, code: IMU_BIAS, status: CLEARED, never: true}
    """)
    result = api.run(parse_scenario(text), [bag], tmp_path / 'out.mcap')
    states = {a.id: (a.state, round((a.time - START) / NS, 3)) for a in result.assertions}
    # FAILED at 2.0, 2.5, 3.0 -> counter -3, CONFIRMED at 3.0 (clamped at -3 by later FAILED reports);
    # PASSED from 5.0 every 0.5 s: -2, -1, 0, 1, 2 -> HEALED at 7.0
    assert states == {'confirmed': ('passed', 3.0), 'healed': ('failed', 6.1), 'never_cleared': ('passed', 9.98)}
    faults = {f['fault_code']: f for f in result.fault_manager['faults']}
    assert faults['IMU_BIAS']['status'] == 'HEALED' and faults['IMU_BIAS']['severity'] == 'WARN'
    events = [(e['t_s'], e['event_type'], e['status']) for e in result.fault_manager['events']]
    assert events[0] == (3.0, 'fault_confirmed', 'CONFIRMED')
    assert (7.0, 'fault_cleared', 'HEALED') in events and (6.5, 'fault_updated', 'CONFIRMED') in events


def test_condition_source_and_black_box(tmp_path):
    bag = make_bag(tmp_path / 'in.mcap', [('/imu', 'sensor_msgs/msg/Imu', 50.0), ('/odom', 'nav_msgs/msg/Odometry',
                                                                                  10.0)], 8.0)
    text = textwrap.dedent("""
        injector: {id: imu, type: imu, input_topic: /imu, output_topic: /imu_out}
        faults:
          - {id: spike, injector_id: imu, start: 3.0, duration: 1.0, config: {linear_acceleration_z_bias: 10.0}}
        fault_manager:
          conditions:
            - {topic: /imu_out, when: {field: linear_acceleration.z, above: 15.0}, code: IMU_SPIKE, severity: ERROR}
          snapshots: {default_topics: [/odom, /imu_out], duration_sec: 1.0, duration_after_sec: 0.5}
        assertions:
          - {id: spike_seen, type: fault_status, code: IMU_SPIKE, status: CONFIRMED, after: spike, within: 0.1}
    """)
    out = tmp_path / 'out.mcap'
    assert main(['run', str(_write(tmp_path, text)), str(bag), '-o', str(out), '--json', str(tmp_path / 'r.json'),
                 '--report', str(tmp_path / 'r.md')]) == 0
    report = json.loads((tmp_path / 'r.json').read_text())
    [snapshot] = report['fault_manager']['snapshots']
    assert snapshot['fault_code'] == 'IMU_SPIKE' and snapshot['t_s'] == 3.0
    frame = snapshot['freeze_frame']
    assert frame['/imu_out']['message']['linear_acceleration']['z'] == pytest.approx(19.81)
    assert frame['/odom']['log_time_ns'] == START + 2_900_000_000  # /odom at 3.0 s comes after /imu_out at 3.0 s
    box = tmp_path / 'out.blackbox.IMU_SPIKE.1.mcap'
    assert snapshot['black_box'] == str(box) and box.exists()
    with box.open('rb') as handle:
        rows = [(c.topic, m.log_time) for _, c, m in make_reader(handle).iter_messages()]
    imu_times = [t for topic, t in rows if topic == '/imu_out']
    assert min(imu_times) == START + 2 * NS and max(imu_times) == START + 3_500_000_000
    assert len(imu_times) == 76 and len([t for topic, t in rows if topic == '/odom']) == 16
    markdown = (tmp_path / 'r.md').read_text()
    assert '## Fault manager' in markdown and '| IMU_SPIKE | ERROR | HEALED' not in markdown
    assert '| IMU_SPIKE | ERROR | CONFIRMED |' in markdown and 'out.blackbox.IMU_SPIKE.1.mcap' in markdown


def _write(folder, text):
    path = folder / 'scenario.yaml'
    path.write_text(text)
    return path


def test_correlation_and_clear_in_a_run(tmp_path, bag):
    text = textwrap.dedent("""
        injector: {id: imu, type: imu, input_topic: /imu, output_topic: /imu_out}
        faults:
          - {id: estop, injector_id: imu, start: 1.0, duration: 1.0, config: {angular_velocity_z_bias: 1},
             report: {code: ESTOP_001, severity: CRITICAL, report_period: 10}}
          - {id: motor, injector_id: imu, start: 1.2, duration: 1.0, config: {angular_velocity_z_bias: 1},
             report: {code: MOTOR_COMM_FL, report_period: 10}}
          - {id: late, injector_id: imu, start: 3.0, duration: 1.0, config: {angular_velocity_z_bias: 1},
             report: {code: MOTOR_LATE, report_period: 10}}
        fault_manager:
          correlation:
            enabled: true
            rules:
              - {id: estop, root_cause: {codes: [ESTOP_001]}, symptoms: [{codes: ['MOTOR_*']}], window_ms: 500}
          clear: [{code: ESTOP_001, at: 5.0}]
        assertions:
          - {id: count, type: fault_count, min: 1, max: 1, exclude_muted: true}
    """)
    result = api.run(parse_scenario(text), [bag], tmp_path / 'out.mcap')
    summary = result.fault_manager
    assert {f['fault_code']: f['status'] for f in summary['faults']} == {
        'ESTOP_001': 'CLEARED', 'MOTOR_COMM_FL': 'CLEARED', 'MOTOR_LATE': 'CONFIRMED'}
    cleared = [e for e in summary['events'] if e['event_type'] == 'fault_cleared']
    assert cleared == [{'t_s': 5.0, 'event_type': 'fault_cleared', 'fault_code': 'ESTOP_001', 'status': 'CLEARED',
                        'auto_cleared_codes': ['MOTOR_COMM_FL']}]
    assert [e['fault_code'] for e in summary['events'] if e['event_type'] == 'fault_confirmed'] == [
        'ESTOP_001', 'MOTOR_LATE']
    assert result.assertions[0].state == 'passed'


@pytest.mark.parametrize(('section', 'problem'), [
    ("fault_manager: {diagnostics: {codes: {a: 'bad code'}}}", "'bad code' is not a fault code"),
    ('fault_manager: {conditions: [{topic: /imu, when: {field: x}}]}', 'give exactly one of above'),
    ('fault_manager: {bogus: 1}', "unknown fault_manager key 'bogus'"),
])
def test_fault_manager_section_is_validated(section, problem):
    text = 'injector: {id: i, type: imu, input_topic: /a, output_topic: /b}\n' + section + '\n'
    with pytest.raises(ScenarioError, match=problem.replace('(', r'\(')):
        parse_scenario(text)


def test_an_invalid_snapshot_regex_is_ignored_with_a_warning_as_medkit_ignores_it():
    """medkit snapshot_capture.cpp: an invalid regex in the snapshot config is logged and IGNORED; the other
    patterns still apply. Under --strict the warning is an error."""
    text = ('injector: {id: i, type: imu, input_topic: /a, output_topic: /b}\n'
            'fault_manager: {snapshots: {patterns: [{match: "(", topics: [/x]}, {match: "IMU_.*", topics: [/a]}]}}\n')
    scenario = parse_scenario(text)
    assert any("invalid regular expression '('" in w and 'ignored, as medkit ignores it' in w for w in scenario.warnings)
    assert scenario.fault_manager_config.snapshots.topics_for('IMU_DRIFT') == ('/a',)
    with pytest.raises(ScenarioError, match='invalid regular expression'):
        parse_scenario(text, strict=True)


def test_a_catastrophic_snapshot_regex_matches_in_linear_time():
    """(a+)+$ against 'aaaa...b' takes exponential time in a backtracking engine (Python's re needs minutes at
    30 characters); RE2 answers at once, so a scenario cannot hang a run through its snapshot patterns."""
    text = ('injector: {id: i, type: imu, input_topic: /a, output_topic: /b}\n'
            'fault_manager: {snapshots: {patterns: {"(A+)+$": [/x]}}}\n')
    snapshots = parse_scenario(text).fault_manager_config.snapshots
    assert snapshots.topics_for('A' * 5000 + 'B') == ()  # no match: the defaults (none here)
    assert snapshots.topics_for('AAAA') == ('/x',)


def test_report_block_is_validated():
    with pytest.raises(ScenarioError, match="'LOUD' is not INFO, WARN, ERROR, CRITICAL"):
        parse_scenario('injector: {id: i, type: imu, input_topic: /a, output_topic: /b}\n'
                       'faults: [{id: f, injector_id: i, config: {}, report: {code: X, severity: LOUD}}]\n')


def test_failed_run_leaves_no_black_box(tmp_path):
    bag = make_bag(tmp_path / 'in.mcap', [('/imu', 'sensor_msgs/msg/Imu', 200.0)], 30.0)
    data = bytearray(bag.read_bytes())
    data[len(data) * 3 // 4: len(data) * 3 // 4 + 5000] = bytes(5000)
    bag.write_bytes(bytes(data))
    text = textwrap.dedent("""
        injector: {id: imu, type: imu, input_topic: /imu, output_topic: /imu_out}
        faults: [{id: spike, injector_id: imu, start: 1.0, config: {linear_acceleration_z_bias: 10.0}}]
        fault_manager:
          conditions: [{topic: /imu_out, when: {field: linear_acceleration.z, above: 15.0}, code: SPIKE}]
          snapshots: {default_topics: [/imu_out], duration_sec: 0.2, duration_after_sec: 0.1}
    """)
    assert main(['run', str(_write(tmp_path, text)), str(bag), '-o', str(tmp_path / 'out.mcap')]) == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ['in.mcap', 'scenario.yaml']


def test_a_status_that_held_before_the_trigger_is_no_detection(tmp_path):
    """IMU_DRIFT is CONFIRMED from the first ERROR report at 2.0 s (10 Hz diagnostics, confirmation at the first
    FAILED by default); imu_bias activates at 5.0 s. Nothing was detected after the fault: the assertion fails
    at 5.0 s naming the earlier time, where it used to pass with '0.000 s after'."""
    early = diagnostics_bag(tmp_path / 'early.mcap', error_from=2.0)
    result = api.run(parse_scenario(scenario(1.0)), [early], tmp_path / 'out.mcap')
    detected = {a.id: a for a in result.assertions}['detected']
    assert detected.state == 'failed' and detected.time == START + 5_000_000_000
    assert detected.message == 'IMU_DRIFT was already CONFIRMED at 2.000 s, before imu_bias activated at 5.000 s'


BLACK_BOX_SCENARIO = """
injector: {id: imu, type: imu, input_topic: /imu, output_topic: /imu_out}
faults:
  - {id: spike, injector_id: imu, start: 1.0, duration: 1.0, config: {linear_acceleration_z_bias: 10.0}}
fault_manager:
  conditions:
    - {topic: /imu_out, when: {field: linear_acceleration.z, above: 15.0}, code: IMU_SPIKE}
  snapshots: {default_topics: [/imu_out], duration_sec: 0.5, duration_after_sec: 0.2}
"""


def test_a_black_box_never_replaces_a_file_bagfault_did_not_write(tmp_path, capsys):
    """The black box of `-o out.mcap` is out.blackbox.IMU_SPIKE.1.mcap: an input of that name (or anyone's file)
    is not replaced; the run stops with one line and writes nothing. A black box of an earlier run is replaced."""
    bag = make_bag(tmp_path / 'out.blackbox.IMU_SPIKE.1.mcap', [('/imu', 'sensor_msgs/msg/Imu', 50.0)], 3.0)
    before = bag.read_bytes()
    scenario = _write(tmp_path, BLACK_BOX_SCENARIO)
    assert main(['run', str(scenario), str(bag), '-o', str(tmp_path / 'out.mcap')]) == 2
    error = capsys.readouterr().err.strip()
    assert error.count('\n') == 0 and 'a black box of' in error and 'would replace the input' in error
    assert bag.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ['out.blackbox.IMU_SPIKE.1.mcap', 'scenario.yaml']
    moved = bag.rename(tmp_path / 'in.mcap')
    foreign = tmp_path / 'out.blackbox.IMU_SPIKE.1.mcap'
    foreign.write_bytes(b'someone else\n')
    assert main(['run', str(scenario), str(moved), '-o', str(tmp_path / 'out.mcap')]) == 2
    error = capsys.readouterr().err.strip()
    assert error.count('\n') == 0 and 'bagfault did not write it' in error and '--force' in error
    assert foreign.read_bytes() == b'someone else\n' and not (tmp_path / 'out.mcap').exists()
    foreign.unlink()
    for _ in range(2):  # the second run replaces the first run's black box, which bagfault wrote
        assert main(['run', str(scenario), str(moved), '-o', str(tmp_path / 'out.mcap')]) == 0
    assert (tmp_path / 'out.blackbox.IMU_SPIKE.1.mcap').exists()


def test_a_report_named_like_a_black_box_is_refused_before_the_run(tmp_path, capsys):
    """`--json out.blackbox.IMU_SPIKE.1.mcap` would be overwritten by (or overwrite) the black box the run writes:
    refused in one line before anything is written."""
    bag = make_bag(tmp_path / 'in.mcap', [('/imu', 'sensor_msgs/msg/Imu', 50.0)], 3.0)
    scenario = _write(tmp_path, BLACK_BOX_SCENARIO)
    report = tmp_path / 'out.blackbox.OTHER.7.mcap'
    assert main(['run', str(scenario), str(bag), '-o', str(tmp_path / 'out.mcap'), '--json', str(report)]) == 2
    error = capsys.readouterr().err.strip()
    assert error.count('\n') == 0 and 'black box' in error and str(report) in error
    assert sorted(p.name for p in tmp_path.iterdir()) == ['in.mcap', 'scenario.yaml']
    fine = tmp_path / 'out.blackbox.json'
    assert main(['run', str(scenario), str(bag), '-o', str(tmp_path / 'out.mcap'), '--json', str(fine)]) == 0
    assert fine.exists()
