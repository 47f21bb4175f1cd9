"""`bagfault demo` from nothing, and fixtures reproducible from their script."""

from __future__ import annotations

import subprocess
import sys

from support.helpers import FIXTURES, ROOT, counts, sha256

from bagfault.cli import main


def test_demo_writes_output_and_report(tmp_path, capsys):
    assert main(['demo', '-o', str(tmp_path / 'demo')]) == 0
    out = capsys.readouterr().out
    assert 'odom_drift' in out and 'report' in out
    files = sorted(p.name for p in (tmp_path / 'demo').iterdir())
    assert files == ['demo_input.mcap', 'demo_output.mcap', 'demo_report.html', 'demo_report.md', 'demo_scenario.yaml']
    got = counts(tmp_path / 'demo' / 'demo_output.mcap')
    assert got['/odom'] == 1000 and got['/sensors/imu'] == 2000
    report = (tmp_path / 'demo' / 'demo_report.md').read_text()
    assert '| 8.000 | lidar_front_blind | scan | active |' in report


def test_readme_starts_with_exactly_two_commands():
    text = (ROOT / 'README.md').read_text().splitlines()
    block = text[text.index('```sh') + 1: text.index('```', text.index('```sh') + 1)]
    assert len(block) == 2
    assert block[0].endswith('bagfault demo') and block[1].endswith('-m pytest')
    ci = (ROOT / '.ci' / 'run').read_text()
    assert block[1] in ci


def test_fixtures_are_reproduced_by_their_script(tmp_path):
    subprocess.run([sys.executable, str(FIXTURES / 'make_fixtures.py'), str(tmp_path)], check=True, capture_output=True)
    assert sha256(tmp_path / 'rover_20s.mcap') == sha256(FIXTURES / 'rover_20s.mcap')
    assert raw(tmp_path / 'rover_3s_sqlite3') == raw(FIXTURES / 'rover_3s_sqlite3')


def raw(bag):
    from bagfault.io.sources import open_source

    source = open_source(bag)
    try:
        return [(source.channels[c].topic, t, bytes(d)) for c, t, _, d in source.messages()]
    finally:
        source.close()


def test_the_readme_is_a_front_door_and_links_nothing_a_user_lacks():
    text = (ROOT / 'README.md').read_text()
    assert len(text.splitlines()) <= 200
    assert '../shared' not in text
    docs = list((ROOT / 'docs').rglob('*.md'))
    assert docs and not [str(p) for p in docs if '../shared' in p.read_text()]
