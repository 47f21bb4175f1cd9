"""Booleans as yaml-cpp's `as<bool>()` reads them (yaml-cpp src/convert.cpp, `convert<bool>::decode`: y/n,
yes/no, true/false, on/off, each all lower, all upper or capitalised), and medkit's keys read that way
(ros2_medkit 505bc2d5, src/ros2_medkit_fault_manager/src/correlation/config_parser.cpp:37 `get_bool`)."""

from __future__ import annotations

import pytest
import yaml

from bagfault.fault_manager.config import parse_fault_manager
from bagfault.fault_manager.correlation import parse_correlation
from bagfault.yamlcpp import as_bool

TRUE = ['y', 'Y', 'yes', 'Yes', 'YES', 'true', 'True', 'TRUE', 'on', 'On', 'ON', True]
FALSE = ['n', 'N', 'no', 'No', 'NO', 'false', 'False', 'FALSE', 'off', 'Off', 'OFF', False]
NOT_BOOLEAN = ['tRUE', 'yEs', 'enable', '1', '0', '', 1, 0, 1.0, None, [], {}]


@pytest.mark.parametrize('value', TRUE)
def test_true_spellings(value: object) -> None:
    assert as_bool(value) is True


@pytest.mark.parametrize('value', FALSE)
def test_false_spellings(value: object) -> None:
    assert as_bool(value) is False


@pytest.mark.parametrize('value', NOT_BOOLEAN)
def test_bad_conversions(value: object) -> None:
    assert as_bool(value) is None


RULES = """
enabled: '{enabled}'
rules:
  - id: estop
    mode: hierarchical
    root_cause: {{codes: [ESTOP]}}
    symptoms: [{{codes: [MOTOR_A]}}]
    mute_symptoms: 'false'
    auto_clear_with_root: "no"
  - id: bursts
    mode: auto_cluster
    match: [{{pattern: 'SENSOR_*'}}]
    show_as_single: 'N'
"""


def parsed(text: str) -> tuple[object, list[str]]:
    problems: list[str] = []
    config = parse_correlation(yaml.safe_load(text), ('correlation',), lambda p, m: problems.append(m))
    return config, problems


def test_quoted_booleans_of_the_correlation_section_read_as_medkit_reads_them() -> None:
    """PyYAML keeps 'false' a string (truthy); yaml-cpp's as<bool> gives false: correlation stays off and the
    rules neither mute nor auto-clear nor fold, as in medkit."""
    config, problems = parsed(RULES.format(enabled='false'))
    assert problems == []
    assert config.enabled is False
    estop, bursts = config.rules
    assert (estop.mute_symptoms, estop.auto_clear_with_root, bursts.show_as_single) == (False, False, False)
    config, _ = parsed(RULES.format(enabled='True'))
    assert config.enabled is True


def test_a_value_yaml_cpp_cannot_convert_is_a_problem() -> None:
    """medkit's as<bool> throws (a bad conversion) where PyYAML would have said truthy."""
    _, problems = parsed(RULES.format(enabled='maybe'))
    assert problems == ["'maybe' is not a boolean as medkit's yaml-cpp reads one (true/false, yes/no, on/off, y/n)"]


def test_snapshots_enabled_is_a_bool_parameter() -> None:
    """medkit declares snapshots.enabled with declare_parameter<bool> (fault_manager_node.cpp:1140): a quoted
    value is a string parameter there, refused; bagfault refuses it instead of reading it as true."""
    problems: list[str] = []
    parse_fault_manager({'snapshots': {'enabled': 'false'}}, lambda p, m: problems.append(m))
    assert problems == ["'false' is not true or false (medkit declares snapshots.enabled as a bool parameter; "
                        'a quoted value is a string there)']
    problems.clear()
    config = parse_fault_manager({'snapshots': {'enabled': False}}, lambda p, m: problems.append(m))
    assert problems == [] and config.snapshots.enabled is False


@pytest.mark.parametrize(('written', 'read'), [('250', 250), ("'250'", 250), ('0x100', 256), ('250.0', None),
                                               ('-5', None), ("'4294967296'", None)])
def test_correlation_windows_and_counts_are_uint32_as_medkit_reads_them(written: str, read: int | None) -> None:
    """config_parser.cpp:45 `get_uint32`: node[key].as<uint32_t>() (a quoted number counts; a float, a negative
    number or one past 2^32-1 throws)."""
    text = (f"enabled: true\ndefault_window_ms: {written}\npatterns: {{sensors: {{codes: ['S_*']}}}}\nrules:\n"
            f'  - {{id: b, mode: auto_cluster, match: [{{pattern: sensors}}], min_count: {written}, '
            f'window_ms: {written}}}\n')
    config, problems = parsed(text)
    if read is None:
        assert len(problems) == 3 and all('is not an integer from 1 to 4294967295' in p for p in problems)
    else:
        assert problems == [] and config.default_window_ms == read
        (rule,) = config.rules
        assert (rule.window_ms, rule.min_count) == (read, read)
