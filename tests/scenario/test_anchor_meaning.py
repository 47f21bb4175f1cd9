"""Scenarios of ros2_fault_injection run with the meaning they have there (its C++ at f104e75).

Each test names the anchor source the expected behaviour comes from.
"""

from __future__ import annotations

import math
import textwrap
import time

import numpy as np
import pytest
from support.helpers import NS, decoded, make_bag, raw_messages, run_inline

from bagfault import api
from bagfault.demo.synthetic import DEFAULT_START as START
from bagfault.errors import ScenarioError
from bagfault.scenario import parse_scenario

ODOM = [('/odom_raw', 'nav_msgs/msg/Odometry', 50.0)]


@pytest.fixture(scope='module')
def odom_bag(tmp_path_factory):
    return make_bag(tmp_path_factory.mktemp('odom') / 'odom.mcap', ODOM, 10.0)


def seconds(time):
    return (time - START) / NS


def test_keys_the_anchor_ignores_are_warnings_and_the_run_goes_on(tmp_path, odom_bag):
    """scenario_config.cpp reads only the keys it knows; scenario_validator.cpp warns on unknown config keys."""
    text = textwrap.dedent("""
        name_of_robot: rover          # unknown top-level key
        injector:
          id: odom
          type: odom
          input_topic: /odom_raw
          output_topic: /odom
          launch_prefix: gdb          # unknown injector key
        faults:
          - id: bias
            injector_id: odom
            description: lateral drift  # unknown fault key
            start: "1.0"                # a quoted number, as yaml-cpp's as<double>() reads it
            config: {x_bias: 1.0, wheel_slip: 0.3}
        assertions:
          - {id: on, type: fault_event, fault_id: bias, state: active, within: 2.0, duration: 5.0}
    """)
    out, result = run_inline(tmp_path, text, odom_bag)
    assert [r.state for r in result.assertions] == ['passed']
    assert len(result.warnings) == 4
    assert any("unknown top-level key 'name_of_robot' is ignored" in w for w in result.warnings)
    assert any("injector.launch_prefix: unknown injector key 'launch_prefix' is ignored" in w for w in result.warnings)
    assert any("faults[0].description: unknown fault key 'description' is ignored" in w for w in result.warnings)
    assert any("faults[0].config.wheel_slip: unknown config key 'wheel_slip'" in w for w in result.warnings)
    [event] = [e for e in result.stats.events if e.state == 'active']
    assert seconds(event.time) == 1.0
    assert event.details == 'config={wheel_slip=0.3, x_bias=1.0}'  # describe_config() shows every key as written
    with pytest.raises(ScenarioError) as info:
        parse_scenario(text, strict=True)
    assert len(info.value.problems) == 4


def test_injectors_win_over_injector(tmp_path, odom_bag):
    """scenario_config.cpp: `if (root["injectors"]) ... else if (root["injector"])`."""
    scenario = parse_scenario(textwrap.dedent("""
        injector: {id: old, type: imu, input_topic: /imu_raw, output_topic: /imu}
        injectors:
          - {id: odom, type: odom, input_topic: /odom_raw, output_topic: /odom}
        faults: [{id: bias, injector_id: odom, config: {x_bias: 1.0}}]
    """))
    assert [i.id for i in scenario.injectors] == ['odom']
    assert "both 'injector' and 'injectors' are given; 'injectors' is used" in scenario.warnings[0]


def test_inf_and_nan_values_are_accepted_as_the_anchor_accepts_them(tmp_path, odom_bag):
    """fault_config_schema.cpp parses doubles with std::from_chars, which reads inf and nan."""
    text = textwrap.dedent("""
        injector: {id: odom, type: odom, input_topic: /odom_raw, output_topic: /odom}
        faults:
          - {id: up, injector_id: odom, active_on_startup: true, config: {x_bias: inf, y_bias: nan}}
    """)
    out, result = run_inline(tmp_path, text, odom_bag)
    assert any('inf makes every value it touches inf or nan' in w for w in result.warnings)
    odom = decoded(out, ['/odom'])['/odom']
    assert all(math.isinf(m.pose.pose.position.x) and math.isnan(m.pose.pose.position.y) for _, m in odom[1:])


