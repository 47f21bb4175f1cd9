"""A leased domain is checked, not assumed: strangers before the start move the run on, during it void it."""

from __future__ import annotations

import os
import random
import re
import socket
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import pytest
from support.helpers import claim_port_base
from support.loop import SCENARIO, LoopRunner, running_with

from bagfault.live import LOOPBACK_PROFILE

pytestmark = pytest.mark.live  # needs rclpy

TALKER = """
import sys, time
import rclpy
from sensor_msgs.msg import Imu
rclpy.init()
node = rclpy.create_node(sys.argv[1])
topic = sys.argv[2]
publisher = node.create_publisher(Imu, topic, 10) if topic != '-' else None
print('up', flush=True)
while True:
    if publisher is not None:
        message = Imu()
        message.angular_velocity.z = 5.0
        publisher.publish(message)
    time.sleep(0.02)
"""


def stranger(domain: int, name: str, topic: str, token: str) -> subprocess.Popen[str]:
    """A plain rclpy node on `domain` in a process of its own (publishing on `topic`, or nothing for '-')."""
    env = {**os.environ, 'ROS_DOMAIN_ID': str(domain), 'FASTRTPS_DEFAULT_PROFILES_FILE': str(LOOPBACK_PROFILE)}
    process = subprocess.Popen([sys.executable, '-c', TALKER, name, topic, token], env=env, text=True,
                               stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
    assert process.stdout is not None and process.stdout.readline().strip() == 'up'
    return process


def ended(process: subprocess.Popen[str]) -> None:
    process.kill()
    process.wait(timeout=10)


@pytest.mark.parametrize('attempt', [1, 2, 3])
def test_a_foreign_publisher_on_the_leased_domain_voids_the_run(tester: LoopRunner, example_bag: Path,
                                                                attempt: int) -> None:
    token = tester.token()
    process, report = tester.start(str(SCENARIO), str(example_bag), '-o', str(tester.tmp / 'out.mcap'), name=token)
    assert process.stdout is not None
    line = process.stdout.readline()
    domain = int(re.search(r'on ROS domain (\d+)', line).group(1))  # type: ignore[union-attr]
    intruder = stranger(domain, f'intruder_{attempt}', '/imu', token)
    try:
        outcome = tester.finish(process, report)
    finally:
        ended(intruder)
    assert outcome.code == 2, (outcome.stdout, outcome.stderr)
    (message,) = [line for line in outcome.stderr.splitlines() if line.startswith('bagfault')]
    assert f'ROS domain {domain} is not isolated' in message
    assert f'/intruder_{attempt} (pid {intruder.pid}) publishing /imu' in message
    assert 'nothing judged' in message
    assert not (tester.tmp / 'out.mcap').exists()  # no verdicts, no recording under the requested name
    assert running_with(token) == []


def test_a_listener_attached_to_watch_is_named_but_does_not_void_the_run(tester: LoopRunner, example_bag: Path) -> None:
    token = tester.token()
    process, report = tester.start(str(SCENARIO), str(example_bag), name=token)
    assert process.stdout is not None
    domain = int(re.search(r'on ROS domain (\d+)', process.stdout.readline()).group(1))  # type: ignore[union-attr]
    watcher = stranger(domain, 'watching_engineer', '-', token)
    try:
        outcome = tester.finish(process, report)
    finally:
        ended(watcher)
    assert outcome.code in (0, 1), outcome.stderr
    assert outcome.report is not None
    assert any(f'on ROS domain {domain} too' in n and f'/watching_engineer (pid {watcher.pid}) listening only' in n
               for n in outcome.report['notes']), outcome.report['notes']


def three_domains() -> list[tuple[int, socket.socket]]:
    """Three consecutive domain ids above the leases' range, claimed the way domain_coordinator claims them (so a
    second test suite running this test beside this one takes three others), with their claims."""
    from bagfault.closedloop.domain import LAST, claim_port

    for first in range(LAST + 1, 230, 3):
        claims = [(domain, claim_port(domain)) for domain in range(first, first + 3)]
        held = [(domain, claim) for domain, claim in claims if claim is not None]
        if len(held) == 3:
            return held
        for _, claim in held:
            claim.close()
    pytest.fail('no three consecutive free domain ids above the leases')


def test_a_crowded_domain_is_passed_over_and_the_system_started_there_stopped(
        tmp_path: Path, example_bag: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture) -> None:
    """The system starts while bagfault looks at the leased domain; nodes of another process there (one that
    only listens too) stop it, and it starts again on the next domain; with none left, one line names them."""
    pytest.importorskip('rclpy')
    from bagfault import api
    from bagfault.closedloop import runner
    from bagfault.engine.stop import StopFlag
    from bagfault.errors import ClosedLoopError

    monkeypatch.setenv('BAGFAULT_DOMAIN_LOCKS', str(tmp_path / 'locks'))
    monkeypatch.setenv('FASTRTPS_DEFAULT_PROFILES_FILE', str(LOOPBACK_PROFILE))
    # (a participant made again in one process can take a second to be seen: a long look here; a fresh
    # `bagfault test` sees a node in ~0.2 s, and its DomainWatch catches any the first look missed)
    monkeypatch.setattr(runner, 'PRESTART', 3.0)
    caplog.set_level('INFO', logger='bagfault')
    claims = three_domains()  # outside the leases' range, and no other test suite's: no other run is there
    crowded, free, other = (domain for domain, _ in claims)
    # this test's own leases claim their ports at another base, so the claims above keep only others away
    monkeypatch.setenv('BAGFAULT_DOMAIN_PORT_BASE', str(claim_port_base(random.Random())))
    token = f'crowd{os.getpid()}'
    scenario = api.load_scenario(SCENARIO)
    system = api.system_of(scenario, {'command': f'{{python}} monitor.py --hardware-id {token}'})
    sitters = [stranger(crowded, 'sitter', '/imu', 'x'), stranger(other, 'listener', '-', 'x')]
    try:
        result = runner.run_test(scenario, [example_bag], None, system=system, seed=7, rate=1.0, logs=None,
                                 stop=StopFlag(), first=crowded, last=other)
        assert result.system is not None and result.system.domain_id == free
        def said(text: str) -> list[int]:
            return [int(re.search(r'domain (\d+)', r.getMessage()).group(1))  # type: ignore[union-attr]
                    for r in caplog.records if text in r.getMessage()]

        passed_over = said('has nodes of other processes')  # the system started there, then stopped
        assert said('system under test started') == [free]  # announced once the domain is the run's alone
        assert set(passed_over) <= {crowded, other}  # leases start where the process id says: crowded first or not
        assert not result.failed, [a.message for a in result.assertions if a.state != 'passed']
        assert running_with(token) == []
        with pytest.raises(ClosedLoopError) as caught:
            runner.run_test(scenario, [example_bag], None, system=system, seed=7, rate=1.0, logs=None,
                            stop=StopFlag(), first=crowded, last=crowded)
        assert said('has nodes of other processes')[-1] == crowded
        assert said('system under test started') == [free]  # not announced again
        assert running_with(token) == []  # the system started on the crowded domain was stopped
    finally:
        for process in sitters:
            ended(process)
        for _, claim in claims:
            claim.close()
    sitter = sitters[0]
    assert 'no quiet ROS domain' in str(caught.value)
    assert f'{crowded}: /sitter (pid {sitter.pid}) publishing /imu' in str(caught.value)


class GraphOfOneIntruder:
    """A node's graph as rclpy gives it: one process (pid 4242) publishing /imu, its node's name unknown for the
    first `unnamed` looks (Fast DDS reports endpoints before the participant tells its node names)."""

    def __init__(self, unnamed: int) -> None:
        self.unnamed = unnamed
        self.looks = 0

    def get_topic_names_and_types(self) -> list[tuple[str, list[str]]]:
        self.looks += 1
        return [('/imu', ['sensor_msgs/msg/Imu'])]

    def get_publishers_info_by_topic(self, topic: str) -> list[SimpleNamespace]:
        gid = b'\x01\x0f' + b'\x00\x00' + (4242).to_bytes(2, 'little') + bytes(18)
        known = self.looks > self.unnamed
        return [SimpleNamespace(endpoint_gid=list(gid), node_namespace='/' if known else '_NODE_NAMESPACE_UNKNOWN_',
                                node_name='intruder' if known else '_NODE_NAME_UNKNOWN_')]


@pytest.mark.parametrize(('unnamed', 'named'), [(3, '/intruder (pid '), (10**6, 'a node not named yet (pid ')])
def test_an_intruder_is_named_once_its_process_says_its_name(unnamed: int, named: str) -> None:
    """The run stops with the intruder's node name when the graph learns it within a second, else without it."""
    from bagfault.closedloop.isolation import DomainWatch
    from bagfault.errors import ClosedLoopError

    graph = GraphOfOneIntruder(unnamed)
    watch = DomainWatch(graph, 42, own_pid=1, system=set)
    with pytest.raises(ClosedLoopError) as caught:
        for _ in range(200):
            watch.look()
            time.sleep(0.01)
    assert named in str(caught.value) and 'publishing /imu' in str(caught.value)
    with pytest.raises(ClosedLoopError, match='a node not named yet'):
        DomainWatch(GraphOfOneIntruder(10**6), 42, own_pid=1, system=set).look(now=True)  # the last look waits not
