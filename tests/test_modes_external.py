"""Every mode on every third-party bag that `run` accepts: run, check, a campaign job, play (short, with
--record, with --foxglove) and test with a small system under test. Outputs are read by the ROS toolchain's
rules, rosbags' AnyReader and `rosbags-convert` (tests/toolchain.py); counts come from the mcap library.

The bags are those of io_cases.ROSBAG2_DIRS (rosbag2 itself reads them) and the ROS 1 and bare MCAP robot bags
of ../shared/external_bags; every case skips, saying so, without ../shared. tests/fixtures/quirks.py holds their
quirks for a fresh clone (tests/closedloop/test_one_clock.py, tests/view, tests/live).
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest
from support.helpers import EXTERNAL, counts, third_party
from support.io_cases import ROSBAG2_DIRS
from support.rosbag2_rules import DISTROS, check_mcap, distros_reading
from support.toolchain import assert_toolchain_opens

from bagfault import api
from bagfault.cli import main
from bagfault.io.sources import InputSet
from bagfault.live import rclpy_available
from bagfault.scenario import parse_scenario

BAGS = [*ROSBAG2_DIRS, 'evo/test/data/nav2_turtlebot.mcap', 'evo/test/data/ROS_example.bag',
        'evo/test/data/tf_example.bag', 'robot_localization/test/test1.bag', 'rosbag.js/fixtures/example.bag']
# rosbags' AnyReader cannot parse rosbag2's service-event schemas ('req --- resp'), in the input as in the
# output, which copies them verbatim: for these bags the toolchain check is rosbag2's rules alone.
ROSBAGS_CANNOT_READ = {
    'rosbag2/rosbag2_tests/resources/mcap/bag_with_topics_and_service_events',
    'rosbag2/rosbag2_tests/resources/sqlite3/bag_with_topics_and_service_events',
}
PASS = parse_scenario('injectors: []\n')
ROOT = Path(__file__).resolve().parents[1]
HEARTBEAT = """
import sys
import rclpy
from rclpy.node import Node
from std_msgs.msg import String
rclpy.init(args=sys.argv)
node = Node('heartbeat')
publisher = node.create_publisher(String, '/heartbeat', 10)
node.create_timer(0.05, lambda: publisher.publish(String(data='alive')))
try:
    rclpy.spin(node)
except Exception:
    pass
"""


# Stored definitions that do not describe the data: rosbag2's test bag keeps one-line stand-ins in its
# message_definitions table ('uint8 level' for rcl_interfaces/msg/Log), which outputs carry on as rosbag2 would.
STAND_IN_DEFINITIONS = {'rosbag2/rosbag2_py/test/resources/sqlite3/talker': {'/rosout', '/parameter_events'}}


QUIRKS = 'tests/fixtures/quirks.py'  # the quirks of these bags in one bag of our own: the fresh clone runs it
CASES = [*third_party(BAGS), QUIRKS]


@pytest.fixture
def bag(request: pytest.FixtureRequest, relative: str) -> Path:
    """The bag of a case (the quirks fixture is made on first use)."""
    if relative == QUIRKS:
        return Path(request.getfixturevalue('quirks_bag'))
    return EXTERNAL / relative


def opens(path: Path, tmp_path: Path, relative: str, bag: Path) -> None:
    """The output opens wherever its input opened: a Jazzy MCAP's name-form QoS is kept on the channels whose
    chunks are copied, so those outputs are held to Jazzy's reader alone."""
    distros = distros_reading(bag) if bag.suffix == '.mcap' else DISTROS
    if relative in ROSBAGS_CANNOT_READ:
        check_mcap(path, distros)
    else:
        assert_toolchain_opens(path, tmp_path, distros=distros, undecodable=STAND_IN_DEFINITIONS.get(relative, ()))


@pytest.mark.parametrize('relative', CASES)
def test_run_and_check(relative: str, bag: Path, tmp_path: Path) -> None:
    out = tmp_path / 'out.mcap'
    result = api.run(PASS, [bag], out)
    assert sum(counts(out).values()) == result.stats.output_messages == result.stats.input_messages
    opens(out, tmp_path, relative, bag)
    assert main(['check', _scenario(tmp_path), str(out)]) == 0


def _scenario(tmp_path: Path) -> str:
    path = tmp_path / 'pass.yaml'
    path.write_text('injectors: []\n')
    return str(path)


def test_a_campaign_job_per_bag(tmp_path: Path) -> None:
    present = [r for r in BAGS if (EXTERNAL / r).exists()]
    if not present:
        pytest.skip(f'needs third-party data: {EXTERNAL} not present (set BAGFAULT_SHARED)')
    (tmp_path / 'pass.yaml').write_text('injectors: []\n')
    bags = ', '.join(json.dumps(str(EXTERNAL / r)) for r in present)
    (tmp_path / 'campaign.yaml').write_text(f'campaign: every_bag\nscenario: pass.yaml\nbags: [{bags}]\n'
                                            'keep: all\n')
    assert main(['campaign', str(tmp_path / 'campaign.yaml'), '-o', str(tmp_path / 'out'), '--workers', '2']) == 0
    plan = json.loads((tmp_path / 'out' / 'campaign.json').read_text())
    assert len(plan['jobs']) == len(present)
    for job in plan['jobs']:
        output = tmp_path / 'out' / 'outputs' / f'{job["key"]}.mcap'
        relative = str(Path(job['bag']).resolve().relative_to(EXTERNAL.resolve()))
        opens(output, tmp_path, relative, EXTERNAL / relative)


