"""The `system_under_test:` and `bags:` sections: read, checked at their lines, overridden from the command line."""

from __future__ import annotations

import textwrap
from pathlib import Path

import pytest

from bagfault import api
from bagfault.errors import ScenarioError
from bagfault.scenario import load_scenario, parse_scenario
from bagfault.spec.system import ReadyCondition, SystemUnderTest, command_line, ready_spec

BASE = """
injector: {id: imu, type: imu, input_topic: /imu, output_topic: /imu}
faults: [{id: bias, injector_id: imu, config: {angular_velocity_z_bias: 0.1}}]
"""


def scenario_file(tmp_path: Path, section: str) -> Path:
    path = tmp_path / 'sub' / 'test_x.bagfault.yaml'
    path.parent.mkdir(exist_ok=True)
    path.write_text(BASE + textwrap.dedent(section))
    return path


def test_every_key_is_read(tmp_path: Path) -> None:
    path = scenario_file(tmp_path, """
        bags: [rover.mcap, ../other_bag]
        system_under_test:
          command: "ros2 launch my_pkg stack.launch.py 'map:=a b'"
          env: {LIMIT: 0.05, VERBOSE: true}
          cwd: work
          ready:
            - {topic: /diagnostics, publisher: true, timeout: 5}
            - {topic: /diagnostics, message: true}
            - {subscribes: [/imu]}
            - {service: /enable}
            - {delay: 0.5}
          record: [/cmd_vel, /diagnostics]
          stop_timeout: 2
          use_sim_time: false
          tail: 0
        """)
    scenario = load_scenario(path)
    system = scenario.system
    assert system is not None
    assert system.command == ['ros2', 'launch', 'my_pkg', 'stack.launch.py', 'map:=a b']  # split as a shell would
    assert system.env == {'LIMIT': '0.05', 'VERBOSE': 'true'}
    assert system.cwd == path.parent / 'work'
    assert system.ready == [
        ReadyCondition('publisher', name='/diagnostics', timeout=5.0),
        ReadyCondition('message', name='/diagnostics'),
        ReadyCondition('subscribes', topics=('/imu',)),
        ReadyCondition('service', name='/enable'),
        ReadyCondition('delay', seconds=0.5),
    ]
    assert system.record == ['/cmd_vel', '/diagnostics']
    assert (system.stop_timeout, system.use_sim_time, system.tail) == (2.0, False, 0.0)
    assert scenario.bags == [path.parent / 'rover.mcap', path.parent / '../other_bag']


def test_defaults_are_those_documented(tmp_path: Path) -> None:
    system = load_scenario(scenario_file(tmp_path, 'system_under_test: {command: [python3, m.py]}\n')).system
    assert system == SystemUnderTest(command=['python3', 'm.py'])
    assert system.conditions() == [ReadyCondition('default', timeout=30.0)]
    assert (system.record, system.stop_timeout, system.use_sim_time, system.tail) == ('all', 5.0, True, 1.0)


@pytest.mark.parametrize(('section', 'where', 'message'), [
    ('system_under_test: python3 m.py', 'system_under_test', 'must be a mapping'),
    ('system_under_test: {env: {}}', 'system_under_test', "missing required key 'command'"),
    ('system_under_test: {command: []}', 'system_under_test.command', 'must be a command line'),
    ('system_under_test: {command: x, ready: {delay: 1}}', 'system_under_test.ready', 'must be a list'),
    ('system_under_test: {command: x, ready: [{topic: /a, timeout: 0}]}', 'system_under_test.ready[0].timeout',
     '0 must be greater than 0'),
    ('system_under_test: {command: x, ready: [{topic: /a, timeout: .inf}]}', 'system_under_test.ready[0].timeout',
     'is not a time bagfault can schedule (0 to 3600 s)'),
    ('system_under_test: {command: x, ready: [{flag: /a}]}', 'system_under_test.ready[0].flag', "unknown key 'flag'"),
    ('system_under_test: {command: x, ready: [{timeout: 3}]}', 'system_under_test.ready[0]',
     'needs one of topic, subscribes, service or delay'),
    ('system_under_test: {command: x, ready: [{subscribes: some}]}', 'system_under_test.ready[0].subscribes',
     "must be 'played' or a list"),
    ('system_under_test: {command: x, record: /a}', 'system_under_test.record', "must be 'all' or a list"),
    ('system_under_test: {command: x, stop_timeout: -1}', 'system_under_test.stop_timeout', 'must be greater than 0'),
    ('system_under_test: {command: x, use_sim_time: yes please}', 'system_under_test.use_sim_time',
     'is not true or false'),
    ('system_under_test: {command: x, env: [A=1]}', 'system_under_test.env', 'must be a mapping of variable names'),
    ('system_under_test: {command: x, launch: y}', 'system_under_test.launch', "unknown key 'launch'"),
    ('bags: rover.mcap', 'bags', 'must be a list of bags'),
])
def test_problems_are_reported_at_their_place(tmp_path: Path, section: str, where: str, message: str) -> None:
    path = scenario_file(tmp_path, section + '\n')
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    [problem] = [p for p in info.value.problems if p.path == where]
    assert message in problem.message
    line = len(BASE.splitlines()) + 1  # the section is the line after BASE
    assert problem.where.startswith(f'{line}:')


