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

FIXTURES_SQLITE = Path(__file__).parent / 'fixtures' / 'rover_3s_sqlite3'


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


def test_a_compression_level_out_of_range_is_one_line_before_anything_is_read(capsys, tmp_path, scenarios, rover_bag):
    out = tmp_path / 'out.mcap'
    for args, problem in ((('--compression-level', '23'), 'zstd compression level 23 is outside -7..22'),
                          (('--compression', 'none', '--compression-level', '1'), 'a compression level needs')):
        code, _, err = run_cli(capsys, 'run', scenarios / 'rover_multi.yaml', rover_bag, '-o', out, *args)
        assert code == 2
        assert err.strip() == f'bagfault: error: {out}: {problem}' + (
            " a compression (lz4 or zstd), not 'none'" if 'needs' in problem else '')
    assert list(tmp_path.iterdir()) == []


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




def _bagfault(*args, cwd=None, stdout=subprocess.PIPE, stderr=subprocess.PIPE):
    """The installed command in a subprocess (for what needs its own cwd or terminal)."""
    return subprocess.run([sys.executable, '-m', 'bagfault', *map(str, args)], cwd=cwd, stdout=stdout,
                          stderr=stderr, text=True, timeout=120, check=False)


def test_an_input_symlink_loop_is_one_line(capsys, tmp_path, scenarios):
    (tmp_path / 'a').symlink_to(tmp_path / 'b')
    (tmp_path / 'b').symlink_to(tmp_path / 'a')
    code, _, err = run_cli(capsys, 'run', scenarios / 'odom.yaml', tmp_path / 'a', '-o', tmp_path / 'o.mcap')
    assert code == 2 and err.count('\n') == 1 and 'symbolic link that leads nowhere' in err, err


