"""Scenario loading: the anchor's three layouts, meaning of schedules, every validation problem."""

from __future__ import annotations

import math
import textwrap

import pytest
import yaml
from support.helpers import third_party

from bagfault.scenario import ScenarioError, load_scenario, parse_scenario

ANCHOR_FILES = [
    'imu_faults.yaml',
    'motor_feedback_faults.yaml',
    'multi_injector_faults.yaml',
    'odom_faults.yaml',
    'scan_faults.yaml',
    'service_integration_faults.yaml',
    'tf_faults.yaml',
    'trigger_service_faults.yaml',
]


@pytest.mark.parametrize('name', third_party(ANCHOR_FILES))
def test_every_anchor_scenario_loads(anchors, name):
    scenario = load_scenario(anchors / name)
    assert scenario.injectors and scenario.faults
    ids = [f.id for f in scenario.faults]
    assert len(ids) == len(set(ids))


def test_battery_scenario_names_the_unknown_type_and_skips_it(scenarios):
    """The anchor warns 'assuming external plugin' and runs without that injector (scenario_validator.cpp:136,
    fault_controller.cpp:44): so does bagfault, saying where, and refuses under --strict."""
    scenario = load_scenario(scenarios / 'battery.yaml')
    assert scenario.injectors == [] and scenario.faults == []
    assert scenario.skipped_faults == ['battery_voltage_bias']
    assert scenario.warnings[0].endswith("injectors[0].type: unknown injector type 'battery_state': not built in "
                                         "and no installed plugin provides it, so injector 'battery' and its faults "
                                         "(battery_voltage_bias) are skipped and the others run, as the anchor does "
                                         "(\"assuming external "
                                         "plugin\"; known: clock, compressed_image, field, image, imu, joint_state, "
                                         "link, odom, pointcloud2, process, scan, tf, topic, trigger_service)")
    assert ':4:11: ' in scenario.warnings[0] and len(scenario.warnings) == 1


def test_nested_topic_layout(scenarios):
    scenario = load_scenario(scenarios / 'nested_odom.yaml')
    odom = scenario.injector('odom')
    assert (odom.input_topic, odom.output_topic, odom.qos_depth) == ('/test/odom_raw', '/test/odom', 10)
    assert scenario.faults[0].config == {'x_bias': 1.0, 'drop_probability': 0.0}


def test_flat_list_layout_and_schedules(scenarios):
    scenario = load_scenario(scenarios / 'rover_multi.yaml')
    assert [i.id for i in scenario.injectors] == ['odom', 'scan', 'motor_feedback', 'imu', 'enable_motors', 'tf_odom_base']
    tf = scenario.injector('tf_odom_base')
    assert (tf.input_topic, tf.output_topic, tf.qos_depth) == ('/tf_raw', '/tf', 50)
    service = scenario.injector('enable_motors')
    assert (service.proxy_service, service.target_service) == ('/enable_motors', '/enable_motors_raw')
    bias = scenario.fault('odom_position_bias')
    assert (bias.start, bias.duration, bias.active_on_startup, bias.manual_only) == (5.0, 10.0, False, False)
    noise = scenario.fault('odom_position_noise')
    assert noise.manual_only
    blind = scenario.fault('scan_front_blind')
    assert blind.config['sector_value'] == math.inf
    assert blind.config_text['sector_value'] == 'inf'
    failure = scenario.fault('enable_motors_forced_failure')
    assert failure.config == {'force_failure': True, 'failure_message': 'Injected scheduled service failure'}
    assert [a.id for a in scenario.assertions][:2] == ['odom_yaw_bias_activates', 'odom_yaw_bias_deactivates']
    assert scenario.assertions[0].within == 6.0


def test_single_injector_layout(scenarios):
    scenario = load_scenario(scenarios / 'scan.yaml')
    assert len(scenario.injectors) == 1
    assert scenario.fault('scan_range_noise').active_on_startup
    assert scenario.fault('scan_delay').config == {'delay_ms': 250}


def test_deprecated_active_alias_means_active_on_startup():
    scenario = parse_scenario(textwrap.dedent("""
        injector: {id: imu, type: imu, input_topic: /a, output_topic: /b}
        faults:
          - {id: f, injector_id: imu, active: true, config: {angular_velocity_z_bias: 1.0}}
    """))
    assert scenario.fault('f').active_on_startup


def test_anchor_warnings_are_not_errors():
    scenario = parse_scenario(textwrap.dedent("""
        injector: {id: imu, type: imu, input_topic: /a, output_topic: /b}
        faults:
          - {id: f, injector_id: imu, active_on_startup: true, start: 3, config: {}}
          - {id: g, injector_id: imu, duration: 3, config: {}}
    """))
    assert scenario.warnings == [
        "<scenario>:4:63: faults[0].start: fault 'f' has active_on_startup and start; start is ignored",
        "<scenario>:5:41: faults[1].duration: fault 'g' has duration but no start; duration is ignored",
    ]


