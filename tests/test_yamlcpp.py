"""bagfault.yamlcpp against yaml-cpp itself: a small C++ program (support/yamlcpp_oracle.cpp) built here with
the system's yaml-cpp prints what `node.as<bool>()`, `as<long long>()`, `as<unsigned long>()` and
`as<double>()` give for each scalar, plain and quoted; the module must agree on every one. The references
(ros2_fault_injection, ros2_medkit) read their files with these conversions.
"""

from __future__ import annotations

import json
import math
import shutil
import subprocess
import textwrap
from pathlib import Path

import pytest

from bagfault.scenario import parse_scenario
from bagfault.yamlcpp import as_bool, as_double, as_int

ORACLE = Path(__file__).parent / 'support' / 'yamlcpp_oracle.cpp'
SCALARS = [
    # booleans: yaml-cpp's table (convert.cpp), in its three cases, and near misses
    'y', 'Y', 'n', 'N', 'yes', 'Yes', 'YES', 'no', 'No', 'NO', 'true', 'True', 'TRUE', 'false', 'False', 'FALSE',
    'on', 'On', 'ON', 'off', 'Off', 'OFF', 'tRUE', 'yEs', 'nO', 't', 'f', '1', '0', 'enable',
    # integers and their bases
    '5', '+5', '-3', '-0', '0', '00', '010', '08', '0x10', '0X1f', '0xg', '0b101', '0o17', '1_000', '1,000',
    '9223372036854775807', '9223372036854775808', '-9223372036854775808', '18446744073709551615',
    '18446744073709551616', '5 ', ' 5', '5.', '5.0', '1e3',
    # floats and special values
    '1.5', '-1.5', '+1.5', '.5', '-.5', '1.', '1e-3', '1E+3', '2.5e10', '1e400', '-1e400', '1e-400', '0.1e1',
    '.inf', '.Inf', '.INF', '+.inf', '+.INF', '-.inf', '-.Inf', '-.INF', '.nan', '.NaN', '.NAN', 'inf',
    'Infinity', 'nan', 'NaN', '-inf', '0x1p3', '1:30', '1.5.2', '', ' ', 'abc', '5abc', '١',
]


@pytest.fixture(scope='module')
def oracle(tmp_path_factory: pytest.TempPathFactory) -> Path:
    compiler = shutil.which('g++')
    if compiler is None or not Path('/usr/include/yaml-cpp/yaml.h').exists():
        pytest.skip("needs g++ and yaml-cpp's headers (Debian: apt-get install g++ libyaml-cpp-dev)")
    binary = tmp_path_factory.mktemp('yamlcpp') / 'oracle'
    subprocess.run([compiler, '-O1', '-o', str(binary), str(ORACLE), '-lyaml-cpp'], check=True, timeout=300)
    return binary


def as_yaml_cpp(oracle: Path, documents: list[str]) -> list[list[str]]:
    """yaml-cpp's four conversions of each scalar of a YAML sequence."""
    done = subprocess.run([str(oracle)], input=''.join(f'- {d}\n' for d in documents), capture_output=True,
                          text=True, timeout=60, check=True)
    return [line.split('\t') for line in done.stdout.splitlines()]


def ours(text: str) -> list[str]:
    """The module's four conversions, printed as the oracle prints them."""
    def show(value: object) -> str:
        if value is None:
            return 'x'
        if isinstance(value, bool):
            return 'true' if value else 'false'
        if isinstance(value, float):
            return 'nan' if math.isnan(value) else 'inf' if value == math.inf else '-inf' if value == -math.inf \
                else value
        return str(value)
    return [show(as_bool(text)), show(as_int(text)), show(as_int(text, unsigned=True)), show(as_double(text))]


def same(theirs: str, mine: object) -> bool:
    if isinstance(mine, float):
        return theirs not in ('x', 'nan', 'inf', '-inf') and float(theirs) == mine
    return theirs == mine


