"""Every assertion type passes where it should and fails with the time and the observed value."""

from __future__ import annotations

import json
import textwrap

import pytest
from support.helpers import FIXTURES, NS, make_bag, run_inline

from bagfault import api
from bagfault.demo.synthetic import DEFAULT_START as START
from bagfault.errors import AssertionSetupError
from bagfault.report.model import build
from bagfault.scenario import ScenarioError, parse_scenario

BASE = textwrap.dedent("""
    injectors:
      - {id: odom, type: odom, input_topic: /odom_raw, output_topic: /odom}
      - {id: scan, type: scan, input_topic: /scan_raw, output_topic: /scan}
      - {id: imu, type: imu, input_topic: /sensors/imu_raw, output_topic: /sensors/imu}
    faults:
      - {id: odom_drift, injector_id: odom, start: 5.0, duration: 10.0, config: {x_bias: 0.5}}
      - {id: lidar_blind, injector_id: scan, start: 8.0, duration: 2.0,
         config: {sector_min_deg: -30.5, sector_max_deg: 30.5, sector_value: inf}}
      - {id: lidar_dead, injector_id: scan, config: {drop_probability: 1.0}}
      - {id: imu_late, injector_id: imu, start: 12.0, duration: 4.0, config: {delay_ms: 250}}
    assertions:
""")


def run(tmp_path, assertions: str, **kw):
    scenario = parse_scenario(BASE + textwrap.indent(textwrap.dedent(assertions), '  '))
    result = api.run(scenario, [FIXTURES / 'rover_20s.mcap'], tmp_path / 'out.mcap', **kw)
    return {r.id: r for r in result.assertions}, result


def seconds(result, run_result):
    return round((result.time - run_result.stats.origin) / 1e9, 3)


def test_topic_gap(tmp_path):
    results, out = run(tmp_path, """
        - {id: ok, type: topic_gap, topic: /scan_raw, max_gap: 0.15}
        - {id: silent, type: topic_gap, topic: /scan, max_gap: 0.5}
        - {id: silent_during, type: topic_gap, topic: /scan, max_gap: 0.5, during: lidar_dead}
        - {id: odom_fine, type: topic_gap, topic: /odom, max_gap: 0.05, during: odom_drift}
        - {id: not_active, type: topic_gap, topic: /odom, max_gap: 0.05, during: imu_late}
    """, activate=['lidar_dead@8+2'])
    assert results['ok'].state == 'passed' and 'longest gap on /scan_raw 0.100 s' in results['ok'].message
    assert results['silent'].state == 'failed' and seconds(results['silent'], out) == 10.0
    assert results['silent'].message == ('gap of 2.100 s on /scan from 7.900 s to 10.000 s exceeds max_gap 0.5 s')
    assert results['silent_during'].state == 'failed' and seconds(results['silent_during'], out) == 10.0
    assert results['silent_during'].message.startswith('gap of 2.000 s on /scan from 8.000 s to 10.000 s (until lidar_dead')
    assert results['odom_fine'].state == 'passed'
    assert results['not_active'].state == 'passed'


def test_topic_gap_catches_a_sensor_that_stops(tmp_path):
    results, out = run(tmp_path, """
        - {id: end, type: topic_gap, topic: /scan, max_gap: 0.5}
    """, activate=['lidar_dead@19'])
    assert results['end'].state == 'failed'
    assert results['end'].message == 'gap of 1.090 s on /scan from 18.900 s to 19.990 s (end of the bag) exceeds max_gap 0.5 s'


def test_field_range(tmp_path):
    results, out = run(tmp_path, """
        - {id: ok, type: field_range, topic: /odom, field: pose.pose.position.x, min: -0.001, max: 2.0, outside: odom_drift}
        - {id: high, type: field_range, topic: /odom, field: pose.pose.position.x, max: 1.0, during: odom_drift}
        - {id: finite, type: field_range, topic: /scan, field: 'ranges[*]', finite: true, during: lidar_blind}
        - {id: finite_ok, type: field_range, topic: /sensors/imu, field: linear_acceleration.z, finite: true, min: 9.8, max: 9.82}
    """)
    assert results['ok'].state == 'passed' and results['ok'].message.startswith('500 messages on /odom outside odom_drift')
    assert results['high'].state == 'failed' and seconds(results['high'], out) == 5.02
    assert results['high'].message == 'at 5.020 s /odom pose.pose.position.x = 1.002 is outside [-inf, 1]'
    assert results['finite'].state == 'failed' and seconds(results['finite'], out) == 8.0
    assert results['finite'].message == 'at 8.000 s /scan ranges[*] (element 0) = inf is outside finite values'
    assert results['finite_ok'].state == 'passed'


