"""Command line contract: exit codes, one-line errors, nothing lost on failure."""

from __future__ import annotations

import io
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from support.helpers import counts, tree_digest

from bagfault.cli import main
from bagfault.progress import ProgressBar


def run_cli(capsys, *args):
    code = main([str(a) for a in args])
    out = capsys.readouterr()
    return code, out.out, out.err


def test_run_prints_a_summary(capsys, tmp_path, scenarios, rover_bag):
    code, out, err = run_cli(capsys, 'run', scenarios / 'rover_multi.yaml', rover_bag, '-o', tmp_path / 'o.mcap')
    assert code == 0, err
    assert 'odom_position_bias' in out and '5.000 s' in out
    assert counts(tmp_path / 'o.mcap')['/odom'] == 1000
    assert os.listdir(tmp_path) == ['o.mcap']


def test_console_script_is_installed():
    exe = shutil.which('bagfault') or os.path.join(os.path.dirname(sys.executable), 'bagfault')
    result = subprocess.run([exe, '--version'], capture_output=True, text=True, check=False)
    assert result.returncode == 0 and result.stdout.startswith('bagfault ')


def test_validate_reports_every_problem_one_per_line(capsys, tmp_path):
    bad = tmp_path / 'bad.yaml'
    bad.write_text('injector: {id: o, type: odom, input_topic: /a, output_topic: /b}\n'
                   'faults:\n  - {id: f, injector_id: o, start: -1, config: {x_bias: x, drop_probability: 2}}\n')
    code, out, err = run_cli(capsys, 'validate', bad)
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 3
    assert all(line.startswith(f'bagfault: error: {bad}:3:') for line in lines)
    assert 'Traceback' not in err


def test_validate_ok_and_warnings(capsys, anchors):
    code, out, err = run_cli(capsys, 'validate', *sorted(p for p in anchors.glob('*.yaml') if 'battery' not in p.name))
    assert code == 0
    assert out.count(': ok (') == 8


@pytest.mark.parametrize('case', ['missing', 'empty', 'truncated', 'same_as_input', 'no_dir', 'inside_input',
                                  'unwritable'])
def test_bad_input_or_output_exit_2_without_traces(capsys, tmp_path, scenarios, rover_bag, rover_sqlite, case):
    scenario = scenarios / 'rover_multi.yaml'
    bag = tmp_path / 'in.mcap'
    shutil.copy(rover_bag, bag)
    out = tmp_path / 'out.mcap'
    if case == 'missing':
        bag = tmp_path / 'nope.mcap'
    elif case == 'empty':
        bag.write_bytes(b'')
    elif case == 'truncated':
        bag.write_bytes(rover_bag.read_bytes()[:300_000])
    elif case == 'same_as_input':
        out = bag
    elif case == 'no_dir':
        out = tmp_path / 'missing_dir' / 'out.mcap'
    elif case == 'unwritable':
        out = Path('/proc/bagfault-test.mcap')
    elif case == 'inside_input':
        bag = tmp_path / 'sqlite_bag'
        shutil.copytree(rover_sqlite, bag)
        scenario = scenarios / 'odom.yaml'
        out = bag / 'out.mcap'
    before = tree_digest(bag) if bag.exists() else None
    listing = sorted(os.listdir(tmp_path))
    code, _, err = run_cli(capsys, 'run', scenario, bag, '-o', out)
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith('bagfault: error: ')
    assert str(out if case in {'no_dir', 'unwritable'} else bag) in lines[0]
    assert 'Traceback' not in err
    assert sorted(os.listdir(tmp_path)) == listing
    if before is not None:
        assert tree_digest(bag) == before


