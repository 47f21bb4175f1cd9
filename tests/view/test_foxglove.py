"""`play --foxglove` driven by the official Foxglove WebSocket client (npm @foxglove/ws-protocol), with rclpy made
unimportable: channels and schemas, the faults as parameters (a switch applied from the next message, a refused
edit explained), events as JSON, and a seek back in time."""

from __future__ import annotations

import base64
import json
import os
import shutil
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from support.helpers import make_bag

pytest.importorskip('foxglove')

from bagfault.demo import synthetic

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
CLIENT_PACKAGES = ['@foxglove/ws-protocol@0.8.0', 'ws@8.18.0']
IMU = 'sensor_msgs/msg/Imu'
NS = 1_000_000_000
SCENARIO = """
injector: {id: imu, type: imu, input_topic: /imu, output_topic: /imu_out}
faults:
  - {id: bias, injector_id: imu, config: {angular_velocity_z_bias: 0.5}}
"""


@pytest.fixture(scope='session')
def client_dir() -> Path:
    """The client script beside its npm packages, installed once into a cache folder."""
    npm = shutil.which('npm')
    if npm is None or shutil.which('node') is None:
        pytest.skip('node and npm are needed for the Foxglove client')
    cache = Path(os.environ.get('XDG_CACHE_HOME', Path.home() / '.cache')) / 'bagfault-tests' / 'foxglove-ws-0.8.0'
    cache.mkdir(parents=True, exist_ok=True)
    if not (cache / 'node_modules' / '@foxglove' / 'ws-protocol').is_dir():
        (cache / 'package.json').write_text('{"name": "bagfault-foxglove-client", "private": true, "type": "module"}')
        done = subprocess.run([npm, 'install', '--no-audit', '--no-fund', '--loglevel=error', *CLIENT_PACKAGES],
                              cwd=cache, capture_output=True, text=True, check=False, timeout=300)
        if done.returncode != 0:
            pytest.skip(f'npm install of the Foxglove client failed: {done.stderr.strip()[-300:]}')
    shutil.copy(HERE / 'foxglove_client.mjs', cache / 'client.mjs')
    return cache


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(('127.0.0.1', 0))
        return int(probe.getsockname()[1])