def test_field_delta(tmp_path):
    results, out = run(tmp_path, """
        - {id: applied, type: field_delta, topic: /odom, field: pose.pose.position.x, equals: 0.5, otherwise: 0.0,
           during: odom_drift, tolerance: 1.0e-12}
        - {id: wrong, type: field_delta, topic: /odom, field: pose.pose.position.x, equals: 0.4, during: odom_drift}
        - {id: untouched, type: field_delta, topic: /odom, field: pose.pose.position.y, equals: 0.0}
        - {id: delayed_same_values, type: field_delta, topic: /sensors/imu, field: angular_velocity.z, equals: 0.0}
    """)
    assert results['applied'].state == 'passed'
    assert results['applied'].message.startswith('1000 message pairs /odom_raw -> /odom')
    assert results['wrong'].state == 'failed' and seconds(results['wrong'], out) == 5.0
    assert results['wrong'].message == ('at 5.000 s pose.pose.position.x changed by 0.5, expected 0.4 +- 1e-09 '
                                        'during odom_drift')
    assert results['untouched'].state == 'passed'
    # pairs are matched by header stamp, so the 250 ms delay does not break them
    assert results['delayed_same_values'].state == 'passed' and '2000 message pairs' in results['delayed_same_values'].message


def test_message_count(tmp_path):
    results, out = run(tmp_path, """
        - {id: exact, type: message_count, topic: /sensors/imu_raw, min: 400, max: 400, during: imu_late}
        - {id: too_many, type: message_count, topic: /sensors/imu_raw, max: 399, during: imu_late}
        - {id: too_few, type: message_count, topic: /scan, min: 200}
        - {id: all, type: message_count, topic: /odom, min: 1000, max: 1000}
    """, activate=['lidar_dead@8+2'])
    assert results['exact'].state == 'passed'
    assert results['too_many'].state == 'failed' and seconds(results['too_many'], out) == 15.99
    assert results['too_many'].message == '/sensors/imu_raw during imu_late: message 400 at 15.990 s is more than max 399'
    assert results['too_few'].state == 'failed'
    assert results['too_few'].message == '/scan: 180 messages by the end of the bag at 19.990 s, expected at least 200'
    assert results['all'].state == 'passed'


def test_sequence(tmp_path):
    results, out = run(tmp_path, """
        - {id: odom_on, type: fault_event, fault_id: odom_drift, state: active}
        - {id: lidar_on, type: fault_event, fault_id: lidar_blind, state: active}
        - {id: odom_off, type: fault_event, fault_id: odom_drift, state: inactive}
        - {id: in_order, type: sequence, steps: [odom_on, lidar_on, odom_off]}
        - {id: reversed, type: sequence, steps: [lidar_on, odom_on]}
        - {id: too_slow, type: sequence, steps: [odom_on, odom_off], within: 10.0}
    """)
    assert results['in_order'].state == 'passed' and seconds(results['in_order'], out) == 15.0
    assert results['reversed'].state == 'failed' and seconds(results['reversed'], out) == 5.0
    assert results['reversed'].message == 'step odom_on passed at 5.000 s before step lidar_on'
    assert results['too_slow'].state == 'failed' and seconds(results['too_slow'], out) == 10.0


def test_topic_hz_of_another_type_counts_nothing_as_the_anchor_does(tmp_path):
    """The anchor subscribes with message_type: a topic of another type brings it no message, so it fails at its
    first look after `within` (at the end without one), as for a silent topic; the message says why."""
    results, out = run(tmp_path, """
        - {id: wrong, type: topic_hz, topic: /odom, message_type: sensor_msgs/msg/Imu, min_hz: 1.0, window: 1.0}
        - {id: wrong_within, type: topic_hz, topic: /odom, message_type: sensor_msgs/msg/Imu, min_hz: 1.0, window: 1.0,
           within: 2.0}
        - {id: missing, type: topic_hz, topic: /nothing, message_type: sensor_msgs/msg/Imu, min_hz: 1.0, window: 1.0}
    """)
    assert results['wrong'].state == 'failed' and seconds(results['wrong'], out) == 19.99  # the last message
    assert results['wrong'].message == ('/odom did not reach 1 Hz (best 0.00 Hz over 1 s, none of type '
                                        'sensor_msgs/msg/Imu (it carries nav_msgs/msg/Odometry)): not observed before '
                                        'the end of the bag')
    assert results['wrong_within'].state == 'failed' and seconds(results['wrong_within'], out) == 2.1
    assert results['missing'].message == ('/nothing did not reach 1 Hz (best 0.00 Hz over 1 s): '
                                          'not observed before the end of the bag')


