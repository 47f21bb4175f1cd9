"""ros2_fault_injection's own validator tests, ported: names, scenarios and expectations from
reeceholland/ros2_fault_injection test/config/test_scenario_validator.cpp at f104e75.

The C++ tests build a ScenarioConfig in code; here the same scenario is written as the YAML that loads into
it (the anchor's `fault.duration = 10 s` is `duration: 10.0`, `initially_active_faults` is
`active_on_startup: true`). "ok" is a scenario that loads; an error is a ScenarioError whose one problem names
the same key; a warning is one entry of `Scenario.warnings` holding the anchor's own words where bagfault
uses them.
"""

from __future__ import annotations

import contextlib
import textwrap
from pathlib import Path

import pytest
from support.helpers import ANCHORS

from bagfault.errors import ScenarioError
from bagfault.scenario import parse_scenario

ODOM = """
injectors:
  - {id: odom, type: odom, topic: {input_topic: /odom_raw, output_topic: /odom, qos_depth: 10}}
faults:
  - id: odom_bias
    injector_id: odom
    config: {x_bias: "1.0", drop_probability: "0.25"%(config)s}
%(fault)s
"""
SCAN = """
injectors:
  - {id: scan, type: scan, topic: {input_topic: /scan_raw, output_topic: /scan, qos_depth: 10}}
faults:
  - {id: scan_front_blind, injector_id: scan, config: {%(config)s}}
"""


def odom(config: str = '', fault: str = '', injectors: str = '') -> str:
    text = ODOM % {'config': f', {config}' if config else '', 'fault': textwrap.indent(fault, '    ')}
    return text.replace('injectors:\n', 'injectors:\n' + injectors) if injectors else text


def errors_of(text: str) -> list[tuple[str, str]]:
    with pytest.raises(ScenarioError) as info:
        parse_scenario(text)
    return [(p.path, p.message) for p in info.value.problems]


def test_AcceptsValidOdomScenario() -> None:
    scenario = parse_scenario(odom())
    assert scenario.warnings == [] and [f.id for f in scenario.faults] == ['odom_bias']


def test_WarnsForExternalPluginInjectorType() -> None:
    scenario = parse_scenario(odom().replace('type: odom', 'type: camera'))
    assert len(scenario.warnings) == 1  # the type, its fault named in it (as the anchor: one)
    assert 'assuming external plugin' in scenario.warnings[0]


def test_WarnsWhenDurationHasNoStart() -> None:
    scenario = parse_scenario(odom(fault='duration: 10.0'))
    assert len(scenario.warnings) == 1 and 'duration' in scenario.warnings[0] and 'start' in scenario.warnings[0]


def test_RejectsNegativeDuration() -> None:
    (error,) = errors_of(odom(fault='start: 1.0\nduration: -1.0'))
    assert error[0] == 'faults[0].duration' and 'negative' in error[1]


def test_RejectsInvalidDropProbability() -> None:
    (error,) = errors_of(odom().replace('drop_probability: "0.25"', 'drop_probability: "1.5"'))
    assert error[0] == 'faults[0].config.drop_probability'


def test_WarnsOnUnknownScanKey() -> None:
    scenario = parse_scenario(SCAN % {'config': 'range_noise_stddev: "0.05", x_bias: "1.0"'})
    assert len(scenario.warnings) == 1 and "unknown config key 'x_bias'" in scenario.warnings[0]


def test_RejectsDuplicateInjectorIds() -> None:
    text = odom(injectors='  - {id: odom, type: odom, topic: {input_topic: /odom_raw, output_topic: /odom}}\n')
    errors = errors_of(text)
    assert ('injectors[1].id', "duplicate injector id 'odom'") in errors
    # bagfault also names what the copy would do (both write /odom); the anchor stops at the id
    assert [e for e in errors if 'duplicate' not in e[1]] == [('injectors[1].output_topic',
                                                               "output topic /odom is already written by injector "
                                                               "'odom'")]


def test_AllowsStartupActiveDurationWithoutStartWarning() -> None:
    scenario = parse_scenario(odom(fault='active_on_startup: true\nduration: 10.0'))
    assert scenario.warnings == []