@pytest.fixture
def live_env(tmp_path: Path):
    if not rclpy_available():
        pytest.skip("rclpy not installed (pip install '.[live]')")
    import bagfault.live
    from bagfault.closedloop.domain import DomainLease

    lease = DomainLease()
    env = {**os.environ, 'ROS_DOMAIN_ID': str(lease.domain), 'PYTHONPATH': str(ROOT),
           'FASTRTPS_DEFAULT_PROFILES_FILE': str(bagfault.live.LOOPBACK_PROFILE), 'PYTHONUNBUFFERED': '1'}
    yield env
    lease.release()


def duration(bag: Path) -> float:
    """Seconds from the bag's first to its last message."""
    with InputSet([bag]) as inputs:
        return ((inputs.end_time or 0) - (inputs.start_time or 0)) / 1e9


def _own_domain(env: dict[str, str]) -> dict[str, str]:
    """`bagfault test` leases its domain and brings its Fast DDS profile."""
    return {k: v for k, v in env.items() if k not in ('ROS_DOMAIN_ID', 'FASTRTPS_DEFAULT_PROFILES_FILE')}


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(('127.0.0.1', 0))
        return int(probe.getsockname()[1])


@pytest.mark.parametrize('relative', CASES)
def test_play_with_record_and_with_foxglove(relative: str, bag: Path, tmp_path: Path,
                                           live_env: dict[str, str]) -> None:
    reference = tmp_path / 'reference.mcap'
    api.run(PASS, [bag], reference)
    recorded = tmp_path / 'played.mcap'
    rate = f'{max(1.0, duration(bag) / 3):g}'  # about 3 s of play
    play = subprocess.run([sys.executable, '-m', 'bagfault.cli', 'play', str(bag), '--rate', rate, '--delay', '0',
                           '--record', str(recorded)], env=live_env, capture_output=True, text=True, timeout=180,
                          check=False)
    assert play.returncode == 0, play.stdout + play.stderr
    assert counts(recorded) == counts(reference)  # every message, each once, on its topic
    opens(recorded, tmp_path, relative, bag)
    pytest.importorskip('foxglove')
    port = _free_port()
    shown = subprocess.Popen([sys.executable, '-m', 'bagfault.cli', 'play', str(bag), '--rate', rate, '--delay', '0',
                              '--foxglove', f'127.0.0.1:{port}'], env=live_env, stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
    try:
        line = shown.stdout.readline()  # type: ignore[union-attr]
        assert f'Foxglove view on ws://127.0.0.1:{port}' in line, line + shown.stderr.read()  # type: ignore[union-attr]
    finally:
        shown.send_signal(signal.SIGINT)
        out, err = shown.communicate(timeout=60)
    assert shown.returncode == 0, out + err
    assert 'Traceback' not in err


@pytest.mark.parametrize('relative', CASES)
def test_closed_loop_with_a_small_system(relative: str, bag: Path, tmp_path: Path,
                                         live_env: dict[str, str]) -> None:
    (tmp_path / 'heartbeat.py').write_text(HEARTBEAT)
    scenario = tmp_path / 'loop.yaml'
    scenario.write_text(f"""name: heartbeat_loop
system_under_test:
  command: ['{{python}}', '{tmp_path / 'heartbeat.py'}']
  ready: [{{topic: /heartbeat, publisher: true}}]
  record: [/heartbeat]
  tail: 0.5
  stop_timeout: 10
injectors: []
""")
    out = tmp_path / 'loop.mcap'
    report = tmp_path / 'loop.json'
    seconds = duration(bag)
    rate = f'{max(1.0, seconds / 5):g}'  # about 5 s of play; a short bag as recorded (its heartbeats need time)
    done = subprocess.run([sys.executable, '-m', 'bagfault.cli', 'test', str(scenario), str(bag), '--rate', rate,
                           '-o', str(out), '--json', str(report)], env=_own_domain(live_env),
                          capture_output=True, text=True, timeout=300, check=False, cwd=tmp_path)
    assert done.returncode == 0, done.stdout + done.stderr
    loaded = json.loads(report.read_text())
    if seconds == 0:  # an empty bag: nothing to play, said so
        assert 'the input holds no messages' in ' '.join(loaded['notes'])
        return
    assert {a['id']: a['state'] for a in loaded['assertions']} == {'system_alive': 'passed'}
    recorded = counts(out)
    assert recorded['/heartbeat'] >= 1 and set(loaded['system_under_test']['heard_per_topic']) == {'/heartbeat'}
    opens(out, tmp_path, relative, bag)