def odometry_at(path, seconds):
    """A bag of /odom (nav_msgs/Odometry) messages at these seconds of bag time."""
    from bagfault.demo import synthetic

    stream = synthetic.Stream('/odom', 'nav_msgs/msg/Odometry', 1.0)
    ts = synthetic.store()
    synthetic.write_mcap(path, [(stream, START + round(t * NS), synthetic.odometry(ts, START + round(t * NS), t))
                                for t in seconds], ts)
    return path


def hz_verdict(tmp_path, seconds, min_hz, window, within=None):
    bag = odometry_at(tmp_path / 'odom.mcap', seconds)
    deadline = '' if within is None else f', within: {within}'
    _, result = run_inline(tmp_path, f"""
        injectors: []
        assertions:
          - {{id: hz, type: topic_hz, topic: /odom, message_type: nav_msgs/msg/Odometry, min_hz: {min_hz},
             window: {window}{deadline}}}
    """, bag)
    [hz] = result.assertions
    return hz.state, round((hz.time - START) / NS, 3)


def test_topic_hz_keeps_a_message_exactly_window_old(tmp_path):
    """topic_hz_assertion.cpp drops a message only when its age is *more* than window: messages at 0.1 s and 1.05 s
    make 2 Hz over 1 s at the 1.1 s look (0.1 s is exactly 1 s old there)."""
    assert hz_verdict(tmp_path, [0.1, 1.05, 4.0], min_hz=2.0, window=1.0) == ('passed', 1.1)


# ros2_fault_injection's own tests of topic_hz (test/assertions/test_topic_hz_assertion.cpp), by name: their
# update(elapsed, now) calls are bagfault's looks every 100 ms of bag time
def test_anchor_PassesWhenObservedRateMeetsMinimum(tmp_path):
    """12 messages 80 ms apart; min 10 Hz over 1 s: 9 by the 0.7 s look, 11 by 0.8 s (the 11th at exactly 0.8 s)."""
    assert hz_verdict(tmp_path, [i * 0.08 for i in range(12)] + [3.0], 10.0, 1.0, within=2.0) == ('passed', 0.8)


def test_anchor_StaysPendingBeforeDeadlineWhenRateTooLow(tmp_path):
    """Messages at 0 and 0.5 s, min 20 Hz, within 5 s: still pending at 2 s (decided only at 5.1 s, failed)."""
    assert hz_verdict(tmp_path, [0.0, 0.5, 6.0], 20.0, 1.0, within=5.0) == ('failed', 5.1)


def test_anchor_FailsAfterDeadlineWhenRateTooLow(tmp_path):
    """Messages at 0 and 1 s, min 10 Hz, within 2 s: failed at the first look after 2 s."""
    assert hz_verdict(tmp_path, [0.0, 1.0, 3.0], 10.0, 1.0, within=2.0) == ('failed', 2.1)


def test_anchor_IgnoresOldMessagesOutsideWindow(tmp_path):
    """Messages at 0, 0.1 and 3 s, min 3 Hz over 1 s: at 3 s the first two are 3 and 2.9 s old, gone; 1 Hz."""
    assert hz_verdict(tmp_path, [0.0, 0.1, 3.0, 3.05], 3.0, 1.0, within=5.0) == ('failed', 3.05)


@pytest.mark.parametrize(('assertion', 'problem'), [
    ('{id: a, type: field_range, topic: /odom, field: x}', "give 'min', 'max' or 'finite: true'"),
    ('{id: a, type: field_range, topic: /odom, field: x, min: 2, max: 1}', '1.0 is below min 2.0'),
    ('{id: a, type: topic_gap, topic: /odom, max_gap: 1, within: 3}', 'within does not apply'),
    ('{id: a, type: message_count, topic: /odom, during: ghost, min: 1}', "unknown fault 'ghost'"),
    ('{id: a, type: sequence, steps: [a, b]}', 'a sequence cannot contain itself'),
    ('{id: a, type: field_delta, topic: /nowhere, field: x, equals: 1}', 'no injector writes /nowhere'),
    ('{id: a, type: topic_gap, topic: /odom, max_gap: 0}', 'must be greater than 0'),
])
def test_assertion_fields_are_validated(assertion, problem):
    with pytest.raises(ScenarioError) as info:
        parse_scenario(BASE + '  - ' + assertion + '\n')
    assert problem in str(info.value)


