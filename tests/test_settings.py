"""Every environment variable bagfault reads is checked before anything runs: a bad value is one line naming
the variable and exit 2 (BAGFAULT_CACHE_GB=abc was a ValueError traceback in a campaign job; a
BAGFAULT_CACHE_NODE of '../x' put the cache outside its root)."""

from __future__ import annotations

import pytest
from support.helpers import FIXTURES

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