BAD = textwrap.dedent("""\
    injectors:
      - id: odom
        type: odom
        input_topic: /odom_raw
        output_topic: /odom
      - id: odom
        type: lidar3d
        input_topic: /x
        output_topic: /y
    faults:
      - id: a
        injector_id: odom
        config:
          drop_probability: 1.5
      - id: a
        injector_id: odom
        start: -1.0
        config:
          x_bias: fast
          bogus_key: 1
      - id: c
        injector_id: nowhere
        duration: -2
    assertions:
      - id: late
        type: fault_event
        fault_id: ghost
        state: active
""")


def test_validation_reports_every_problem_with_its_location():
    with pytest.raises(ScenarioError) as info:
        parse_scenario(BAD)
    found = {(p.path, p.message) for p in info.value.problems}
    where = {p.path: p.where for p in info.value.problems}
    assert ('faults[1].start', '-1.0 is negative') in found
    assert ('faults[2].duration', '-2 is negative') in found
    assert ('injectors[1].id', "duplicate injector id 'odom'") in found
    assert not any(p == 'faults[1].id' for p, _ in found)  # a fault id defined again is the anchor's warning
    assert not any(p == 'injectors[1].type' for p, _ in found)  # an unknown type is a warning (the anchor's)
    assert ('faults[0].config.drop_probability', '1.5 is above the maximum 1.0') in found
    assert ('faults[1].config.x_bias', "'fast' is not a number") in found
    assert any(p == 'faults[2].injector_id' and "unknown injector 'nowhere'" in m for p, m in found)
    assert any(p == 'assertions[0].fault_id' and "unknown fault 'ghost'" in m for p, m in found)
    assert where['faults[0].config.drop_probability'] == '14:25'
    assert len(info.value.problems) == 7  # the unknown config key, the unknown type, the repeated fault id: warnings
    with pytest.raises(ScenarioError) as strict:
        parse_scenario(BAD, strict=True)
    assert any(p.path == 'faults[1].config.bogus_key' and "unknown config key 'bogus_key' for injector type 'odom'"
               in p.message and p.message.endswith('(a warning, an error with --strict)')
               for p in strict.value.problems)
    assert len(strict.value.problems) == 10
    text = str(info.value)
    assert 'faults[0].config.drop_probability: 1.5 is above the maximum 1.0' in text


def test_misspelled_key_is_a_warning_with_a_suggestion_and_an_error_with_strict():
    text = textwrap.dedent("""
        injector: {id: imu, type: imu, input_topic: /a, output_topic: /b}
        faults:
          - {id: f, injector_id: imu, config: {angular_velocity_z_bais: 1.0}}
    """)
    scenario = parse_scenario(text)
    [warning] = scenario.warnings
    assert "faults[0].config.angular_velocity_z_bais: unknown config key 'angular_velocity_z_bais'" in warning
    assert "is ignored (did you mean 'angular_velocity_z_bias'?)" in warning
    assert scenario.faults[0].config == {}  # ignored, as the anchor's injector ignores it
    assert scenario.faults[0].describe_config() == 'config={angular_velocity_z_bais=1.0}'  # shown as written
    with pytest.raises(ScenarioError, match="did you mean 'angular_velocity_z_bias'"):
        parse_scenario(text, strict=True)


def test_required_and_cross_field_checks():
    with pytest.raises(ScenarioError) as info:
        parse_scenario(textwrap.dedent("""
            injectors:
              - {id: tf, type: tf, input_topic: /tf_raw, output_topic: /tf}
            faults:
              - {id: f, injector_id: tf, config: {x_bias: 1.0}}
        """))
    messages = [p.message for p in info.value.problems]
    assert "missing required key 'parent_frame' for injector type 'tf'" in messages
    assert "missing required key 'child_frame' for injector type 'tf'" in messages


def test_a_sector_with_one_bound_blanks_nothing_and_says_so():
    scenario = parse_scenario(textwrap.dedent("""
        injector: {id: scan, type: scan, input_topic: /s, output_topic: /t}
        faults:
          - {id: g, injector_id: scan, config: {sector_min_deg: 10}}
    """))
    assert scenario.warnings == ['<scenario>:4:40: faults[0].config: sector_min_deg without sector_max_deg: no sector '
                                 'is blanked (ros2_fault_injection skips it too)']


