"""Entry-point plugins: an external package installed next to bagfault adds a type."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from support.helpers import ROOT, counts, make_bag

EXAMPLE = ROOT / 'examples' / 'bagfault-rover-plugins'


@pytest.fixture(scope='module')
def plugin_path(tmp_path_factory) -> Path:
    """Install the example plugin into a private folder (no dependencies, no network)."""
    target = tmp_path_factory.mktemp('plugin')
    subprocess.run(
        [sys.executable, '-m', 'pip', 'install', '--quiet', '--no-deps', '--no-build-isolation',
         '--target', str(target), str(EXAMPLE)],
        check=True, capture_output=True,
    )
    return target


def bagfault(plugin_path: Path, *args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, 'PYTHONPATH': os.pathsep.join([str(plugin_path), str(ROOT)])}
    return subprocess.run([sys.executable, '-m', 'bagfault.cli', *args], capture_output=True, text=True,
                          env=env, cwd=cwd, check=False)


def test_without_the_plugin_the_type_is_skipped_with_its_faults_as_the_anchor_does(scenarios, tmp_path):
    """ros2_fault_injection scenario_validator.cpp:136-138 warns "injector.type '...' is not built in; assuming
    external plugin"; fault_controller.cpp:44-57 creates no injector for it and register_faults skips its faults;
    the other injectors run. A warning here (an error under --strict), never a refusal of the whole file."""
    checked = subprocess.run([sys.executable, '-m', 'bagfault.cli', 'validate', str(scenarios / 'battery.yaml')],
                             capture_output=True, text=True, check=False)
    assert checked.returncode == 0, checked.stderr
    assert "unknown injector type 'battery_state'" in checked.stderr and 'assuming external plugin' in checked.stderr
    assert "injector 'battery' and its faults (battery_voltage_bias) are skipped" in checked.stderr
    assert checked.stderr.count('warning: ') == 1  # one warning, as the anchor's validator gives one
    strict = subprocess.run([sys.executable, '-m', 'bagfault.cli', 'validate', '--strict',
                             str(scenarios / 'battery.yaml')], capture_output=True, text=True, check=False)
    assert strict.returncode == 2
    mixed = tmp_path / 'mixed.yaml'
    mixed.write_text('injectors:\n'
                     '  - {id: battery, type: battery_state, topic: {input_topic: /battery, output_topic: /b2}}\n'
                     '  - {id: imu, type: imu, input_topic: /imu, output_topic: /imu_out}\n'
                     'faults:\n'
                     '  - {id: low, injector_id: battery, start: 0.5, config: {voltage_bias: -1.0}}\n'
                     '  - {id: bias, injector_id: imu, start: 0.5, config: {angular_velocity_z_bias: 0.5}}\n'
                     'assertions:\n'
                     '  - {id: imu_faulted, type: fault_event, fault_id: bias, state: active, within: 1.0}\n'
                     '  - {id: battery_faulted, type: fault_event, fault_id: low, state: active, within: 1.0}\n')
    bag = make_bag(tmp_path / 'imu.mcap', [('/imu', 'sensor_msgs/msg/Imu', 50.0)], 2.0)
    ran = subprocess.run([sys.executable, '-m', 'bagfault.cli', 'run', str(mixed), str(bag), '-o',
                          str(tmp_path / 'out.mcap'), '--json', str(tmp_path / 'r.json')],
                         capture_output=True, text=True, check=False)
    assert ran.returncode == 1, ran.stderr  # the imu runs; the skipped battery fault never activates
    import json
    states = {a['id']: a['state'] for a in json.loads((tmp_path / 'r.json').read_text())['assertions']}
    assert states == {'imu_faulted': 'passed', 'battery_faulted': 'failed'}
    assert '/imu_out' in counts(tmp_path / 'out.mcap')


def test_installed_plugin_is_found_validated_and_runs(plugin_path, tmp_path, scenarios):
    listed = bagfault(plugin_path, 'schema', 'battery_state', '--json')
    assert listed.returncode == 0, listed.stderr
    assert '"voltage_bias"' in listed.stdout
    checked = bagfault(plugin_path, 'validate', str(scenarios / 'battery.yaml'))
    assert checked.returncode == 0, checked.stderr
    tests = subprocess.run(
        [sys.executable, '-m', 'pytest', '-q', '-p', 'no:cacheprovider', str(EXAMPLE / 'tests')],
        capture_output=True, text=True, check=False, cwd=tmp_path,
        env={**os.environ, 'PYTHONPATH': os.pathsep.join([str(plugin_path), str(ROOT)])},
    )
    assert tests.returncode == 0, tests.stdout + tests.stderr
    assert '4 passed' in tests.stdout