def test_bad_field_path_stops_the_run_naming_the_closest_path(tmp_path):
    with pytest.raises(AssertionSetupError) as info:
        run(tmp_path, '- {id: a, type: field_range, topic: /odom, field: pose.pose.postion.x, max: 1}\n')
    text = str(info.value)
    assert "'pose.pose.postion.x' is not a field of nav_msgs/msg/Odometry" in text
    assert 'closest valid path: pose.pose.position.x' in text
    assert not (tmp_path / 'out.mcap').exists()


@pytest.mark.parametrize(('min_hz', 'state', 'at'), [(50.3, 'passed', 3.0), (50.4, 'failed', 8.1)])
def test_topic_hz_looks_every_100_ms_as_the_anchor_does(tmp_path, min_hz, state, at):
    """At a look (every 100 ms, on the 20 ms grid) a 50 Hz topic holds 151 messages in [t - 3, t] (both ends kept,
    as the anchor keeps an age of exactly window): 50.33 Hz, never 50.4 (anchor runner, 100 ms timer)."""
    bag = make_bag(tmp_path / 'odom.mcap', [('/odom', 'nav_msgs/msg/Odometry', 50.0)], 20.0)
    text = (f'injectors: []\nassertions:\n  - {{id: hz, type: topic_hz, topic: /odom, message_type: nav_msgs/msg/Odometry, '
            f'min_hz: {min_hz}, window: 3.0, within: 8.0}}\n')
    _, result = run_inline(tmp_path, text, bag)
    [hz] = result.assertions
    assert (hz.state, (hz.time - START) / NS) == (state, at)  # failed at the first look after within (8.0 s)


@pytest.mark.parametrize(('start', 'state', 'decided'), [
    (1.05, 'passed', 1.05),  # after within (1.0) but before the look at 1.1 s: the anchor passes it
    (1.0, 'passed', 1.0),
    (1.15, 'failed', 1.1),   # the look at 1.1 s finds elapsed 1.1 > within
])
def test_fault_event_within_is_judged_at_the_anchors_100_ms_looks(tmp_path, start, state, decided):
    """ros2_fault_injection's fault_assertion_runner.cpp looks every 100 ms of its timer and fails a pending
    fault_event only when elapsed > within (fault_event_assertion.cpp:39-55); an event is observed at once."""
    bag = make_bag(tmp_path / 'in.mcap', [('/imu', 'sensor_msgs/msg/Imu', 100.0)], 3.0)
    _, result = run_inline(tmp_path, f"""
        injector: {{id: imu, type: imu, input_topic: /imu, output_topic: /imu_out}}
        faults:
          - {{id: bias, injector_id: imu, start: {start}, config: {{angular_velocity_z_bias: 0.1}}}}
        assertions:
          - {{id: on_time, type: fault_event, fault_id: bias, state: active, within: 1.0}}
    """, bag)
    [verdict] = result.assertions
    assert (verdict.state, round((verdict.time - START) / NS, 3)) == (state, decided)


# -- margins: how far each assertion was from failing, in its own unit, by hand from the fixture bag --------
# rover_20s.mcap (bagfault.demo.synthetic): /odom_raw every 20 ms with x = 0.1 t, /scan_raw every 100 ms, 200 of
# them; BASE's odom_drift adds 0.5 m to x on [5, 15) s, lidar_blind is active on [8, 10) s.