def test_covariance_scale_below_one_changes_nothing(tmp_path, odom_bag):
    """odom_fault_injector.cpp: active_max_double("pose_covariance_scale", 1.0) starts at 1.0."""
    text = textwrap.dedent("""
        injector: {id: odom, type: odom, input_topic: /odom_raw, output_topic: /odom}
        faults:
          - {id: shrink, injector_id: odom, active_on_startup: true,
             config: {pose_covariance_scale: 0.5, twist_covariance_scale: 0.1}}
    """)
    out, result = run_inline(tmp_path, text, odom_bag)
    assert sum('is below 1 and changes nothing' in w for w in result.warnings) == 2
    data = decoded(out, ['/odom_raw', '/odom'])
    for (_, a), (_, b) in zip(data['/odom_raw'], data['/odom'], strict=True):
        assert np.array_equal(a.pose.covariance, b.pose.covariance)
        assert np.array_equal(a.twist.covariance, b.twist.covariance)


def test_start_and_duration_are_whole_milliseconds_with_a_1_ms_timer_minimum(tmp_path, odom_bag):
    """scenario_config.cpp: static_cast<int64_t>(seconds * 1000.0); fault_scheduler.cpp: max(delay, 1 ms)."""
    text = textwrap.dedent("""
        injector: {id: odom, type: odom, input_topic: /odom_raw, output_topic: /odom}
        faults:
          - {id: at_zero, injector_id: odom, start: 0.0, duration: 0.0004, config: {x_bias: 1.0}}
          - {id: late, injector_id: odom, start: 2.0009, duration: 1.0009, config: {y_bias: 1.0}}
    """)
    _, result = run_inline(tmp_path, text, odom_bag)
    events = [(e.fault_id, e.state, round(seconds(e.time), 6)) for e in result.stats.events]
    assert events == [('at_zero', 'active', 0.001), ('at_zero', 'inactive', 0.001),
                      ('late', 'active', 2.0), ('late', 'inactive', 3.0)]  # 2000 ms + 1000 ms


def test_a_delay_that_shrinks_keeps_the_order(tmp_path, odom_bag):
    """odom_fault_injector.cpp: delayed messages wait in a std::deque released front first."""
    text = textwrap.dedent("""
        injector: {id: odom, type: odom, input_topic: /odom_raw, output_topic: /odom}
        faults:
          - {id: long, injector_id: odom, start: 2.0, duration: 2.0, config: {delay_ms: 300}}
          - {id: short, injector_id: odom, start: 3.0, duration: 3.0, config: {delay_ms: 100}}
    """)
    out, _ = run_inline(tmp_path, text, odom_bag)
    raw = raw_messages(out)
    sent = {d: seconds(t) for t, _, d in raw['/odom_raw']}
    received = [(sent[d], seconds(t)) for t, _, d in raw['/odom']]
    delayed = [sent_at for sent_at, _ in received if sent_at < 6.0]
    assert len(delayed) == 300 and delayed == sorted(delayed)  # while a delay is active the order is kept
    out_time = dict(received)
    # the message at 4.00 s (delay 100 ms now) leaves after the one at 3.98 s (delay 300 ms: out at 4.28 s)
    assert out_time[3.98] == pytest.approx(4.28) and out_time[4.0] == pytest.approx(4.28)
    assert out_time[4.5] == pytest.approx(4.6)  # the queue has drained: 100 ms again
    # with no delay left a message goes out at once, before the last delayed ones (the anchor publishes it directly)
    assert out_time[6.0] == 6.0 and out_time[5.98] == pytest.approx(6.08)


def test_topic_names_without_a_leading_slash_can_be_faulted(tmp_path):
    """Bags written by other tools (ROS 1 `groundtruth`, test bags' `AAA`) hold names without a slash."""
    bag = make_bag(tmp_path / 'bare.mcap', [('groundtruth', 'nav_msgs/msg/Odometry', 10.0)], 2.0)
    for written in ('groundtruth', '/groundtruth'):
        text = (f'injector: {{id: o, type: odom, input_topic: {written}, output_topic: {written}}}\n'
                'faults: [{id: f, injector_id: o, active_on_startup: true, config: {x_bias: 2.0}}]\n')
        out, result = run_inline(tmp_path, text, bag)
        data = decoded(out)
        assert sorted(data) == ['/fault_injection/events', 'groundtruth'] and not result.warnings  # in place
        assert all(m.pose.pose.position.x >= 2.0 for _, m in data['groundtruth'])


def test_a_missing_input_topic_is_a_warning_and_the_other_injectors_run(tmp_path, odom_bag):
    text = textwrap.dedent("""
        injectors:
          - {id: imu, type: imu, input_topic: /imu_raw, output_topic: /imu}
          - {id: odom, type: odom, input_topic: /odom_raw, output_topic: /odom}
        faults:
          - {id: spin, injector_id: imu, active_on_startup: true, config: {angular_velocity_z_bias: 1.0}}
          - {id: bias, injector_id: odom, active_on_startup: true, config: {x_bias: 1.0}}
    """)
    out, result = run_inline(tmp_path, text, odom_bag)
    [warning] = result.warnings
    assert "injector 'imu': input topic /imu_raw is not in the bag, so its faults have no effect" in warning
    assert 'the bag has /odom_raw (nav_msgs/msg/Odometry)' in warning
    assert len(decoded(out, ['/odom'])['/odom']) == 500