def test_every_scalar_converts_as_yaml_cpp_converts_it_quoted(oracle: Path) -> None:
    """Quoted, every text reaches yaml-cpp as it is (its conversions ignore the quoting)."""
    got = as_yaml_cpp(oracle, [json.dumps(s) for s in SCALARS])
    assert len(got) == len(SCALARS)
    wrong = {s: (theirs, ours(s)) for s, theirs in zip(SCALARS, got, strict=True)
             if not all(same(t, m) for t, m in zip(theirs, ours(s), strict=True))}
    assert wrong == {}


def test_plain_scalars_too(oracle: Path) -> None:
    """Unquoted (where YAML allows it): the same text, the same results."""
    plain = [s for s in SCALARS if s and s.strip() == s and not s.startswith(('-', ':')) and ',' not in s]
    got = as_yaml_cpp(oracle, plain)
    wrong = {s: (theirs, ours(s)) for s, theirs in zip(plain, got, strict=True)
             if not all(same(t, m) for t, m in zip(theirs, ours(s), strict=True))}
    assert wrong == {}


@pytest.mark.parametrize(('written', 'start'), [('5', 5.0), ('"5"', 5.0), ('1e1', 10.0), ('.5', 0.5),
                                                ('1_000', None), ('0x10', None), ('" 5"', None)])
def test_a_fault_start_is_read_as_the_anchor_reads_it(written: str, start: float | None) -> None:
    """scenario_config.cpp: node["start"].as<double>(); `1_000` and `0x10` (numbers to PyYAML) it refuses."""
    text = textwrap.dedent(f"""
        injector: {{id: imu, type: imu, input_topic: /imu, output_topic: /imu_out}}
        faults: [{{id: f, injector_id: imu, start: {written}, config: {{angular_velocity_z_bias: 1.0}}}}]
    """)
    if start is None:
        with pytest.raises(Exception, match='is not a number of seconds'):
            parse_scenario(text)
    else:
        assert parse_scenario(text).faults[0].start == start


@pytest.mark.parametrize(('written', 'depth'), [('5', 5), ('"7"', 7), ('0x10', 16), ('010', 8), ('5.0', None),
                                                ('-1', None)])
def test_qos_depth_is_read_as_an_unsigned_size(written: str, depth: int | None) -> None:
    """scenario_config.cpp: topic_node["qos_depth"].as<std::size_t>()."""
    text = textwrap.dedent(f"""
        injector: {{id: imu, type: imu, topic: {{input_topic: /imu, output_topic: /imu_out, qos_depth: {written}}}}}
        faults: []
    """)
    if depth is None:
        with pytest.raises(Exception, match='is not a positive integer'):
            parse_scenario(text)
    else:
        assert parse_scenario(text).injectors[0].qos_depth == depth


@pytest.mark.parametrize(('written', 'warned'), [('10', False), ('"10"', False), ('1e1', False), ('1_0', True),
                                                 ('0x10', True)])
def test_topic_hz_numbers_the_anchor_would_refuse_are_warnings(written: str, warned: bool) -> None:
    """scenario_config.cpp reads min_hz and window with as<double>(): a spelling it refuses (numbers to PyYAML)
    is read here with a warning naming the refusal, and refused under --strict."""
    text = textwrap.dedent(f"""
        injector: {{id: imu, type: imu, input_topic: /imu, output_topic: /imu_out}}
        faults: []
        assertions:
          - {{id: hz, type: topic_hz, topic: /imu_out, message_type: sensor_msgs/msg/Imu, min_hz: {written},
             window: 1.0}}
    """)
    scenario = parse_scenario(text)
    assert scenario.assertions[0].params['min_hz'] in (10.0, 16.0)
    assert any('yaml-cpp refuses it (as<double>' in w for w in scenario.warnings) == warned
    if warned:
        with pytest.raises(Exception, match='as<double>'):
            parse_scenario(text, strict=True)
