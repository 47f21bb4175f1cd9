"""Sim time is one clock: a bag's own /clock (a simulator's recording) is never published beside bagfault's.

The system under test is the example's safety monitor with a 0.5 s odometry
watchdog on ROS time. The bags' largest /odom gap is 0.39 s (TurtleBot,
measured with rosbags) and 0.04 s (the quirks fixture), so on one clock the
watchdog never fires; with the bag's /clock (1396 s) published beside
bagfault's (1.7e9 s) its time jumps and it fires.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from support.helpers import EXTERNAL, need
from support.loop import EXAMPLE, WALL_CLOCK_SYSTEM, LoopRunner

TURTLEBOT = EXTERNAL / 'Turtlebot_Walker_Algorithm_ROS2' / 'walker_bag_topics_list'


def watchdog_scenario(folder: Path, bag: Path) -> Path:
    path = folder / 'watchdog.bagfault.yaml'
    path.write_text(f"""name: watchdog_one_clock
bags: ['{bag}']
system_under_test:
  command: ['{{python}}', '{EXAMPLE / 'monitor.py'}', '--timeout', '0.5']
  ready:
    - {{subscribes: [/imu, /odom], timeout: 30}}
    - {{topic: /diagnostics, publisher: true}}
  stop_timeout: 10
  tail: 0.2   # after the bag the input is silent for real: 0.5 s later the watchdog fires, rightly
injectors: []
faults: []
fault_manager:
  diagnostics: {{codes: {{'odom_watchdog: timeout': ODOM_TIMEOUT}}}}
assertions:
  - {{id: no_false_alarm, type: fault_status, code: ODOM_TIMEOUT, status: CONFIRMED, never: true}}
  - {{id: diagnostics_heard, type: message_count, topic: /diagnostics, min: 10}}
""")
    return path


def judge(tester: LoopRunner, bag: Path, tmp_path: Path) -> None:
    out = tmp_path / 'loop.mcap'
    result = tester.run(str(watchdog_scenario(tmp_path, bag)), '-o', str(out))
    assert result.code == 0, result.stdout + result.stderr
    report = result.report
    assert {a['id']: a['state'] for a in report['assertions']} == {
        'system_alive': 'passed', 'no_false_alarm': 'passed', 'diagnostics_heard': 'passed'}
    system = report['system_under_test']
    domain = system['ros_domain_id']  # said when the system started, so a tool can be attached while it runs
    assert f'started on ROS domain {domain}; to watch it: ROS_DOMAIN_ID={domain} ' in result.stdout
    assert '/clock' not in system['played_per_topic'] and system['played_per_topic']['/odom'] > 0
    assert set(system['heard_per_topic']) == {'/diagnostics'}  # bagfault's own topics are not the system's
    assert any("bag's own /clock was not published" in note for note in report['notes'])


def test_the_quirks_bags_own_clock_is_left_out_and_the_watchdog_stays_quiet(tester: LoopRunner, quirks_bag: Path,
                                                                           tmp_path: Path) -> None:
    judge(tester, quirks_bag, tmp_path)


@pytest.mark.parametrize('run', range(5))
def test_the_turtlebot_bag_gives_no_false_alarm_five_times_of_five(tester: LoopRunner, tmp_path: Path,
                                                                   run: int) -> None:
    judge(tester, need(TURTLEBOT), tmp_path)


def test_a_system_on_wall_time_is_named_when_the_rate_is_not_one(tester: LoopRunner, tmp_path: Path) -> None:
    import sys

    sys.path.insert(0, str(EXAMPLE))
    try:
        import make_bag
    finally:
        sys.path.remove(str(EXAMPLE))
    bag = make_bag.write(tmp_path / 'rover.mcap', 3.0)  # bag time starts near zero, far from the wall clock
    (tmp_path / 'wall.py').write_text(WALL_CLOCK_SYSTEM)
    scenario = tmp_path / 'wall.bagfault.yaml'
    scenario.write_text(f"""name: wall_clock
bags: ['{bag}']
system_under_test:
  command: ['{{python}}', wall.py]
  record: [/temperature]
  stop_timeout: 10
injectors: []
faults: []
assertions:
  - {{id: status_heard, type: message_count, topic: /temperature, min: 1}}
""")
    result = tester.run(str(scenario), '--rate', '2')
    assert result.code == 0, result.stdout + result.stderr
    warnings = result.report['warnings']
    # 10 Hz on a steady timer: heard about 8 times in the 0.8 s counted of the clock's 1 s standstill
    assert any(w.startswith('/temperature: published ') and 'while the sim clock stood still' in w
               and 'run with --rate 1' in w for w in warnings), warnings
    assert any(w.startswith('/temperature: ') and 'header stamps follow the wall clock' in w for w in warnings)
    assert 'while the sim clock stood still' in result.stderr  # warnings go to stderr as they do for every command