def play_without_ros(client_dir: Path, tmp_path: Path, args: list[str], plan: dict) -> tuple[list[dict], str]:
    """`bagfault play ARGS --foxglove` where rclpy cannot be imported, driven by the official client with `plan`:
    the client's rows and the play's stdout (after a SIGINT once the client is done)."""
    blocked = tmp_path / 'no_ros' / 'rclpy'
    blocked.mkdir(parents=True)
    (blocked / '__init__.py').write_text("raise ImportError('no ROS on this machine')\n")
    env = {**os.environ, 'PYTHONPATH': os.pathsep.join([str(blocked.parent), str(ROOT)])}
    port = free_port()
    play = subprocess.Popen([sys.executable, '-m', 'bagfault.cli', 'play', *args, '--foxglove', f'127.0.0.1:{port}'],
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = play.stdout.readline()  # type: ignore[union-attr]
        assert f'Foxglove view on ws://127.0.0.1:{port}' in line, line + play.stderr.read()  # type: ignore[union-attr]
        client = subprocess.run(['node', 'client.mjs', f'ws://127.0.0.1:{port}', json.dumps(plan)], cwd=client_dir,
                                capture_output=True, text=True, check=False, timeout=120)
        rows = [json.loads(line) for line in client.stdout.splitlines() if line.startswith('{')]
        assert rows and rows[-1]['kind'] == 'done' and client.returncode == 0, client.stdout[-2000:] + client.stderr
    finally:
        play.send_signal(2)
        out, err = play.communicate(timeout=30)
    assert play.returncode == 0, err
    return rows, out


@pytest.mark.parametrize('open_only', [False, True], ids=['app', 'open-protocol-client'])
def test_play_in_foxglove_without_ros(client_dir: Path, tmp_path: Path, open_only: bool) -> None:
    """The official client drives a play: offering both subprotocol names as the Foxglove app does, and only
    `foxglove.websocket.v1` as Lichtblick and ws-protocol 0.8 clients do (the SDK's server answered 400)."""
    bag = make_bag(tmp_path / 'imu.mcap', [('/imu', IMU, 100.0)], 12.0)
    scenario = tmp_path / 'bias.yaml'
    scenario.write_text(SCENARIO)
    start = synthetic.DEFAULT_START
    plan = {'subscribe': ['/imu_out', '/bagfault/events'], 'count_topic': '/imu_out', 'switch_at': 100,
            'switch': {'name': 'bias.active', 'value': True}, 'refuse_at': 200,
            'refuse': {'name': 'bias.angular_velocity_z_bias', 'value': 'fast'}, 'seek_at': 300,
            'seek_to': start + NS // 2, 'after_seek': 20, 'timeout_s': 60, 'open_only': open_only}
    rows, out = play_without_ros(client_dir, tmp_path, [str(scenario), str(bag)], plan)
    assert 'played into the Foxglove view only (rclpy is not installed here)' in out

    info = next(r for r in rows if r['kind'] == 'serverInfo')
    assert info['protocol'] == ('foxglove.websocket.v1' if open_only else 'foxglove.sdk.v1')
    assert {'parameters', 'time'} <= set(info['capabilities'])
    channels = {r['topic']: (r['encoding'], r['schemaName']) for r in rows if r['kind'] == 'channel'}
    assert channels['/imu_out'] == ('cdr', IMU) and channels['/imu'] == ('cdr', IMU)
    assert channels['/bagfault/events'][0] == 'json'
    assert channels['/fault_injection/events'] == ('cdr', 'ros2_fault_injection/msg/FaultEvent')

    initial = next(r for r in rows if r['kind'] == 'parameters' and r['id'] == 'initial')['parameters']
    values = {p['name']: p['value'] for p in initial}
    assert values['bias.active'] is False and values['bias.angular_velocity_z_bias'] == 0.5
    assert 'bias.drop_probability' in values  # every key of the injector type

    store = synthetic.store()
    order = [r for r in rows if r['kind'] in ('message', 'action')]
    switched = next(i for i, r in enumerate(order) if r.get('action') == 'switch')
    seeked = next(i for i, r in enumerate(order) if r.get('action') == 'seek')
    z = [(i, store.deserialize_cdr(base64.b64decode(r['data']), IMU).angular_velocity.z)
         for i, r in enumerate(order) if r['kind'] == 'message' and r['topic'] == '/imu_out']
    raw = synthetic.imu_values(0.0)[0]
    before = [v for i, v in z if i < switched]
    after = [v for i, v in z if switched < i < seeked]
    assert len(before) == 100 and all(abs(v - raw) < 1e-12 for v in before)
    lag = next(n for n, v in enumerate(after) if abs(v - raw - 0.5) < 1e-12)
    assert lag <= 10 and all(abs(v - raw - 0.5) < 1e-12 for v in after[lag:])  # from the next messages on

    statuses = [r for r in rows if r['kind'] == 'status']
    assert statuses and 'bias.angular_velocity_z_bias' in statuses[0]['message'] and statuses[0]['level'] == 2
    refused = next(r for r in rows if r['kind'] == 'parameters' and r['id'] == 'refuse')['parameters']
    assert {p['name']: p['value'] for p in refused}['bias.angular_velocity_z_bias'] == 0.5  # unchanged

    events = [json.loads(base64.b64decode(r['data'])) for r in rows
              if r['kind'] == 'message' and r['topic'] == '/bagfault/events']
    assert [(e['fault_id'], e['state'], e['source']) for e in events if e['topic'] == '/fault_injection/events'][:1] \
        == [('bias', 'active', 'manual')]

    after_seek = [int(r['t']) for r in order[seeked + 1:] if r['kind'] == 'message' and r['topic'] == '/imu_out']
    assert min(after_seek) <= start + NS // 2 + 50_000_000  # the timeline went back to 0.5 s
    assert time.time() > 0


def test_proxy_in_foxglove_switches_faults_for_ros_too(client_dir: Path, graph, scenarios: Path) -> None:
    port = free_port()
    proxy = graph.bagfault('proxy', str(scenarios / 'imu.yaml'), '--foxglove', f'127.0.0.1:{port}', name='proxy')
    graph.wait_for(proxy, 'bagfault proxy ready')
    assert f'Foxglove view on ws://127.0.0.1:{port}' in proxy.err_path.read_text()
    publisher = graph.peer('publish-imu', '/sensors/imu_raw', '--rate', '100', '--seconds', '8', name='imu')
    plan = {'subscribe': ['/sensors/imu', '/bagfault/events'], 'count_topic': '/sensors/imu', 'switch_at': 50,
            'switch': {'name': 'imu_yaw_rate_bias.active', 'value': True}, 'refuse_at': 100,
            'refuse': {'name': 'imu_dropout.drop_probability', 'value': 3.0}, 'stop_at': 200, 'timeout_s': 60,
            'open_only': True}  # a client of the open protocol's name only (Lichtblick)
    client = subprocess.run(['node', 'client.mjs', f'ws://127.0.0.1:{port}', json.dumps(plan)], cwd=client_dir,
                            capture_output=True, text=True, check=False, timeout=120)
    rows = [json.loads(line) for line in client.stdout.splitlines() if line.startswith('{')]
    assert rows and rows[-1]['kind'] == 'done' and client.returncode == 0, client.stdout[-2000:] + client.stderr
    described = graph.call('describe-params', '/bagfault', 'imu_yaw_rate_bias.active')
    assert described['imu_yaw_rate_bias.active']['value'] is True  # the ROS parameter followed the view
    publisher.wait(timeout=30)
    assert graph.stop(proxy) == 0
    store = synthetic.store()
    order = [r for r in rows if r['kind'] in ('message', 'action')]
    switched = next(i for i, r in enumerate(order) if r.get('action') == 'switch')
    later = [store.deserialize_cdr(base64.b64decode(r['data']), IMU) for r in order[switched + 10:]
             if r['kind'] == 'message' and r['topic'] == '/sensors/imu']
    assert later and all(abs(m.angular_velocity.z - 0.001 * (int(m.orientation_covariance[0]) % 100) - 0.05) < 1e-9
                         for m in later)  # the publisher's value plus the fault's 0.05
    statuses = [r['message'] for r in rows if r['kind'] == 'status']
    assert statuses and 'imu_dropout.drop_probability' in statuses[0] and 'maximum' in statuses[0]


def _handshake(port: int, subprotocols: str) -> tuple[str, str]:
    """The status line and the Sec-WebSocket-Protocol a WebSocket upgrade offering `subprotocols` gets (RFC 6455
    handshake, by hand)."""
    request = (f'GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n'
               f'Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n'
               f'Sec-WebSocket-Protocol: {subprotocols}\r\n\r\n')
    with socket.create_connection(('127.0.0.1', port), timeout=10) as connection:
        connection.sendall(request.encode())
        lines = connection.recv(4096).decode(errors='replace').split('\r\n')
    chosen = [line.split(':', 1)[1].strip() for line in lines if line.lower().startswith('sec-websocket-protocol:')]
    return lines[0], chosen[0] if chosen else ''


def test_the_view_takes_both_names_of_the_protocol() -> None:
    """The SDK's server (foxglove-sdk 0.30) accepts `foxglove.sdk.v1` only and answers 400 to a client that
    offers nothing but the older `foxglove.websocket.v1`; the view's relay asks it for the new name and answers
    with the one offered. A client offering neither still gets the server's 400."""
    from bagfault.scenario import parse_scenario
    from bagfault.view.foxglove import FoxgloveView

    view = FoxgloveView(f'127.0.0.1:{free_port()}', parse_scenario(SCENARIO))
    try:
        port = view.relay.port
        assert _handshake(port, 'foxglove.sdk.v1') == ('HTTP/1.1 101 Switching Protocols', 'foxglove.sdk.v1')
        assert _handshake(port, 'foxglove.websocket.v1') == ('HTTP/1.1 101 Switching Protocols',
                                                             'foxglove.websocket.v1')
        assert _handshake(port, 'foxglove.websocket.v1, foxglove.sdk.v1')[1] == 'foxglove.sdk.v1'  # the app
        assert ' 400 ' in _handshake(port, 'chat')[0] + ' '
        assert ' 400 ' in _handshake(view.server.port, 'foxglove.websocket.v1')[0] + ' '  # the SDK's own answer
    finally:
        view.close()
    page = (ROOT / 'docs' / 'modes' / 'foxglove.md').read_text()
    assert 'foxglove.sdk.v1' in page and 'foxglove.websocket.v1' in page


def test_play_in_foxglove_leaves_out_a_type_nobody_defined(client_dir: Path, quirks_bag: Path, tmp_path: Path) -> None:
    plan = {'subscribe': ['/imu'], 'count_topic': '/imu', 'stop_at': 50, 'timeout_s': 60}
    rows, out = play_without_ros(client_dir, tmp_path, [str(quirks_bag)], plan)
    channels = {r['topic'] for r in rows if r['kind'] == 'channel'}
    assert {'/imu', '/odom', '/scan', '/clock', 'robot_status'} <= channels
    assert '/performance_metrics' not in channels
    assert ('/performance_metrics not shown in the Foxglove view: no definition of '
            'gazebo_msgs/msg/PerformanceMetrics') in out