def test_yaml_the_way_yaml_cpp_reads_it(tmp_path, odom_bag):
    text = textwrap.dedent("""
        base: &bias {injector_id: odom, config: {x_bias: 1.0}}
        injector: {id: odom, type: odom, input_topic: /odom_raw, output_topic: /odom}
        faults:
          - {<<: *bias, id: merged, start: 1e0}       # merge key; 1e0 is a number (YAML 1.2, yaml-cpp)
        faults:
          - {id: second_faults_block, injector_id: odom, config: {}}
    """)
    scenario = parse_scenario(text)
    [fault] = scenario.faults
    assert (fault.id, fault.injector_id, fault.start, fault.config) == ('merged', 'odom', 1.0, {'x_bias': 1.0})
    assert any('faults: key given twice (first on line 4); the first value is used' in w for w in scenario.warnings)
    with pytest.raises(ScenarioError, match="'1:30' is not a number of seconds"):
        parse_scenario('injector: {id: o, type: odom, input_topic: /a, output_topic: /b}\n'
                       'faults: [{id: f, injector_id: o, start: 1:30}]\n')


@pytest.mark.parametrize(('text', 'problem'), [
    ('a: &a [1, *a]\n', 'recursive alias'),
    ('a: !!python/object:os.system {}\n', 'unknown tag'),
    ('a: ' + '[' * 200 + ']' * 200 + '\n', 'nested more than 64 levels deep'),
    ('a: &a [x, x, x, x, x, x, x, x, x, x]\nb: &b [*a, *a, *a, *a, *a, *a, *a, *a, *a, *a]\n'
     'c: &c [*b, *b, *b, *b, *b, *b, *b, *b, *b, *b]\nd: &d [*c, *c, *c, *c, *c, *c, *c, *c, *c, *c]\n'
     'e: &e [*d, *d, *d, *d, *d, *d, *d, *d, *d, *d]\nf: [*e, *e, *e, *e, *e, *e, *e, *e, *e, *e]\n', 'alias bomb'),
])
def test_hostile_yaml_is_refused_at_its_place(text, problem):
    with pytest.raises(ScenarioError, match=problem) as info:
        parse_scenario(text)
    assert info.value.problems[0].where != '1:1' or 'nested' in problem


def test_api_run_with_a_scenario_object_and_strict_checks(tmp_path, odom_bag):
    scenario = parse_scenario('injector: {id: o, type: odom, input_topic: /odom_raw, output_topic: /odom}\n'
                              'faults: [{id: f, injector_id: o, active_on_startup: true, config: {x_bias: 1}}]\n')
    result = api.run(scenario, [odom_bag], tmp_path / 'o.mcap')
    assert not result.warnings and result.stats.input_messages == 500


def test_a_nan_noise_level_is_accepted_with_a_true_warning_and_adds_nothing(tmp_path, odom_bag):
    """fault_injector_base.cpp:143-156 (active_max_double): std::max(0.0, nan) keeps 0.0, so the anchor adds no
    noise for a nan stddev, and says nothing; bagfault does the same and says why."""
    text = textwrap.dedent("""
        injector: {id: odom, type: odom, input_topic: /odom_raw, output_topic: /odom}
        faults:
          - {id: quiet, injector_id: odom, active_on_startup: true, config: {x_noise_stddev: nan}}
    """)
    out, result = run_inline(tmp_path, text, odom_bag)
    assert any(w.endswith("nan has no effect: a level is the largest of the active faults' values, and "
                          'ros2_fault_injection folds them with std::max(level, nan), which keeps level')
               for w in result.warnings)
    raw = decoded(odom_bag, ['/odom_raw'])['/odom_raw']
    odom = decoded(out, ['/odom'])['/odom']
    assert [m.pose.pose.position.x for _, m in odom] == [m.pose.pose.position.x for _, m in raw]


