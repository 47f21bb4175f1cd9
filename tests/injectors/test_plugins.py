"""Entry-point plugins: an external package installed next to bagfault adds a type."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from support.helpers import ROOT

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


def test_without_the_plugin_the_type_is_unknown(scenarios):
    result = subprocess.run([sys.executable, '-m', 'bagfault.cli', 'validate', str(scenarios / 'battery.yaml')],
                            capture_output=True, text=True, check=False)
    assert result.returncode == 2
    assert "unknown injector type 'battery_state'" in result.stderr


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