def test_WarnsWhenStartupActiveFaultAlsoHasStart() -> None:
    scenario = parse_scenario(odom(fault='active_on_startup: true\nstart: 12.0\nduration: 8.0'))
    assert len(scenario.warnings) == 1 and 'active_on_startup' in scenario.warnings[0] \
        and 'start' in scenario.warnings[0]


def test_RejectsNegativeYawNoiseStddevDeg() -> None:
    (error,) = errors_of(odom(config='yaw_noise_stddev_deg: "-1.0"'))
    assert error[0] == 'faults[0].config.yaw_noise_stddev_deg'


IMU = """
injectors:
  - {id: imu, type: imu, topic: {input_topic: /sensors/imu_raw, output_topic: /sensors/imu, qos_depth: 10}}
faults:
  - {id: imu_accel_noise, injector_id: imu, config: {%s}}
"""


def test_AcceptsValidImuScenario() -> None:
    scenario = parse_scenario(IMU % ('linear_acceleration_x_noise_stddev: "0.15", '
                                     'linear_acceleration_y_noise_stddev: "0.15", '
                                     'linear_acceleration_z_noise_stddev: "0.05"'))
    assert scenario.warnings == []


def test_RejectsNegativeImuNoiseStddev() -> None:
    (error,) = errors_of(IMU % 'linear_acceleration_x_noise_stddev: "-0.15"')
    assert error[0] == 'faults[0].config.linear_acceleration_x_noise_stddev'


def test_RejectsInvalidSchemaValue() -> None:
    (error,) = errors_of(odom().replace('x_bias: "1.0"', 'x_bias: "not_a_number"'))
    assert error[0] == 'faults[0].config.x_bias'


def test_RejectsMissingRequiredTfFrame() -> None:
    (error,) = errors_of("""
injectors:
  - {id: tf, type: tf, topic: {input_topic: /tf_raw, output_topic: /tf, qos_depth: 10}}
faults:
  - {id: tf_missing_child_frame, injector_id: tf, config: {parent_frame: odom, x_bias: "1.0"}}
""")
    assert 'child_frame' in error[0] + error[1]


def test_WarnsOnUnknownSchemaKey() -> None:
    scenario = parse_scenario(odom(config='unexpected_key: some_value'))
    assert len(scenario.warnings) == 1 and "unknown config key 'unexpected_key'" in scenario.warnings[0]


def test_AcceptsSpecialFloatSectorValue() -> None:
    """Accepted, inf kept. (bagfault adds its advisory that a sector_value without a sector blanks nothing;
    the anchor accepts that silently and blanks nothing either.)"""
    scenario = parse_scenario(SCAN % {'config': 'sector_value: "inf"'})
    assert scenario.faults[0].config['sector_value'] == float('inf')
    assert all('sector_value without sector_min_deg' in w for w in scenario.warnings)


def test_ExternalPluginTypeWarnsButDoesNotFail() -> None:
    scenario = parse_scenario("""
injectors:
  - {id: battery, type: battery_state, topic: {input_topic: /battery_state_raw, output_topic: /battery_state,
     qos_depth: 10}}
faults:
  - {id: battery_voltage_bias, injector_id: battery, config: {voltage_bias: "-1.5"}}
""")
    assert scenario.warnings and 'assuming external plugin' in scenario.warnings[0]


FAULT_EVENT = odom() + """
assertions:
  - {id: %s, type: fault_event, fault_id: %s, state: active, within: 6.0}
"""


def test_AcceptsScenarioWithValidFaultEventAssertion() -> None:
    scenario = parse_scenario(FAULT_EVENT % ('odom_bias_activates', 'odom_bias'))
    assert [a.id for a in scenario.assertions] == ['odom_bias_activates']


def test_RejectsScenarioWithInvalidFaultEventAssertion() -> None:
    (error,) = errors_of(FAULT_EVENT % ('invalid_assertion', 'nonexistent_fault'))
    assert error[0] == 'assertions[0].fault_id'