def test_validate_reports_every_problem_of_the_section(tmp_path: Path) -> None:
    path = scenario_file(tmp_path, 'system_under_test: {command: [], stop_timeout: 0, record: 3}\n')
    with pytest.raises(ScenarioError) as info:
        api.validate([path])
    assert sorted(p.path for p in info.value.problems) == ['system_under_test.command', 'system_under_test.record',
                                                            'system_under_test.stop_timeout']


@pytest.mark.parametrize(('text', 'expected'), [
    ('publisher:/diagnostics', {'topic': '/diagnostics', 'publisher': True}),
    ('message:/scan@12', {'topic': '/scan', 'message': True, 'timeout': 12.0}),
    ('subscribes:played', {'subscribes': 'played'}),
    ('subscribes:/imu,/odom@3.5', {'subscribes': ['/imu', '/odom'], 'timeout': 3.5}),
    ('service:/enable_motors', {'service': '/enable_motors'}),
    ('delay:1.5', {'delay': 1.5}),
])
def test_ready_specs_from_the_command_line(text: str, expected: dict[str, object]) -> None:
    assert ready_spec(text) == expected


def test_command_line_values_replace_the_scenario_keys(tmp_path: Path) -> None:
    path = scenario_file(tmp_path, """
        system_under_test:
          command: [python3, m.py]
          env: {A: '1', B: '2'}
          ready: [{delay: 1}]
        """)
    scenario = load_scenario(path)
    system = api.system_of(scenario, {'command': 'python3 other.py --fast', 'env': {'B': '3', 'C': '4'},
                                      'ready': [ready_spec('publisher:/x@2')], 'stop_timeout': 1.0,
                                      'use_sim_time': False, 'cwd': 'here'})
    assert system.command == ['python3', 'other.py', '--fast']
    assert system.env == {'A': '1', 'B': '3', 'C': '4'}  # added to, not replaced
    assert system.ready == [ReadyCondition('publisher', name='/x', timeout=2.0)]
    assert (system.stop_timeout, system.use_sim_time) == (1.0, False)
    assert system.cwd == Path('here')  # relative to where bagfault runs, not to the scenario
    with pytest.raises(ScenarioError, match='stop_timeout'):
        api.system_of(scenario, {'stop_timeout': -3.0})


def test_test_needs_a_system_and_a_bag(tmp_path: Path) -> None:
    plain = parse_scenario(BASE)
    with pytest.raises(ScenarioError, match='needs a system under test'):
        api.system_of(plain, {})
    assert api.system_of(plain, {'command': 'python3 m.py'}).command == ['python3', 'm.py']


@pytest.mark.parametrize(('command', 'shell', 'sim', 'expected'), [
    (['{python}', 'm.py'], False, True, ['/py', 'm.py', '--ros-args', '-p', 'use_sim_time:=true']),
    (['ros2', 'launch', 'pkg', 'a.launch.py'], False, True, ['ros2', 'launch', 'pkg', 'a.launch.py',
                                                             'use_sim_time:=true']),
    (['/opt/ros/jazzy/bin/ros2', 'run', 'pkg', 'node'], False, True,
     ['/opt/ros/jazzy/bin/ros2', 'run', 'pkg', 'node', '--ros-args', '-p', 'use_sim_time:=true']),
    (['ros2 launch pkg a.launch.py > out.txt'], True, True, ['ros2 launch pkg a.launch.py > out.txt use_sim_time:=true']),
    (['{python} m.py'], True, True, ['/py m.py --ros-args -p use_sim_time:=true']),
    (['{python}', 'm.py'], False, False, ['/py', 'm.py']),
])
def test_use_sim_time_is_passed_where_it_applies(command: list[str], shell: bool, sim: bool,
                                                 expected: list[str]) -> None:
    system = SystemUnderTest(command=command, shell=shell, use_sim_time=sim)
    assert command_line(system, '/py') == expected
