"""Every environment variable bagfault reads is checked before anything runs: a bad value is one line naming
the variable and exit 2 (BAGFAULT_CACHE_GB=abc was a ValueError traceback in a campaign job; a
BAGFAULT_CACHE_NODE of '../x' put the cache outside its root)."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest
from support.helpers import FIXTURES

from bagfault import settings
from bagfault.cli import main

BAD = [('BAGFAULT_CACHE_GB', 'abc'), ('BAGFAULT_CACHE_GB', '-1'), ('BAGFAULT_CACHE_GB', '0'),
       ('BAGFAULT_CACHE_GB', 'nan'), ('BAGFAULT_CACHE_GB', 'inf'),
       ('BAGFAULT_CACHE_NODE', '..'), ('BAGFAULT_CACHE_NODE', '../elsewhere'), ('BAGFAULT_CACHE_NODE', 'a/b'),
       ('BAGFAULT_CACHE_NODE', '/abs'), ('BAGFAULT_CACHE_NODE', '.hidden'),
       ('BAGFAULT_CACHE', 'FILE'), ('BAGFAULT_DOMAIN_LOCKS', 'FILE'),
       ('BAGFAULT_DOMAIN_PORT_BASE', 'x'), ('BAGFAULT_DOMAIN_PORT_BASE', '80'),
       ('BAGFAULT_DOMAIN_PORT_BASE', '70000'), ('BAGFAULT_EXECUTOR', 'multi')]
GOOD = [('BAGFAULT_CACHE_GB', '0.5'), ('BAGFAULT_CACHE_GB', '50'), ('BAGFAULT_CACHE_NODE', 'node-2'),
        ('BAGFAULT_CACHE', 'FOLDER'), ('BAGFAULT_DOMAIN_PORT_BASE', '40000'), ('BAGFAULT_EXECUTOR', 'single'),
        ('BAGFAULT_EXECUTOR', 'events'), ('BAGFAULT_CACHE_GB', '')]


def _value(value: str, tmp_path) -> str:
    if value == 'FILE':
        (tmp_path / 'a-file').write_text('x')
        return str(tmp_path / 'a-file')
    return str(tmp_path) if value == 'FOLDER' else value


@pytest.mark.parametrize(('name', 'value'), BAD)
def test_a_bad_setting_is_one_line_naming_it_before_anything_runs(tmp_path, monkeypatch, capsys, name, value):
    monkeypatch.setenv(name, _value(value, tmp_path))
    out = tmp_path / 'out.mcap'
    assert main(['run', str(FIXTURES / 'scenarios' / 'imu.yaml'), str(FIXTURES / 'rover_20s.mcap'),
                 '-o', str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and err.startswith(f'bagfault: error: {name}='), err
    assert not out.exists()


@pytest.mark.parametrize(('name', 'value'), GOOD)
def test_good_settings_pass(tmp_path, monkeypatch, name, value):
    monkeypatch.setenv(name, _value(value, tmp_path))
    assert main(['validate', str(FIXTURES / 'scenarios' / 'imu.yaml')]) == 0


def test_cache_paths_stay_inside_their_root(tmp_path, monkeypatch):
    from bagfault.io.objects import cache_root

    monkeypatch.setenv('BAGFAULT_CACHE', str(tmp_path / 'cache'))
    monkeypatch.setenv('BAGFAULT_CACHE_NODE', 'node-2')
    assert cache_root() == tmp_path / 'cache' / 'node-2'


def test_every_setting_is_documented():
    """The reference page names every variable settings.py reads."""
    import re
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    read = set(re.findall(r"(?:_text|_folder)\('([A-Z_]+)'\)", (root / 'bagfault' / 'settings.py').read_text()))
    page = (root / 'docs' / 'reference' / 'environment.md').read_text()
    assert read and all(f'`{name}`' in page for name in read), read


BLAS_PROBE = """
import os, sys
if sys.argv[1] == 'command':
    from bagfault.cli import main
    sys.argv = ['bagfault', 'schema', 'imu']
    main()  # as the console script calls it
import numpy
print(len(os.listdir('/proc/self/task')), os.environ.get('OPENBLAS_NUM_THREADS'), file=sys.stderr)
"""


@pytest.mark.skipif(not os.path.isdir('/proc/self/task') or (os.cpu_count() or 1) < 2, reason='Linux, 2 cores')
@pytest.mark.parametrize(('how', 'users', 'threads'), [('numpy', None, os.cpu_count()), ('command', None, 1),
                                                       ('command', '2', 2)])
def test_the_command_loads_numpy_with_one_blas_thread_unless_the_user_says(how, users, threads):
    """numpy alone starts an OpenBLAS thread per core; the `bagfault` command loads it with none beside the main
    thread, and keeps a value the user gave."""
    env = {k: v for k, v in os.environ.items() if 'OPENBLAS' not in k and k != 'OMP_NUM_THREADS'}
    if users is not None:
        env['OPENBLAS_NUM_THREADS'] = users
    done = subprocess.run([sys.executable, '-c', BLAS_PROBE, how], env=env, capture_output=True, text=True,
                          check=True, timeout=120)
    counted, value = done.stderr.split()[-2:]
    assert int(counted) == threads
    assert value == (users or ('1' if how == 'command' else 'None'))


def test_a_system_gets_the_users_environment_without_bagfaults_blas_setting(monkeypatch):
    from bagfault.closedloop.runner import system_env
    from bagfault.spec.system import SystemUnderTest

    system = SystemUnderTest(command=['true'])
    # an environment of the test's own: what one_blas_thread sets goes with it
    monkeypatch.setattr(os, 'environ', {k: v for k, v in os.environ.items() if 'OPENBLAS' not in k})
    settings.one_blas_thread()  # as the command does
    assert os.environ['OPENBLAS_NUM_THREADS'] == '1'
    env = system_env(system, 7)
    assert 'OPENBLAS_NUM_THREADS' not in env and 'BAGFAULT_SET_OPENBLAS_NUM_THREADS' not in env
    assert env['ROS_DOMAIN_ID'] == '7'
    del os.environ['BAGFAULT_SET_OPENBLAS_NUM_THREADS']  # now the user's own value
    os.environ['OPENBLAS_NUM_THREADS'] = '3'
    settings.one_blas_thread()
    assert system_env(system, 7)['OPENBLAS_NUM_THREADS'] == '3'
    assert 'BAGFAULT_SET_OPENBLAS_NUM_THREADS' not in os.environ