def test_a_nan_drop_probability_is_accepted_and_drops_nothing(tmp_path, odom_bag):
    """fault_config_schema.cpp:190-199 refuses a drop_probability outside [0, 1] by `< 0.0 || > 1.0`, which nan
    passes; should_drop (fault_injector_base.cpp:222) takes active_max_double, 0.0 for nan: nothing dropped."""
    text = textwrap.dedent("""
        injector: {id: odom, type: odom, input_topic: /odom_raw, output_topic: /odom}
        faults:
          - {id: never, injector_id: odom, active_on_startup: true, config: {drop_probability: nan}}
    """)
    out, result = run_inline(tmp_path, text, odom_bag)
    assert any(w.endswith('which keeps level') for w in result.warnings)
    assert len(decoded(out, ['/odom'])['/odom']) == len(decoded(odom_bag, ['/odom_raw'])['/odom_raw'])
    with pytest.raises(ScenarioError, match=r'above the maximum 1\.0'):
        parse_scenario(text.replace('nan', 'inf'))


@pytest.mark.parametrize(('config', 'key', 'refusal'), [
    # fault_config_schema.cpp validate_config_value: bool is the text 'true' or 'false'; numbers are
    # std::from_chars over the whole text (parse_double, parse_int), which takes no '+', no hex, no YAML '.inf'
    ('{force_failure: yes}', 'force_failure', "config 'force_failure' must be 'true' or 'false'"),
    ('{delay_ms: 100.0}', 'delay_ms', "config 'delay_ms' must be an integer"),
    ('{delay_ms: 0x10}', 'delay_ms', "config 'delay_ms' must be an integer"),
    ('{delay_ms: +5}', 'delay_ms', "config 'delay_ms' must be an integer"),
])
def test_spellings_the_anchors_validator_refuses_are_warnings_and_errors_under_strict(config, key, refusal):
    text = ('injectors:\n  - {id: t, type: trigger_service, proxy_service: /a, target_service: /b}\n'
            f'faults:\n  - {{id: f, injector_id: t, config: {config}}}\n')
    scenario = parse_scenario(text)
    assert any(f'faults[0].config.{key}:' in w and f'validator refuses it ({refusal})' in w
               for w in scenario.warnings), scenario.warnings
    with pytest.raises(ScenarioError, match='would not load in the anchor'):
        parse_scenario(text, strict=True)


@pytest.mark.parametrize(('value', 'refused'), [
    ('+1.0', True), ('.inf', True), ('1e3', False), ('-2.5', False), ('inf', False), ('-inf', False),
    ('nan', False), ('.5', False), ('5.', False),
])
def test_a_number_the_anchor_parses_with_from_chars(value, refused):
    """parse_double (fault_config_schema.cpp): std::from_chars, general format, the whole text."""
    text = ('injector: {id: o, type: odom, input_topic: /odom_raw, output_topic: /odom}\n'
            f'faults:\n  - {{id: f, injector_id: o, config: {{x_bias: {value}}}}}\n')
    warned = any('validator refuses it' in w for w in parse_scenario(text).warnings)
    assert warned == refused


@pytest.mark.parametrize(('value', 'active'), [
    ('y', True), ('N', False), ("'false'", False), ("'TRUE'", True), ('Yes', True), ('off', False), ('On', True),
])
def test_active_on_startup_is_read_as_yaml_cpp_reads_a_bool(value, active):
    """scenario_config.cpp:160 reads `active_on_startup` (and `active`) with yaml-cpp's as<bool>(), whose table
    (convert.cpp) takes y/n, yes/no, true/false and on/off, quoted or not, in lower, upper or capitalised case."""
    text = ('injector: {id: o, type: odom, input_topic: /odom_raw, output_topic: /odom}\n'
            f'faults:\n  - {{id: f, injector_id: o, active_on_startup: {value}, config: {{x_bias: 1.0}}}}\n')
    assert parse_scenario(text).faults[0].active_on_startup is active


def test_a_bool_yaml_cpp_cannot_read_is_refused():
    text = ('injector: {id: o, type: odom, input_topic: /odom_raw, output_topic: /odom}\n'
            'faults:\n  - {id: f, injector_id: o, active_on_startup: tRUE, config: {x_bias: 1.0}}\n')
    with pytest.raises(ScenarioError, match="'tRUE' is not true or false"):  # not flexible case: bad conversion
        parse_scenario(text)


def test_a_topic_hz_within_shorter_than_its_window_is_the_anchors_advisory_warning():
    """scenario_validator.cpp validate_assertions: within < window warns "has within smaller than window; it may
    fail before a full measurement window is available" (a warning: the file still loads)."""
    text = ('injector: {id: o, type: odom, input_topic: /odom_raw, output_topic: /odom}\nfaults: []\n'
            'assertions:\n  - {id: hz, type: topic_hz, topic: /odom, message_type: nav_msgs/msg/Odometry, '
            'min_hz: 10.0, window: 2.0, within: 1.0}\n')
    warnings = parse_scenario(text).warnings
    assert [w.split(': ', 2)[1:] for w in warnings] == [
        ['assertions[0].within', "assertion 'hz' has within smaller than window; it may fail before a full "
                                 'measurement window is available']]
    assert parse_scenario(text.replace('within: 1.0', 'within: 2.0')).warnings == []


