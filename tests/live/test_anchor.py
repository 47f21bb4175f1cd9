"""The anchor's live interface, against its real generated types: ros2_fault_injection's message and service
definitions (tests/fixtures/anchor_interfaces) built once with the rosidl toolchain from PyPI, then the proxy's
nine services answered as fault_service_manager.cpp answers them and its events on the anchor's topic."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest
from support.helpers import FIXTURES

SOURCE = FIXTURES / 'anchor_interfaces'
SITE = f'lib/python{sys.version_info.major}.{sys.version_info.minor}/site-packages'


@pytest.fixture(scope='session')
def anchor_prefix() -> Path:
    """The interface package built into a cache folder (once per definition set); skips without the toolchain."""
    prefix = Path(sys.prefix)
    if not (prefix / 'share' / 'rosidl_default_generators').is_dir():
        pytest.skip("the rosidl generators are not installed (pip install '.[interfaces]')")
    if shutil.which('cmake') is None or (shutil.which('c++') or shutil.which('g++')) is None:
        pytest.skip('cmake and a C++ compiler are needed to generate the interface package')
    digest = hashlib.sha256()
    for path in sorted(SOURCE.rglob('*')):
        if path.is_file():
            digest.update(path.name.encode() + path.read_bytes())
    digest.update(sys.prefix.encode())
    cache = Path(os.environ.get('XDG_CACHE_HOME', Path.home() / '.cache')) / 'bagfault-tests' / \
        f'anchor-interfaces-{digest.hexdigest()[:16]}'
    install = cache / 'install'
    if not (install / SITE / 'ros2_fault_injection' / 'srv' / '__init__.py').is_file():
        shutil.rmtree(cache, ignore_errors=True)
        shutil.copytree(SOURCE, cache / 'src')
        env = {**os.environ, 'AMENT_PREFIX_PATH': sys.prefix,
               'PATH': os.pathsep.join([str(Path(sys.executable).parent), os.environ.get('PATH', '')])}
        steps = [
            ['cmake', '-S', str(cache / 'src'), '-B', str(cache / 'build'), f'-DCMAKE_PREFIX_PATH={sys.prefix}',
             f'-DCMAKE_INSTALL_PREFIX={install}', f'-DPython3_EXECUTABLE={sys.executable}', '-DBUILD_TESTING=OFF'],
            ['cmake', '--build', str(cache / 'build'), '-j2'],
            ['cmake', '--install', str(cache / 'build')],
        ]
        for step in steps:
            done = subprocess.run(step, env=env, capture_output=True, text=True, check=False, timeout=900)
            assert done.returncode == 0, f'{" ".join(step[:2])} failed:\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}'
    return install


def test_the_proxy_answers_the_anchors_services_and_publishes_its_events(graph, scenarios: Path,
                                                                          anchor_prefix: Path) -> None:
    graph.env['PYTHONPATH'] = os.pathsep.join([str(anchor_prefix / SITE), graph.env['PYTHONPATH']])
    graph.env['LD_LIBRARY_PATH'] = os.pathsep.join(filter(None, [str(anchor_prefix / 'lib'),
                                                                 graph.env.get('LD_LIBRARY_PATH')]))
    graph.env['AMENT_PREFIX_PATH'] = os.pathsep.join([str(anchor_prefix), sys.prefix])
    events = graph.peer('echo', '/fault_injection/events', 'ros2_fault_injection/msg/FaultEvent', '--seconds', '300',
                        '--fields', 'fault_id', 'state', 'source', 'details', name='events')
    graph.wait_for(events, 'ready')
    scenario = scenarios / 'imu.yaml'
    proxy = graph.bagfault('proxy', str(scenario), name='proxy')
    graph.wait_for(proxy, 'bagfault proxy ready')
    assert 'serving the anchor interface (fault_injection/*)' in proxy.err_path.read_text()
    graph.wait_for(events, 'matched')  # the events are volatile: the listener must be matched before they go out
    time.sleep(0.5)                    # and the proxy's side of the match may come a moment later
    calls = graph.peer('anchor-calls', 'imu_yaw_rate_bias', name='calls')
    assert calls.wait(timeout=120) == 0, calls.err_path.read_text()
    rows = graph.lines(calls)
    faults = ['imu_dropout', 'imu_delay', 'imu_yaw_rate_bias', 'imu_yaw_rate_noise', 'imu_linear_acceleration_bias',
              'imu_linear_acceleration_noise']
    listed, unknown, switched, status, bad_key, configured, config, schema, got, report, reload, again = rows
    assert listed == {'service': 'ListFaults', 'fault_ids': faults, 'active_fault_ids': []}
    assert (unknown['success'], unknown['message']) == (False, 'unknown fault_id: no_such_fault')
    assert (switched['success'], switched['message']) == (True, 'activated fault: imu_yaw_rate_bias')
    assert [(f['fault_id'], f['state']) for f in status['faults']][:3] == [
        ('imu_dropout', 'inactive'), ('imu_delay', 'inactive'), ('imu_yaw_rate_bias', 'active')]
    assert status['faults'][2]['details'] == 'manual-only, config={angular_velocity_z_bias=0.05}'  # describe_fault
    assert (bad_key['success'], bad_key['message']) == (False, "key 'gain' is not valid for injector type 'imu'")
    assert configured == {'service': 'SetFaultConfig', 'success': True,
                          'message': "updated fault 'imu_yaw_rate_bias' config 'angular_velocity_z_bias' to '0.2'"}
    assert (config['keys'], config['values'], config['injector_type']) == (['angular_velocity_z_bias'], ['0.2'], 'imu')
    assert schema['success'] and schema['keys'] == sorted(schema['keys']) and 'angular_velocity_z_bias' in schema['keys']
    drop = schema['keys'].index('drop_probability')
    assert (schema['has_max_values'][drop], schema['max_values'][drop]) == (True, 1.0)
    assert got['success'] and got['scenario_file'] == str(scenario) and got['content'] == scenario.read_text()
    assert report['success'] and '# ' in report['report_markdown']
    assert reload['success'] and 'kept what was set at run time' in reload['message']
    assert again['active_fault_ids'] == ['imu_yaw_rate_bias']  # the reload kept the switch
    time.sleep(0.5)
    assert graph.stop(proxy) == 0
    graph.stop(events)  # it prints each event as it comes; it listens until now, however slow the machine
    seen = [(e['fault_id'], e['state'], e['source']) for e in graph.lines(events)]
    assert ('imu_yaw_rate_bias', 'active', 'manual') in seen
    assert ('imu_yaw_rate_bias', 'config_updated', 'manual') in seen
    assert json.dumps(seen)  # every event decoded with the generated type
