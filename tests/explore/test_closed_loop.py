"""`bagfault explore` in closed loop: the planted-bug system of bench/explore (real rclpy processes, each run on
its own leased domain) on a 4 s bag; its odometry teleport bug (B8 of bench/explore/bugs.yaml: x jumps by more
than 1.0 m between consecutive odometry messages, the jump is x_bias + 0.004 m at the fault's start) found and
shrunk to its threshold, each step confirmed by a second run; the clock held to look for wall time in the baseline
run only."""

from __future__ import annotations

import html
import json

import pytest
import yaml
from support.helpers import ROOT, make_bag
from support.loop import WALL_CLOCK_SYSTEM, rclpy_available

from bagfault import api

pytestmark = [pytest.mark.live, pytest.mark.closed_loop, pytest.mark.slow]
BENCH = ROOT / 'bench' / 'explore'


def test_a_planted_bug_is_found_and_shrunk_in_closed_loop(tmp_path):
    if not rclpy_available():
        pytest.skip("rclpy not installed (pip install '.[live]')")
    make_bag(tmp_path / 'rover.mcap', [('/imu', 'sensor_msgs/msg/Imu', 50.0),
                                       ('/odom', 'nav_msgs/msg/Odometry', 25.0)], 4.0)
    data = yaml.safe_load((BENCH / 'space.yaml').read_text())
    data['bags'] = ['rover.mcap']
    data['system_under_test']['cwd'] = str(BENCH)
    data['injectors'] = [i for i in data['injectors'] if i['id'] != 'scan']
    data['explore'] = {'faults': [{'id': 'odom_jump', 'injector_id': 'odom', 'start': 1.0, 'duration': 0.5,
                                   'config': {'x_bias': [0.5, 2.0]}}],
                       'budget': 16, 'confirm': 2, 'batch': 2, 'resolution': 0.1}  # a short test: 10 % of the range
    space = tmp_path / 'space.yaml'
    space.write_text(yaml.safe_dump(data))
    result = api.explore(space, directory=tmp_path / 'out', workers=2, rate=4.0, seed=2)
    assert [r.outcome.status for r in result.runs].count('error') == 0, [r.outcome.message for r in result.runs]
    assert result.runs[0].outcome.status == 'passed'  # no fault: no bug
    (failure,) = result.failures
    assert failure.assertions == {'estimate_bounded'} and failure.state == 'shrunk'
    bias = dict(failure.minimal.drawn('odom_jump').values)['config.x_bias']
    assert 0.996 < bias <= 0.996 + 0.15 + 0.0015  # 10 % of the range, on the grid
    kept = [s for s in failure.steps if s.kept and s.change != 'confirm the original']
    assert all(s.runs == 2 for s in kept)  # confirm: 2
    assert failure.replay is not None and failure.replay.failing == {'estimate_bounded'}
    document = json.loads((tmp_path / 'out' / 'explore.json').read_text())
    assert document['mode'] == 'test' and document['rate'] == 4.0
    assert (tmp_path / 'out' / 'failures' / f'{failure.name}.mcap').stat().st_size > 0  # the replay's recording


def test_only_the_baseline_holds_the_clock_to_look_for_wall_time(tmp_path):
    """At a rate other than 1 a closed-loop run holds the sim clock still for HOLD (1 s) before the first record
    to see what the system publishes on wall time; an exploration looks in its baseline run only. By
    construction, a system on a 10 Hz wall-clock timer at rate 2: the baseline's warning names its topic (on
    the result, in explore.json and the report). That the later runs do not look is shown by the jobs they are
    given (test_explore.py): their wall time, a second shorter on a quiet machine, was longer than the
    baseline's beside a second suite."""
    if not rclpy_available():
        pytest.skip("rclpy not installed (pip install '.[live]')")
    make_bag(tmp_path / 'rover.mcap', [('/imu', 'sensor_msgs/msg/Imu', 50.0)], 2.0)
    (tmp_path / 'wall.py').write_text(WALL_CLOCK_SYSTEM)
    space = tmp_path / 'space.yaml'
    space.write_text(yaml.safe_dump({
        'bags': ['rover.mcap'],
        'system_under_test': {'command': ['{python}', 'wall.py'], 'cwd': str(tmp_path), 'record': ['/temperature'],
                              'stop_timeout': 10},
        'injectors': [{'id': 'imu', 'type': 'imu', 'input_topic': '/imu', 'output_topic': '/imu'}],
        'faults': [],
        'assertions': [{'id': 'status_heard', 'type': 'message_count', 'topic': '/temperature', 'min': 1}],
        'explore': {'faults': [{'id': 'drift', 'injector_id': 'imu', 'start': 0.5, 'duration': 0.5,
                                'config': {'angular_velocity_z_bias': [0.0, 1.0]}}], 'budget': 5, 'batch': 2},
    }))
    result = api.explore(space, directory=tmp_path / 'out', workers=1, rate=2.0, seed=1)
    assert [r.outcome.status for r in result.runs] == ['passed'] * 5, [r.outcome.message for r in result.runs]
    held = [w for w in result.warnings if w.startswith('/temperature: published ') and 'stood still' in w]
    assert held, result.warnings
    document = json.loads((tmp_path / 'out' / 'explore.json').read_text())
    assert document['baseline_warnings'] == result.warnings
    assert held[0] in html.unescape((tmp_path / 'out' / 'report.html').read_text())  # the report says it too