def test_every_warning_is_shown_with_the_errors_and_a_misspelt_key_names_the_right_one(tmp_path, capsys):
    """A misspelt `confg:` makes the fault do nothing: a warning naming `config`, shown even when the file also has
    an error (which exits 2), and beside the errors of another file given to the same `validate`."""
    from bagfault.cli import main

    broken = tmp_path / 'broken.yaml'
    broken.write_text('injectors: [{id: imu, type: imu, input_topic: /imu, output_topic: /imu}]\n'
                      'faults: [{id: f, injector_id: imu, start: 1.0, confg: {angular_velocity_z_bias: 0.2}}]\n'
                      'assertions: [{id: a, type: topic_gap, topic: /imu, max_gap: -1}]\n')
    warned = tmp_path / 'warned.yaml'
    warned.write_text('injectors: [{id: imu, type: imu, input_topic: /imu, output_topic: /imu}]\n'
                      'faults: [{id: g, injector_id: imu, start: 1.0, config: {x_bais: 0.2}}]\n')
    assert main(['validate', str(broken), str(warned)]) == 2
    err = capsys.readouterr().err
    assert 'max_gap: -1.0 must be greater than 0' in err
    assert "unknown fault key 'confg' is ignored (did you mean 'config'?" in err
    assert f'bagfault: warning: {warned}' in err and "unknown config key 'x_bais'" in err
    assert err.index('bagfault: error:') < err.index('bagfault: warning:')


def test_run_ends_its_summary_with_the_warnings_of_what_does_nothing(tmp_path, capsys):
    from support.helpers import FIXTURES

    from bagfault.cli import main

    scenario = tmp_path / 's.yaml'
    scenario.write_text('injectors: [{id: imu, type: imu, input_topic: /sensors/imu_raw, output_topic: /imu}]\n'
                        'faults:\n'
                        '  - {id: f, injector_id: imu, start: 1.0, confg: {angular_velocity_z_bias: 0.2}}\n'
                        '  - {id: g, injector_id: imu, duration: 2.0, config: {angular_velocity_z_bias: 0.1}}\n'
                        'assertions: [{id: a, type: topic_gap, topic: /imu, max_gap: 1.0}]\n')
    assert main(['run', str(scenario), str(FIXTURES / 'rover_20s.mcap'), '-o', str(tmp_path / 'o.mcap')]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    # the misspelt key and a duration without start: two; the fault defined twice is no such warning (none here)
    assert out[-1] == 'PASSED: 1 passed, 0 failed; 2 warnings of something in the scenario that does nothing (above)'


def _records(scenario: object) -> object:
    """What the validator could change: the lists of records and every value they hold."""
    import copy

    return copy.deepcopy([(i.id, i.type, i.options) for i in scenario.injectors]  # type: ignore[attr-defined]
                         + [(f.id, f.config) for f in scenario.faults]  # type: ignore[attr-defined]
                         + [(a.id, a.type, a.params) for a in scenario.assertions]  # type: ignore[attr-defined]
                         + [scenario.fault_manager_config, scenario.skipped_faults])  # type: ignore[attr-defined]


SCENARIO_FILES = [*sorted((Path(__file__).parents[1] / 'fixtures' / 'scenarios').glob('*.yaml')),
                  Path(__file__).parents[2] / 'examples' / 'closed_loop' / 'test_imu_drift.bagfault.yaml',
                  *sorted(ANCHORS.glob('*.yaml'))]


@pytest.mark.parametrize('path', SCENARIO_FILES, ids=lambda p: p.name)
def test_the_checks_read_the_records_and_never_change_them(path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Every scenario file bagfault ships and every one of the anchor's (where they are): the records as
    scenario/resolve.py left them are the same after the validator's checks, value for value."""
    from bagfault.scenario import validator
    from bagfault.scenario.loader import load_scenario

    seen: list[tuple[object, object]] = []
    checks = validator.validate_scenario

    def watched(scenario: object, out: object) -> None:
        before = _records(scenario)
        checks(scenario, out)  # type: ignore[arg-type]
        seen.append((before, _records(scenario)))

    monkeypatch.setattr(validator, 'validate_scenario', watched)
    with contextlib.suppress(ScenarioError):  # a file with problems is checked all the same
        load_scenario(path)
    [(before, after)] = seen
    assert repr(after) == repr(before)  # (repr: nan is not equal to itself)