def test_wrong_types_and_structure():
    with pytest.raises(ScenarioError) as info:
        parse_scenario(textwrap.dedent("""
            injector: {id: imu, type: imu, input_topic: /a, output_topic: /b, qos_depth: 0}
            faults:
              - {id: f, injector_id: imu, active_on_startup: maybe, config: {delay_ms: 2.5}}
            asertions: []
        """))
    found = {(p.path, p.message) for p in info.value.problems}
    assert ('injector.qos_depth', '0 is not a positive integer') in found
    assert ('faults[0].active_on_startup', "'maybe' is not true or false (nor yes/no, y/n, on/off, as yaml-cpp reads "
            'booleans)') in found
    assert ('faults[0].config.delay_ms', '2.5 is not an integer') in found
    assert not any(p == 'asertions' for p, _ in found)  # an unknown top-level key is a warning


def test_yaml_syntax_error_has_a_location():
    with pytest.raises(ScenarioError) as info:
        parse_scenario('injectors:\n  - id: [unclosed\n')
    assert info.value.problems[0].where.startswith('3:') or info.value.problems[0].where.startswith('2:')
    assert 'invalid YAML' in info.value.problems[0].message


def test_missing_file_is_one_clear_problem(tmp_path, capsys):
    with pytest.raises(ScenarioError, match='scenario file not found'):
        load_scenario(tmp_path / 'nope.yaml')
    (tmp_path / 'folder.yaml').mkdir()
    from bagfault.cli import main

    for command in (['validate', str(tmp_path / 'nope.yaml')], ['validate', str(tmp_path / 'folder.yaml')],
                    ['run', str(tmp_path / 'nope.yaml'), str(tmp_path / 'bag.mcap'), '-o', str(tmp_path / 'o.mcap')]):
        assert main(command) == 2
    assert capsys.readouterr().err.splitlines() == [  # the file and the problem, no made-up place in it
        f'bagfault: error: {tmp_path / "nope.yaml"}: scenario file not found',
        f'bagfault: error: {tmp_path / "folder.yaml"}: is a directory, not a scenario file',
        f'bagfault: error: {tmp_path / "nope.yaml"}: scenario file not found']


def test_extended_schedules_parse_and_validate():
    scenario = parse_scenario(textwrap.dedent("""
        injector: {id: imu, type: imu, input_topic: /a, output_topic: /b}
        faults:
          - {id: r, injector_id: imu, repeat: {period: 2.0, on: 0.5}, config: {}}
          - {id: p, injector_id: imu, probability_per_second: 0.2, hold: 1.0, config: {}}
          - {id: a, injector_id: imu, after: {fault: r, delay: 0.25}, duration: 1.0, config: {}}
    """))
    assert (scenario.fault('r').repeat.period, scenario.fault('r').repeat.on) == (2.0, 0.5)
    assert (scenario.fault('p').probability_per_second, scenario.fault('p').hold) == (0.2, 1.0)
    assert (scenario.fault('a').after.fault, scenario.fault('a').after.delay) == ('r', 0.25)
    with pytest.raises(ScenarioError) as info:
        parse_scenario(textwrap.dedent("""
            injector: {id: imu, type: imu, input_topic: /a, output_topic: /b}
            faults:
              - {id: r, injector_id: imu, repeat: {period: 1.0, on: 2.0}, config: {}}
              - {id: p, injector_id: imu, probability_per_second: 0.2, config: {}}
              - {id: a, injector_id: imu, after: {fault: a}, config: {}}
              - {id: b, injector_id: imu, after: {fault: ghost}, config: {}}
        """))
    messages = {(p.path, p.message) for p in info.value.problems}
    assert ('faults[0].repeat.on', '2.0 is longer than the period 1.0') in messages
    assert any(p == 'faults[1].probability_per_second' and "needs 'hold'" in m for p, m in messages)
    assert ('faults[2].after.fault', 'a fault cannot be chained after itself') in messages
    assert ('faults[3].after.fault', "unknown fault 'ghost'") in messages


def test_a_loop_of_after_chains_is_one_problem_naming_the_loop():
    """f3 -> f4 -> f3 is one loop: one line at its first fault, whatever chains lead into it (f5 follows f3)."""
    with pytest.raises(ScenarioError) as info:
        parse_scenario(textwrap.dedent("""
            injector: {id: imu, type: imu, input_topic: /a, output_topic: /b}
            faults:
              - {id: f1, injector_id: imu, start: 1.0, config: {}}
              - {id: f5, injector_id: imu, after: {fault: f3}, config: {}}
              - {id: f3, injector_id: imu, after: {fault: f4}, config: {}}
              - {id: f4, injector_id: imu, after: {fault: f3}, config: {}}
              - {id: f6, injector_id: imu, after: {fault: f6}, config: {}}
        """))
    assert [(p.path, p.message) for p in info.value.problems] == [
        ('faults[2].after.fault', 'chain of "after" faults loops: f3 -> f4 -> f3'),
        ('faults[4].after.fault', 'a fault cannot be chained after itself')]