def test_failure_during_the_run_leaves_nothing(capsys, tmp_path, scenarios, rover_bag):
    data = bytearray(rover_bag.read_bytes())
    data[len(data) // 2: len(data) // 2 + 4000] = bytes(4000)  # inside a compressed chunk
    bag = tmp_path / 'corrupt.mcap'
    bag.write_bytes(bytes(data))
    code, _, err = run_cli(capsys, 'run', scenarios / 'rover_multi.yaml', bag, '-o', tmp_path / 'out.mcap')
    assert code == 2 and 'corrupt' in err and str(bag) in err
    assert sorted(os.listdir(tmp_path)) == ['corrupt.mcap']


def test_debug_shows_the_traceback(capsys, tmp_path, scenarios):
    code, _, err = run_cli(capsys, '--debug', 'run', scenarios / 'odom.yaml', tmp_path / 'x.mcap', '-o', tmp_path / 'o.mcap')
    assert code == 2 and 'Traceback' in err


def test_unknown_activate_fault(capsys, tmp_path, scenarios, rover_bag):
    code, _, err = run_cli(capsys, 'run', scenarios / 'odom.yaml', rover_bag, '-o', tmp_path / 'o.mcap',
                           '--activate', 'ghost@1')
    assert code == 2 and '--activate ghost: no such fault in odom.yaml' in err


def test_usage_error_is_exit_2(capsys):
    with pytest.raises(SystemExit) as info:
        main(['run'])
    assert info.value.code == 2


def test_schema_text_and_json(capsys):
    code, out, _ = run_cli(capsys, 'schema', 'odom')
    assert code == 0 and 'x_bias' in out and 'metres' in out
    code, out, _ = run_cli(capsys, 'schema', '--json')
    data = json.loads(out)
    assert set(data) >= {'odom', 'scan', 'imu', 'joint_state', 'tf', 'trigger_service'}
    drop = next(f for f in data['odom']['fields'] if f['key'] == 'drop_probability')
    assert (drop['type'], drop['min'], drop['max'], drop['default']) == ('double', 0.0, 1.0, 0.0)
    assert data['trigger_service']['live_only'] is True
    code, _, err = run_cli(capsys, 'schema', 'nope')
    assert code == 2 and "unknown injector type 'nope'" in err


def test_info_lists_topics(capsys, rover_bag):
    code, out, _ = run_cli(capsys, 'info', rover_bag)
    assert code == 0
    assert '/odom_raw' in out and '1000  nav_msgs/msg/Odometry' in out and 'messages:  5200' in out


def test_progress_bar_shows_eta_on_a_terminal():
    stream = io.StringIO()
    bar = ProgressBar(stream=stream, enabled=True)
    bar.begin(0, 10_000_000_000, 100)
    bar.last_draw = -1.0
    bar.began -= 2.0
    bar(50, 5_000_000_000)
    text = stream.getvalue()
    assert '50.0%' in text and 'ETA 00:02' in text and '5.0/10.0 s bag' in text
    quiet = io.StringIO()
    ProgressBar(stream=quiet)(1, 1)
    assert quiet.getvalue() == ''


@pytest.mark.parametrize('option', ['--json', '--report', '--junit', '--html'])
def test_bad_report_path_is_refused_before_the_run(capsys, tmp_path, scenarios, rover_bag, option):
    out = tmp_path / 'o.mcap'
    code, _, err = run_cli(capsys, 'run', scenarios / 'odom.yaml', rover_bag, '-o', out, option,
                           tmp_path / 'missing' / 'r.txt')
    assert code == 2
    assert err.count('\n') == 1 and f'{option} report: folder' in err and 'Traceback' not in err
    assert not out.exists() and os.listdir(tmp_path) == []  # refused before the run: nothing written


@pytest.mark.parametrize('target', ['input', 'scenario', 'output'])
def test_report_never_replaces_what_the_run_reads_or_writes(capsys, tmp_path, scenarios, rover_bag, target):
    scenario = tmp_path / 'odom.yaml'
    shutil.copy(scenarios / 'odom.yaml', scenario)
    bag = tmp_path / 'in.mcap'
    shutil.copy(rover_bag, bag)
    out = tmp_path / 'o.mcap'
    before = {p.name: tree_digest(p) for p in (scenario, bag)}
    path = {'input': bag, 'scenario': scenario, 'output': out}[target]
    code, _, err = run_cli(capsys, 'run', scenario, bag, '-o', out, '--json', path)
    assert code == 2 and f'would replace the {target}' in err
    assert {p.name: tree_digest(p) for p in (scenario, bag)} == before
    assert not out.exists()


def test_output_onto_the_scenario_is_refused(capsys, tmp_path, scenarios, rover_bag):
    scenario = tmp_path / 'odom.yaml'
    shutil.copy(scenarios / 'odom.yaml', scenario)
    text = scenario.read_text()
    code, _, err = run_cli(capsys, 'run', scenario, rover_bag, '-o', scenario)
    assert code == 2 and 'would replace the scenario' in err
    assert scenario.read_text() == text


def test_a_bug_still_ends_with_exit_2_and_one_line(capsys, tmp_path, scenarios, rover_bag, monkeypatch):
    from bagfault import api

    def broken(*args, **kwargs):
        raise RuntimeError('boom')

    monkeypatch.setattr(api, 'run', broken)
    code, _, err = run_cli(capsys, 'run', scenarios / 'odom.yaml', rover_bag, '-o', tmp_path / 'o.mcap')
    assert code == 2
    assert err == 'bagfault: internal error: RuntimeError: boom (a bug in bagfault; --debug shows where)\n'
    code, _, err = run_cli(capsys, '--debug', 'run', scenarios / 'odom.yaml', rover_bag, '-o', tmp_path / 'o.mcap')
    assert code == 2 and 'Traceback' in err