def test_a_deleted_current_directory_is_one_line(tmp_path, scenarios, rover_bag):
    gone = tmp_path / 'gone'
    gone.mkdir()
    script = (f'import os, subprocess, sys; os.chdir({str(gone)!r}); os.rmdir({str(gone)!r}); '
              f'sys.exit(subprocess.run([sys.executable, "-m", "bagfault", "run", {str(scenarios / "odom.yaml")!r}, '
              f'{str(rover_bag)!r}, "-o", "o.mcap"]).returncode)')
    done = subprocess.run([sys.executable, '-c', script], capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 2 and done.stderr.count('\n') == 1, done.stderr
    assert 'current directory no longer exists' in done.stderr


def test_stdout_on_a_full_device_is_exit_2_and_says_the_output_was_written(tmp_path, scenarios, rover_bag):
    """The summary cannot be printed: exit 2, one line on stderr, which says truly that the output exists."""
    with open('/dev/full', 'w') as full:
        done = _bagfault('run', scenarios / 'odom.yaml', rover_bag, '-o', tmp_path / 'o.mcap', stdout=full)
    assert done.returncode == 2 and done.stderr.count('\n') == 1, done.stderr
    assert 'No space left on device' in done.stderr and f'written before that: {tmp_path / "o.mcap"}' in done.stderr
    assert _bagfault('run', scenarios / 'odom.yaml', rover_bag, '-o', tmp_path / 'ref.mcap').returncode == 0
    assert counts(tmp_path / 'o.mcap') == counts(tmp_path / 'ref.mcap')


def test_a_verdict_whose_warnings_cannot_be_shown_is_exit_2(tmp_path, rover_bag):
    """A failing run (exit 1) with a warning, stderr on a full device: the reason is lost, so exit 2."""
    scenario = tmp_path / 'warn.yaml'
    scenario.write_text("""
injectors: [{id: imu, type: imu, input_topic: /nothere, output_topic: /nothere_out}]
faults: [{id: f1, injector_id: imu, start: 1.0, duration: 1.0, config: {linear_acceleration_z_bias: 1.0}}]
assertions: [{id: a1, type: fault_event, fault_id: f1, state: active, within: 0.5}]
""")
    done = _bagfault('run', scenario, rover_bag, '-o', tmp_path / 'o.mcap')
    assert done.returncode == 1 and 'not in the bag' in done.stderr  # f1 starts at 1.0 s, after `within`
    with open('/dev/full', 'w') as full:
        done = _bagfault('run', scenario, rover_bag, '-o', tmp_path / 'o2.mcap', stderr=full)
    assert done.returncode == 2


def test_a_full_tmpdir_while_expanding_a_compressed_split_is_one_line(capsys, tmp_path, scenarios, monkeypatch):
    """A FILE-compressed rosbag2 part is decompressed into TMPDIR; no room there is an input error, not a bug."""
    import errno

    import zstandard

    from bagfault.io import rosbag2_source

    folder = tmp_path / 'bag'
    shutil.copytree(FIXTURES_SQLITE, folder)
    storage = folder / 'rover_3s_sqlite3.db3'
    (folder / 'rover_3s_sqlite3.db3.zstd').write_bytes(zstandard.ZstdCompressor().compress(storage.read_bytes()))
    storage.unlink()
    metadata = (folder / 'metadata.yaml').read_text()
    (folder / 'metadata.yaml').write_text(metadata.replace('rover_3s_sqlite3.db3', 'rover_3s_sqlite3.db3.zstd')
                                          .replace("compression_mode: ''", 'compression_mode: FILE')
                                          .replace("compression_format: ''", 'compression_format: zstd'))

    def full(*_args, **_kwargs):
        raise OSError(errno.ENOSPC, 'No space left on device')

    monkeypatch.setattr(rosbag2_source.shutil, 'copyfileobj', full)
    code, _, err = run_cli(capsys, 'run', scenarios / 'odom.yaml', folder, '-o', tmp_path / 'o.mcap')
    assert code == 2 and err.count('\n') == 1, err
    assert 'cannot decompress it into' in err and 'No space left on device' in err and 'TMPDIR' in err
    assert not (tmp_path / 'o.mcap').exists()


def test_a_system_command_or_env_no_process_can_take_is_a_scenario_error(capsys, tmp_path):
    for key, text, message in (('command', '"a\\0b"', 'NUL character'),
                               ('env', '{"A=B": "1"}', 'not a variable name'),
                               ('env', '{A: "x\\0y"}', 'NUL character')):
        body = 'command: sleep 1' if key == 'env' else ''
        scenario = tmp_path / 'sut.yaml'
        scenario.write_text(f'injectors: []\nfaults: []\nsystem_under_test:\n  {body}\n  {key}: {text}\n')
        code, _, err = run_cli(capsys, 'validate', scenario)
        assert code == 2 and f'system_under_test.{key}' in err and message in err, err


def test_a_signal_after_the_output_is_published_says_it_was_written(capsys, tmp_path, scenarios, rover_bag,
                                                                    monkeypatch):
    """SIGTERM while the reports are written (the last moments of a run): the output is complete under its name,
    and the last line says so instead of 'nothing was written'."""
    from bagfault.report.files import ReportPaths

    def signalled(*_args, **_kwargs):
        raise KeyboardInterrupt('SIGTERM')  # what _terminating_signals raises on SIGTERM

    monkeypatch.setattr(ReportPaths, 'write', signalled)
    code, _, err = run_cli(capsys, 'run', scenarios / 'odom.yaml', rover_bag, '-o', tmp_path / 'o.mcap',
                           '--json', tmp_path / 'r.json')
    assert code == 2
    assert err == f'bagfault: stopped by SIGTERM; written before that: {tmp_path / "o.mcap"}\n'
    assert counts(tmp_path / 'o.mcap')['/odom'] > 0 and not (tmp_path / 'r.json').exists()


def test_an_unreadable_split_or_folder_is_one_line(capsys, tmp_path, scenarios, monkeypatch):
    """As a non-root user meets them (root reads everything, so the refusal is the kernel's, raised here)."""
    import errno

    folder = tmp_path / 'bag'
    shutil.copytree(FIXTURES_SQLITE, folder)
    storage = folder / 'rover_3s_sqlite3.db3'
    real_open = Path.open

    def denied(self, *args, **kwargs):
        if self == storage:
            raise PermissionError(errno.EACCES, 'Permission denied', str(self))
        return real_open(self, *args, **kwargs)

    monkeypatch.setattr(Path, 'open', denied)
    code, _, err = run_cli(capsys, 'run', scenarios / 'odom.yaml', folder, '-o', tmp_path / 'o.mcap')
    assert code == 2 and err.count('\n') == 1 and 'Permission denied' in err and str(storage) in err, err
    monkeypatch.undo()

    real_iterdir = Path.iterdir

    def unlistable(self):
        if self == folder:
            raise PermissionError(errno.EACCES, 'Permission denied', str(self))
        return real_iterdir(self)

    monkeypatch.setattr(Path, 'iterdir', unlistable)
    code, _, err = run_cli(capsys, 'run', scenarios / 'odom.yaml', folder, '-o', tmp_path / 'o.mcap')
    assert code == 2 and err.count('\n') == 1 and 'Permission denied' in err and str(folder) in err, err
    assert not (tmp_path / 'o.mcap').exists()