def test_a_fault_id_defined_twice_runs_as_the_anchor_runs_it(tmp_path, odom_bag):
    """The anchor loads it (scenario_validator.cpp checks injector and assertion ids only): the injector's map
    keeps the second definition's config (fault_injector_base.cpp add_fault: faults_[id] = config) and the
    scheduler sets timers for both definitions (fault_scheduler.cpp schedule: a loop over every FaultConfig).
    So x_bias 5.0 during both windows, [1, 2) s and [4, 5) s."""
    text = textwrap.dedent("""
        injector: {id: odom, type: odom, input_topic: /odom_raw, output_topic: /odom}
        faults:
          - {id: shift, injector_id: odom, start: 1.0, duration: 1.0, config: {x_bias: 1.0}}
          - {id: shift, injector_id: odom, start: 4.0, duration: 1.0, config: {x_bias: 5.0}}
    """)
    scenario = parse_scenario(text)
    assert len(scenario.warnings) == 1 and 'faults[1].id' in scenario.warnings[0]
    assert 'defined again' in scenario.warnings[0]
    with pytest.raises(ScenarioError):
        parse_scenario(text, strict=True)
    out, result = run_inline(tmp_path, text, odom_bag)
    events = [(e.fault_id, e.state, round(seconds(e.time), 3)) for e in result.stats.events]
    assert events == [('shift', 'active', 1.0), ('shift', 'inactive', 2.0), ('shift', 'active', 4.0),
                      ('shift', 'inactive', 5.0)]
    raw = {t: m.pose.pose.position.x for t, m in decoded(odom_bag, ['/odom_raw'])['/odom_raw']}
    shifted = {round(seconds(t), 2): m.pose.pose.position.x - raw[t] for t, m in decoded(out, ['/odom'])['/odom']}
    assert shifted[0.5] == 0.0 and shifted[1.5] == pytest.approx(5.0) and shifted[3.0] == 0.0
    assert shifted[4.5] == pytest.approx(5.0) and shifted[5.5] == 0.0


def test_one_fault_id_on_two_injectors_is_refused():
    text = textwrap.dedent("""
        injectors:
          - {id: a, type: odom, input_topic: /odom_raw, output_topic: /odom}
          - {id: b, type: odom, input_topic: /odom2_raw, output_topic: /odom2}
        faults:
          - {id: shift, injector_id: a, start: 1.0, config: {x_bias: 1.0}}
          - {id: shift, injector_id: b, start: 1.0, config: {x_bias: 1.0}}
    """)
    with pytest.raises(ScenarioError, match="also a fault of injector 'a'"):
        parse_scenario(text)


def test_a_big_file_and_an_alias_bomb_are_told_apart(monkeypatch):
    """Values the file writes count against MAX_NODES, values reached again through aliases against
    MAX_EXPANDED: a scenario of many plain faults is no alias bomb (30 000 fault windows were refused as one)."""
    from bagfault.spec import yamlnodes

    monkeypatch.setattr(yamlnodes, 'MAX_NODES', 1000)
    monkeypatch.setattr(yamlnodes, 'MAX_EXPANDED', 1000)
    plain = 'faults:\n' + ''.join(f'  - {{id: f{n}, start: {n}}}\n' for n in range(400))  # 400 x 3 values (keys uncounted)
    with pytest.raises(yamlnodes.YamlSyntaxError, match='more than 1000 values: a scenario file holds at most'):
        yamlnodes.load_located(plain)
    aliases = 'a: &a [1, 2, 3, 4, 5, 6, 7, 8, 9, 10]\nb: [' + ', '.join(['*a'] * 120) + ']\n'  # 12 written, 1320 again
    with pytest.raises(yamlnodes.YamlSyntaxError, match='reached again through aliases'):
        yamlnodes.load_located(aliases)


def test_thirty_thousand_fault_windows_load_in_linear_time(tmp_path):
    lines = ['injectors: [{id: imu, type: imu, input_topic: /imu, output_topic: /imu}]', 'faults:']
    lines += [f'  - {{id: f{n}, injector_id: imu, start: {n / 1000:.3f}, duration: 0.0005, '
              'config: {angular_velocity_z_bias: 0.1}}' for n in range(30_000)]
    began = time.monotonic()
    scenario = parse_scenario('\n'.join(lines) + '\n')
    assert len(scenario.faults) == 30_000 and time.monotonic() - began < 30  # about 4 s here