def test_live_injector_keys_are_checked_like_the_rest():
    with pytest.raises(ScenarioError) as info:
        parse_scenario(textwrap.dedent("""
            injectors:
              - {id: imu, type: imu, input_topic: /a, output_topic: /b, reliability: fast, durability: volatile}
              - {id: odom, type: odom, input_topic: /c, output_topic: /d, message_type: sensor_msgs/msg/Imu}
              - {id: any, type: topic, input_topic: /e, output_topic: /f, on_malformed: ignore}
            faults: []
        """))
    found = {(p.path, p.message) for p in info.value.problems}
    assert ('injectors[0].reliability', "'fast' is not one of reliable, best_effort") in found
    assert ('injectors[1]', "message_type sensor_msgs/msg/Imu does not fit injector type 'odom', "
                            'which takes nav_msgs/msg/Odometry') in found
    assert ('injectors[2].on_malformed', "'ignore' is not one of forward, drop, error") in found
    assert len(found) == 3
    ok = parse_scenario('injector: {id: s, type: topic, input_topic: /e, output_topic: /f, '
                        'reliability: best_effort, durability: transient_local, message_type: std_msgs/msg/String}\n'
                        'faults: []\n')
    assert ok.injectors[0].options == {'reliability': 'best_effort', 'durability': 'transient_local',
                                       'message_type': 'std_msgs/msg/String'}


def test_a_loaded_scenario_is_read_only_and_a_run_time_change_makes_a_new_record(scenarios):
    """Nothing edits a loaded scenario: its records refuse assignment, and a fault changed while running (the
    engine's FaultState) is a new FaultSpec beside the loaded one, which keeps its value."""
    import dataclasses

    from bagfault.engine.fault_state import FaultState

    scenario = load_scenario(scenarios / 'rover_multi.yaml')
    fault = scenario.faults[0]
    records = [scenario, fault, scenario.injectors[0], *scenario.assertions[:1]]
    for record in records:
        name = next(f.name for f in dataclasses.fields(record) if not f.name.startswith('_'))
        with pytest.raises(dataclasses.FrozenInstanceError, match='never edited'):
            setattr(record, name, getattr(record, name))
    key = next(iter(fault.config))
    state = FaultState(scenario)
    changed = state.configure(fault.id, key, state.check(fault.id, key, 12.5))
    assert state.fault(fault.id) is changed and changed.config[key] == 12.5
    assert scenario.fault(fault.id).config[key] != 12.5


NESTED = {  # a key whose value is a mapping of its own, where it goes in a scenario that is otherwise valid
    'injectors[0].topic': (0, 'topic', {'input_topic': '/imu', 'output_topic': '/imu_out'}),
    'injectors[1].trigger_service': (1, 'trigger_service', {'proxy_service': '/a', 'target_service': '/b'}),
    'faults[0].repeat': (None, 'repeat', {'period': 2.0, 'on': 0.5}),
    'faults[0].after': (None, 'after', {'fault': 'other', 'delay': 0.5}),
    'faults[0].config': (None, 'config', {'angular_velocity_z_bias': 0.1}),
}


def nested_scenario(where: str, value: object) -> str:
    injectors = [{'id': 'imu', 'type': 'imu', 'input_topic': '/imu', 'output_topic': '/imu_out'},
                 {'id': 'svc', 'type': 'trigger_service', 'proxy_service': '/a', 'target_service': '/b'}]
    faults = [{'id': 'bias', 'injector_id': 'imu', 'start': 1.0, 'config': {'angular_velocity_z_bias': 0.1}},
              {'id': 'other', 'injector_id': 'imu', 'start': 3.0, 'config': {'angular_velocity_z_bias': 0.2}}]
    index, key, _ = NESTED[where]
    if index is not None:
        injectors[index] = {k: v for k, v in injectors[index].items() if k not in ('input_topic', 'output_topic',
                                                                                  'proxy_service', 'target_service')}
        injectors[index][key] = value
    else:
        faults[0][key] = value
        if key == 'after':
            del faults[0]['start']
    return yaml.safe_dump({'injectors': injectors, 'faults': faults})


@pytest.mark.parametrize('where', sorted(NESTED))
def test_each_nested_mapping_key_as_a_mapping_is_valid(where):
    parse_scenario(nested_scenario(where, NESTED[where][2]))


@pytest.mark.parametrize('where', sorted(NESTED))
@pytest.mark.parametrize('value', [5, 2.5, 'text', [1, 2], True, [{'input_topic': '/x'}]])
def test_a_nested_mapping_key_that_is_no_mapping_is_one_problem(where, value):
    """Told once where it stands: not again as the keys it lacks, nor as what those lacking keys leave out."""
    with pytest.raises(ScenarioError) as info:
        parse_scenario(nested_scenario(where, value))
    [problem] = info.value.problems
    assert problem.path == where and problem.message.startswith('must be a mapping')