def test_margins_of_passing_assertions(tmp_path):
    results, _ = run(tmp_path, """
        - {id: gap, type: topic_gap, topic: /scan_raw, max_gap: 0.15}
        - {id: hz, type: topic_hz, topic: /odom_raw, message_type: nav_msgs/msg/Odometry, min_hz: 40, window: 1.0}
        - {id: range, type: field_range, topic: /odom, field: pose.pose.position.x, min: -2.0, max: 3.0}
        - {id: finite, type: field_range, topic: /odom, field: pose.pose.position.x, finite: true}
        - {id: count, type: message_count, topic: /scan_raw, min: 150, max: 250}
        - {id: drift_on, type: fault_event, fault_id: odom_drift, state: active, within: 6.0}
        - {id: blind_on, type: fault_event, fault_id: lidar_blind, state: active}
        - {id: delta, type: field_delta, topic: /odom, field: pose.pose.position.x, equals: 0.5, during: odom_drift,
           tolerance: 0.001}
        - {id: order, type: sequence, steps: [drift_on, blind_on]}
    """)
    margins = {k: (r.state, r.margin, r.margin_unit) for k, r in results.items()}
    # the longest gap is one scan period, 0.1 s: 0.05 s to spare
    assert margins['gap'][:2] == ('passed', pytest.approx(0.05)) and margins['gap'][2] == 's'
    # looks every 100 ms count (t - 1, t]: 36 messages at 0.7 s, 41 at 0.8 s: 41 Hz, 1 Hz above min_hz
    assert margins['hz'] == ('passed', pytest.approx(1.0), 'Hz')
    # the largest x is 0.1 x 14.98 + 0.5 = 1.998 m (0.1 x 19.98 after the drift): 1.002 below max; x = 0 is 2 above min
    assert margins['range'][:2] == ('passed', pytest.approx(1.002))
    assert margins['finite'] == ('passed', None, '')  # finite or not: no distance
    assert margins['count'] == ('passed', 50.0, 'messages')  # 200 scans: 50 from either bound
    assert margins['drift_on'] == ('passed', pytest.approx(1.0), 's')  # active at 5 s, within 6 s
    assert margins['blind_on'] == ('passed', None, '')  # no `within`: no deadline to measure from
    assert margins['delta'][0] == 'passed' and 0.001 - 1e-12 < margins['delta'][1] <= 0.001  # exact bias
    assert margins['order'] == ('passed', pytest.approx(3.0), 's')  # steps at 5 s and 8 s


def test_margins_of_failing_assertions(tmp_path):
    results, _ = run(tmp_path, """
        - {id: gap, type: topic_gap, topic: /scan, max_gap: 0.5}
        - {id: range, type: field_range, topic: /odom, field: pose.pose.position.x, max: 1.25}
        - {id: count, type: message_count, topic: /scan_raw, min: 210}
        - {id: hz, type: topic_hz, topic: /scan_raw, message_type: sensor_msgs/msg/LaserScan, min_hz: 12, window: 1.0}
    """, activate=['lidar_dead@8+2'])
    margins = {k: (r.state, r.margin) for k, r in results.items()}
    assert margins['gap'] == ('failed', pytest.approx(0.5 - 2.1))  # scans at 7.9 s and 10.0 s
    assert margins['range'] == ('failed', pytest.approx(1.25 - 1.252))  # first above (7.5 s is 1.25): 0.1 x 7.52 + 0.5
    assert margins['count'] == ('failed', -10.0)  # 200 of 210
    assert margins['hz'] == ('failed', pytest.approx(11.0 - 12.0))  # at best 11 scans in [t - 1, t]


def test_margins_in_the_json_report(tmp_path):
    scenario = parse_scenario("""
injectors: [{id: odom, type: odom, input_topic: /odom_raw, output_topic: /odom}]
assertions:
  - {id: gap, type: topic_gap, topic: /scan_raw, max_gap: 0.25}
""")
    result = api.run(scenario, [FIXTURES / 'rover_20s.mcap'], tmp_path / 'out.mcap')
    (entry,) = json.loads(json.dumps(build(result)))['assertions']
    assert entry['margin'] == pytest.approx(0.15) and entry['margin_unit'] == 's'
    assert entry['value'] == pytest.approx(0.1) and entry['unit'] == 's'


def test_a_value_that_is_not_finite_leaves_the_json_report_valid(tmp_path):
    """A field_range failing on inf (the blind sector) measured a value JSON cannot hold: the report says null (the
    message keeps inf) and renders as strict JSON, as every report must."""
    from bagfault.report.json_report import render

    results, out = run(tmp_path, """
        - {id: finite, type: field_range, topic: /scan, field: 'ranges[*]', min: 0.0, max: 20.0, during: lidar_blind}
    """)
    assert results['finite'].state == 'failed' and '= inf' in results['finite'].message
    (entry,) = json.loads(render(build(out)))['assertions']
    assert entry['value'] is None and entry['margin'] is None
