"""Campaigns run for real: job processes on a local pool, Ray tasks on a local instance and on a Ray head.

Expected states come from corpus.py's arithmetic (z + bias > 0.1 is detected,
40 ms after the fault starts) and from separate `api.run` calls on scenario
texts written here, not from the campaign code.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import socket
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import pytest
from support.corpus import SCENARIO, InterruptAfter, campaign_file, write_imu_bag
from support.html_check import figures, rendered
from support.raycluster import skip_if_ray_did_not_start

from bagfault import api
from bagfault.cli import main
from bagfault.scenario import parse_scenario

pq = pytest.importorskip('pyarrow.parquet', reason='campaign extra not installed')
BIAS = 'faults.bias.config.angular_velocity_z_bias'
CAMPAIGN = f"""
    campaign: drift
    scenario: drift.yaml
    bags: [bags/*.mcap]
    sweep:
      {BIAS}: [0.05, 0.09, 0.2]
    seeds: [0, 1]
    keep: all
"""
BASE_Z = {'bags/a.mcap': 0.02, 'bags/b.mcap': 0.0}


def table(directory: Path) -> list[dict[str, Any]]:
    """results.parquet without the columns measured as the jobs ran (wall and CPU seconds)."""
    rows = pq.read_table(directory / 'results.parquet').to_pylist()
    return [{k: v for k, v in row.items() if k not in ('seconds', 'cpu_s')} for row in rows]


def one_bag(folder: Path, name: str, *lines: str) -> Path:
    """A campaign of one job: bag a with bias 0.2 (0.02 + 0.2 > 0.1: detected), and any more `key: value` lines."""
    return campaign_file(folder, '\n'.join([f'campaign: {name}', 'scenario: drift.yaml', 'bags: [bags/a.mcap]',
                                            f'sweep: {{{BIAS}: [0.2]}}', *lines]) + '\n')


@pytest.fixture(scope='module')
def sweep(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The 2 bags x 3 biases x 2 seeds campaign, run once on one local worker."""
    folder = tmp_path_factory.mktemp('sweep')
    (folder / 'bags').mkdir()
    for name, z in BASE_Z.items():
        write_imu_bag(folder / name, z)
    (folder / 'drift.yaml').write_text(SCENARIO % {'bias': '0.0'})
    campaign_file(folder, CAMPAIGN)
    assert main(['campaign', str(folder / 'campaign.yaml'), '-o', str(folder / 'one'), '--workers', '1']) == 1
    return folder


def test_twelve_rows_match_twelve_separate_runs(sweep: Path, tmp_path: Path) -> None:
    rows = table(sweep / 'one')
    assert len(rows) == 12
    measured = pq.read_table(sweep / 'one' / 'results.parquet').to_pylist()  # CPU seconds per job: its two cores'
    assert all(0 < row['cpu_s'] <= 2 * row['seconds'] + 0.05 for row in measured), measured  # worth at most
    assert [(r['bag'], r[BIAS], r['seed']) for r in rows] == [
        (bag, bias, seed) for bag in BASE_Z for bias in (0.05, 0.09, 0.2) for seed in (0, 1)]
    for row in rows:
        detected = BASE_Z[row['bag']] + row[BIAS] > 0.1
        assert row['status'] == ('passed' if detected else 'failed')
        assert row['drift_detected'] == row['status']
        if detected:
            assert row['drift_detected.value'] == pytest.approx(0.04) and row['drift_detected.unit'] == 's'
            assert row['IMU_DRIFT.confirmed_s'] == pytest.approx(1.04)
            assert row['message'] is None  # nothing to say: null, never an empty string beside nulls
        else:
            assert row['IMU_DRIFT.confirmed_s'] is None and 'did not reach CONFIRMED' in row['message']
        assert row['warnings'] is None
        # the same run by hand, from a scenario text written here
        scenario = parse_scenario(SCENARIO % {'bias': repr(row[BIAS])})
        result = api.run(scenario, [sweep / row['bag']], tmp_path / f'{row["job"]}.mcap', seed=row['seed'])
        (by_hand,) = result.assertions
        assert (by_hand.state, by_hand.value) == (row['drift_detected'], row['drift_detected.value'])


def test_the_report_plots_the_pass_rate_known_from_the_thresholds(sweep: Path, tmp_path: Path) -> None:
    """detected iff base z + bias > 0.1: bias 0.05 passes on no bag, 0.09 on a (0.02 + 0.09) only, 0.2 on both."""
    drawn = figures(sweep / 'one' / 'report.html')
    passed = next(t for t in drawn[f'pass_rate:{BIAS}']['data'] if t['name'] == 'job passed')
    assert (passed['x'], passed['y']) == ([0.05, 0.09, 0.2], [0.0, 50.0, 100.0])
    body = rendered(sweep / 'one' / 'report.html', tmp_path / 'profile')
    assert body['errors'] == '0' and int(body['figures']) == len(drawn)
    # per bag, before any parameter: a passes at 0.09 and 0.2 (4 of 6 jobs), b only at 0.2 (2 of 6)
    import re
    html = (sweep / 'one' / 'report.html').read_text()
    table_of_bags = html[html.index('Pass rate against <code>bag</code>'):]
    table_of_bags = table_of_bags[:table_of_bags.index('</table>')]
    rows = re.findall(r'<td class="l">([^<]+)</td><td[^>]*>(\d+)% <span class="muted">\((\d+)/(\d+)\)', table_of_bags)
    assert rows == [('bags/a.mcap', '67', '4', '6'), ('bags/b.mcap', '33', '2', '6')]


def test_a_job_writes_what_bagfault_run_writes_by_hand(sweep: Path, tmp_path: Path) -> None:
    import json

    plan = json.loads((sweep / 'one' / 'campaign.json').read_text())
    for job in plan['jobs'][::5]:
        hand = tmp_path / f'hand{job["index"]}.mcap'
        scenario = sweep / 'one' / job['scenario']
        assert parse_scenario(scenario.read_text()).fault('bias').config['angular_velocity_z_bias'] == \
            job['values'][BIAS]
        code = main(['run', str(scenario), job['bag'], '-o', str(hand), '--seed', str(job['seed'])])
        assert code == (0 if BASE_Z[str(Path(job['bag']).relative_to(sweep))] + job['values'][BIAS] > 0.1 else 1)
        assert hand.read_bytes() == (sweep / 'one' / 'outputs' / f'{job["key"]}.mcap').read_bytes()


def test_the_table_is_the_same_on_two_workers_and_on_ray(sweep: Path, capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip('ray')
    assert main(['campaign', str(sweep / 'campaign.yaml'), '-o', str(sweep / 'two'), '--workers', '2']) == 1
    assert table(sweep / 'two') == table(sweep / 'one')
    assert (sweep / 'two' / 'results.csv').read_text().count('\n') == 13
    code = main(['campaign', str(sweep / 'campaign.yaml'), '-o', str(sweep / 'ray'), '--ray', '--workers', '2'])
    if code == 2:
        skip_if_ray_did_not_start(capsys.readouterr().err)
    assert code == 1
    assert table(sweep / 'ray') == table(sweep / 'one')


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        return int(s.getsockname()[1])


def _processes_mentioning(text: str) -> list[int]:
    found = []
    for entry in Path('/proc').iterdir():
        if entry.name.isdigit():
            try:
                if text.encode() in (entry / 'cmdline').read_bytes():
                    found.append(int(entry.name))
            except OSError:
                continue
    return found


def _wait_for_port(port: int, process: subprocess.Popen[str], seconds: float) -> None:
    import time

    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline and process.poll() is None:
        with socket.socket() as probe:
            if probe.connect_ex(('127.0.0.1', port)) == 0:
                return
        time.sleep(0.2)
    raise AssertionError(f'the Ray head did not listen on {port} (exit {process.poll()})')


def test_a_campaign_on_a_ray_head_started_on_loopback(sweep: Path) -> None:
    """A head of its own, stopped by its own process group: never `ray stop`, which kills every Ray process on
    the machine and any process with `monitor.py` in its command line (another suite's system under test)."""
    import signal
    import time

    pytest.importorskip('ray')
    ray_cli = Path(sys.executable).parent / 'ray'
    temp = Path(tempfile.mkdtemp(prefix='rh', dir='/tmp'))  # Ray's socket paths must stay short
    port = _free_port()
    # (no token: two suites' heads would write one user's token file in turn; the head is this test's alone)
    env = {**os.environ, 'RAY_USAGE_STATS_ENABLED': '0', 'RAY_AUTH_MODE': 'disabled'}
    head = subprocess.Popen([str(ray_cli), 'start', '--head', '--block', '--node-ip-address', '127.0.0.1', '--port',
                             str(port), '--temp-dir', str(temp), '--num-cpus', '2', '--include-dashboard', 'false',
                             '--disable-usage-stats'], env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True, start_new_session=True)
    try:
        assert head.stdout is not None
        said = []
        for line in head.stdout:  # (EOF if it fails) it says so once the node is up and its token written
            said.append(line)
            if 'Ray runtime started' in line:
                break
        if head.poll() is not None or not any('Ray runtime started' in line for line in said):
            pytest.skip(f'Ray itself could not start a head here: {" ".join("".join(said).split())[-300:]}')
        _wait_for_port(port, head, 60)
        done = subprocess.run([sys.executable, '-m', 'bagfault.cli', 'campaign', str(sweep / 'campaign.yaml'), '-o',
                               str(sweep / 'head'), '--ray', f'127.0.0.1:{port}'], env=env, capture_output=True,
                              text=True, timeout=300, check=False)
        assert done.returncode == 1, done.stderr[-3000:]
        assert f'on Ray at 127.0.0.1:{port} (2 CPUs)' in done.stdout
        assert table(sweep / 'head') == table(sweep / 'one')
    finally:
        head.send_signal(signal.SIGINT)  # `ray start --block` stops what it started
        with contextlib.suppress(subprocess.TimeoutExpired):
            head.communicate(timeout=60)
        with contextlib.suppress(ProcessLookupError):
            os.killpg(head.pid, signal.SIGKILL)
        head.wait(timeout=30)
        deadline = time.monotonic() + 30
        while _processes_mentioning(str(temp)) and time.monotonic() < deadline:
            time.sleep(0.5)
        left = _processes_mentioning(str(temp))
        for pid in left:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        shutil.rmtree(temp, ignore_errors=True)
    assert left == []  # the head's processes ended with it


def test_search_finds_the_breaking_point_known_from_the_thresholds(corpus: Path) -> None:
    (corpus / 'bags' / 'b.mcap').unlink()
    path = campaign_file(corpus, f"""
        campaign: breaking
        scenario: drift.yaml
        bags: [bags/a.mcap]
        sweep: {{{BIAS}: [0.2]}}
        search:
          parameter: {BIAS}
          low: 0.0
          high: 0.5
          tolerance: 0.01
          until: {{assertion: drift_detected, state: passed}}
        keep: none
    """)
    result = api.campaign(path, corpus / 'out', workers=2)
    (point,) = result.breaking_points
    # detected iff 0.02 + bias > 0.1: the point is 0.08, bracketed to the tolerance
    assert point.below is not None and point.value is not None
    assert point.below <= 0.08 < point.value and point.value - point.below <= 0.01
    # both ends, then halvings of 0.5 down to 0.01: ceil(log2(50)) = 6
    assert point.jobs == 8
    search = [r for r in result.table.rows if r['kind'] == 'search']
    assert len(search) == 8 and [r['job'] for r in search] == list(range(1, 9))
    for row in search:
        assert row['status'] == ('passed' if 0.02 + row[BIAS] > 0.1 else 'failed')
    assert not list((corpus / 'out' / 'outputs').iterdir())  # keep: none
    html = (corpus / 'out' / 'report.html').read_text()
    assert 'Breaking point of' in html and f'{point.value:g}' in html
    drawn = {t['name']: t for t in figures(corpus / 'out' / 'report.html')[f'search:{BIAS}']['data']}
    assert sorted(drawn['passed']['x'] + drawn['failed']['x']) == sorted(r[BIAS] for r in search)
    assert all(0.02 + x > 0.1 for x in drawn['passed']['x']) and drawn['breaking point']['x'] == [point.value]


def test_an_offline_search_gives_the_same_breaking_point_byte_for_byte(corpus: Path) -> None:
    import json

    (corpus / 'bags' / 'b.mcap').unlink()
    text = f"""
        campaign: again
        scenario: drift.yaml
        bags: [bags/a.mcap]
        search:
          parameter: {BIAS}
          low: 0.0
          high: 0.5
          tolerance: 0.01
          until: {{assertion: drift_detected, state: passed}}
        keep: none
    """
    found = []
    for name in ('one', 'two'):
        result = api.campaign(campaign_file(corpus, text), corpus / name, workers=2)
        (point,) = result.breaking_points
        found.append(json.dumps(json.loads((corpus / name / 'campaign.json').read_text())['breaking_points']))
        # an offline run is the same for its seed: one sample per value by default, each 1 of 1 or 0 of 1
        assert [(s.runs, s.held) for s in point.samples] == [(1, int(0.02 + s.value > 0.1)) for s in point.samples]
    assert found[0] == found[1]
    assert 'held in 1 of 1 runs at' in point.note


def test_a_search_repeats_each_value_as_asked_and_needs_every_sample(corpus: Path) -> None:
    (corpus / 'bags' / 'b.mcap').unlink()
    path = campaign_file(corpus, f"""
        campaign: repeated
        scenario: drift.yaml
        bags: [bags/a.mcap]
        seeds: [1, 2]
        search:
          parameter: {BIAS}
          low: 0.0
          high: 0.5
          tolerance: 0.2
          repeat: 2
          until: {{assertion: drift_detected, state: passed}}
        keep: none
    """)
    result = api.campaign(path, corpus / 'out', workers=2)
    (point,) = result.breaking_points
    # values 0.0, 0.5, then 0.25 and 0.125 (tolerance 0.2: two halvings); each run 2 seeds x 2 samples
    assert [s.value for s in point.samples] == [0.0, 0.5, 0.25, 0.125]
    assert all(s.runs == 4 for s in point.samples) and point.jobs == 16
    assert (point.below, point.value) == (0.0, 0.125)  # detected iff 0.02 + bias > 0.1
    search = [r for r in result.table.rows if r['kind'] == 'search']
    assert len(search) == 16 and len({r['key'] for r in search}) == 16  # a sample is a job of its own
    assert sorted((r['seed'], r[BIAS]) for r in search) == sorted(
        (seed, value) for value in (0.0, 0.5, 0.25, 0.125) for seed in (1, 2) for _ in range(2))


def test_a_search_value_that_could_not_run_decides_nothing(corpus: Path) -> None:
    (corpus / 'bags' / 'c.mcap').write_bytes(b'\x89MCAP0\r\n' + bytes(64))
    path = campaign_file(corpus, f"""
        campaign: broken
        scenario: drift.yaml
        bags: [bags/c.mcap]
        search:
          parameter: {BIAS}
          low: 0.0
          high: 0.5
          tolerance: 0.1
          until: {{assertion: drift_detected, state: passed}}
        keep: none
    """)
    result = api.campaign(path, corpus / 'out', workers=1)
    (point,) = result.breaking_points
    assert point.value is None and point.below is None
    assert point.note.startswith('stopped: a run at 0 could not run (job ') and 'c.mcap' in point.note
    assert [(s.value, s.held) for s in point.samples] == [(0.0, 0), (0.5, 0)]  # no bisection on errors


def test_a_corrupt_bag_is_an_error_row_and_the_others_complete(corpus: Path) -> None:
    (corpus / 'bags' / 'c.mcap').write_bytes(b'\x89MCAP0\r\n' + os.urandom(64))
    path = campaign_file(corpus, f"""
        campaign: corrupt
        scenario: drift.yaml
        bags: [bags/*.mcap]
        sweep: {{{BIAS}: [0.2]}}
    """)
    assert main(['campaign', str(path), '-o', str(corpus / 'out')]) == 1
    rows = table(corpus / 'out')
    assert [(r['bag'], r['status']) for r in rows] == [('bags/a.mcap', 'passed'), ('bags/b.mcap', 'passed'),
                                                      ('bags/c.mcap', 'error')]
    assert 'c.mcap' in rows[2]['message'] and rows[2]['drift_detected'] is None
    html = (corpus / 'out' / 'report.html').read_text()
    assert 'Jobs that did not pass' in html and 'bags/c.mcap' in html


def test_resume_reruns_only_unfinished_and_changed_jobs(corpus: Path) -> None:
    body = f"""
        campaign: resumable
        scenario: drift.yaml
        bags: [bags/*.mcap]
        sweep: {{{BIAS}: [0.05, 0.2]}}
        seeds: [0, 1, 2]
    """
    path = campaign_file(corpus, body)
    out = corpus / 'out'
    with pytest.raises(KeyboardInterrupt):
        api.campaign(path, out, workers=1, progress=InterruptAfter(5))  # type: ignore[arg-type]
    stored = {p.name: p.stat().st_mtime_ns for p in (out / 'jobs').glob('*.json')}
    assert len(stored) == 5 and not (out / 'results.parquet').exists()
    assert not [p for p in (out / 'outputs').iterdir() if p.name.endswith('.partial')]
    assert main(['campaign', str(path), '-o', str(out)]) == 2  # a used folder needs --resume
    resumed = api.campaign(path, out, workers=2, resume=True)
    assert resumed.ran == 12 - 5 and len(resumed.table.rows) == 12
    assert {p.name: p.stat().st_mtime_ns for p in (out / 'jobs').glob('*.json') if p.name in stored} == stored
    # every row as a fresh campaign would have it: detected iff z + bias > 0.1 (corpus.py)
    z = {'bags/a.mcap': 0.02, 'bags/b.mcap': 0.0}
    assert [(r['bag'], r[BIAS], r['seed'], r['status']) for r in resumed.table.rows] == [
        (bag, bias, seed, 'passed' if z[bag] + bias > 0.1 else 'failed')
        for bag in z for bias in (0.05, 0.2) for seed in (0, 1, 2)]
    # a changed campaign: one more value reruns only its 6 jobs
    campaign_file(corpus, body.replace('[0.05, 0.2]', '[0.05, 0.2, 0.09]'))
    changed = api.campaign(path, out, workers=2, resume=True)
    assert changed.ran == 6 and len(changed.table.rows) == 18


def test_dry_run_prints_the_plan_and_its_size(corpus: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = campaign_file(corpus, f"""
        campaign: plan
        scenario: drift.yaml
        bags: [bags/*.mcap]
        sweep:
          {BIAS}: {{range: [0.0, 0.3, 0.1]}}
          faults.bias.start: [0.5, 1.0]
        seeds: {{range: [0, 3]}}
    """)
    assert main(['campaign', str(path), '--dry-run']) == 0
    out = capsys.readouterr().out.splitlines()
    # 2 bags x 4 biases (0.0 to 0.3 inclusive) x 2 starts x 3 seeds (0, 1, 2)
    assert out[0].startswith('campaign plan: 48 jobs (2 bags x 4 ')
    assert len(out) == 1 + 48
    assert not (corpus / 'out').exists()


def test_a_job_past_its_timeout_is_an_error_row(corpus: Path) -> None:
    path = one_bag(corpus, 'slow', 'timeout: 0.001')
    result = api.campaign(path, corpus / 'out', workers=1)
    (row,) = result.table.rows
    assert (row['status'], row['message']) == ('error', 'timed out after 0.001 s (the campaign timeout)')
    assert result.failed and result.counts == {'passed': 0, 'failed': 0, 'error': 1}


def test_a_ray_address_where_nothing_answers_is_one_line_and_leaves_nothing(corpus: Path,
                                                                           capsys: pytest.CaptureFixture[str]) -> None:
    path = one_bag(corpus, 'nowhere')
    assert main(['campaign', str(path), '-o', str(corpus / 'out'), '--ray', f'127.0.0.1:{_free_port()}']) == 2
    err = capsys.readouterr().err
    assert err.startswith('bagfault: error: --ray 127.0.0.1:') and 'no Ray head answers there' in err
    assert len(err.splitlines()) == 1 and 'Traceback' not in err
    assert not (corpus / 'out').exists()


def test_without_pyarrow_the_table_and_the_report_are_still_written(corpus: Path) -> None:
    """The jobs ran: results.csv and report.html hold their table; only results.parquet needs the extra."""
    path = one_bag(corpus, 'no_arrow', 'keep: none')
    blocked = corpus / 'no_arrow'
    blocked.mkdir()
    (blocked / 'pyarrow.py').write_text('raise ImportError("pyarrow is not installed here")\n')
    env = {**os.environ, 'PYTHONPATH': os.pathsep.join(filter(None, [str(blocked), os.environ.get('PYTHONPATH')]))}
    done = subprocess.run([sys.executable, '-m', 'bagfault.cli', 'campaign', str(path), '-o', str(corpus / 'out'),
                           '--workers', '1'], env=env, capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 0, done.stderr
    assert done.stderr.startswith('bagfault: pyarrow is not installed: results.csv and report.html will hold')
    assert 'note: results.parquet not written: pyarrow is not installed' in done.stdout
    assert (corpus / 'out' / 'results.csv').exists() and (corpus / 'out' / 'report.html').exists()
    assert not (corpus / 'out' / 'results.parquet').exists()
    assert f'results   {corpus / "out" / "results.csv"}' in done.stdout


def test_a_jobs_warnings_and_what_made_the_table_are_in_it(corpus: Path) -> None:
    """A bag without the faulted topic: the run's warning is in the job's row (CSV and Parquet), not only a
    'failed'; the Parquet file says which campaign, bagfault and scenario made it; a symlinked folder of bags
    keeps the name the campaign gives it."""
    import csv
    import hashlib

    from bagfault import __version__

    (corpus / 'other').mkdir()
    write_imu_bag(corpus / 'other' / 'odom_only.mcap', 0.0, topic='/odom_imu')
    (corpus / 'linked').symlink_to(corpus / 'other', target_is_directory=True)
    path = campaign_file(corpus, f"""
        campaign: warned
        scenario: drift.yaml
        bags: [linked/odom_only.mcap]
        sweep: {{{BIAS}: [0.2]}}
        keep: none
    """)
    result = api.campaign(path, corpus / 'out', workers=1)
    (row,) = result.table.rows
    assert row['bag'] == 'linked/odom_only.mcap'
    assert 'input topic /imu is not in the bag' in row['warnings']
    with (corpus / 'out' / 'results.csv').open() as stream:
        (written,) = list(csv.DictReader(stream))
    assert written['warnings'] == row['warnings']
    meta = pq.read_schema(corpus / 'out' / 'results.parquet').metadata
    assert meta[b'bagfault.campaign'] == b'warned' and meta[b'bagfault.version'] == __version__.encode()
    assert meta[b'bagfault.scenario_sha256'] == hashlib.sha256((corpus / 'drift.yaml').read_bytes()).hexdigest().encode()
    assert meta[b'bagfault.campaign_sha256'] == hashlib.sha256(path.read_bytes()).hexdigest().encode()


ORPHANS = """
import ctypes, os, subprocess, sys, time
ctypes.CDLL(None).prctl(36, 1, 0, 0, 0)  # PR_SET_CHILD_SUBREAPER: the campaign's orphans become ours
code = subprocess.call(sys.argv[1:])
time.sleep(1.0)
orphans = 0
while True:
    try:
        pid, _ = os.waitpid(-1, os.WNOHANG)
    except ChildProcessError:
        break
    if pid == 0:
        time.sleep(0.2)
        continue
    orphans += 1
print(code, orphans)
"""


@pytest.mark.parametrize('engine', [['--workers', '2'], ['--ray', '']], ids=['local', 'ray'])
def test_a_campaign_leaves_no_zombie_behind(corpus: Path, engine: list[str]) -> None:
    """Its fork server and resource tracker are stopped and reaped when it ends: left to exit with it, they
    were two zombies per campaign on a machine whose PID 1 reaps none (this one); with a local Ray instance,
    the fork servers of Ray's workers were four more. The campaign runs under a subreaper here, which counts
    what it left to be reaped, whatever else runs on the machine."""
    path = one_bag(corpus, 'tidy', 'keep: none')
    env = {**os.environ, 'RAY_USAGE_STATS_ENABLED': '0', 'RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER': '0'}
    done = subprocess.run([sys.executable, '-c', ORPHANS, sys.executable, '-m', 'bagfault.cli', 'campaign',
                           str(path), '-o', str(corpus / 'out'), *engine], capture_output=True, text=True,
                          timeout=300, check=False, env=env)
    if done.stdout.split()[-2:-1] == ['2']:
        skip_if_ray_did_not_start(done.stderr)
    assert done.stdout.split()[-2:] == ['0', '0'], done.stdout + done.stderr  # exit 0, nothing left to reap


def test_a_campaign_folder_replaces_nothing_it_reads_or_did_not_write(
        corpus: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A results.csv of someone else's in -o stops the campaign before any job (--force replaces it); -o inside a
    bag folder is refused."""
    path = one_bag(corpus, 'guard')
    out = corpus / 'guarded'
    out.mkdir()
    (out / 'results.csv').write_text('name,score\nmine,1\n')
    assert main(['campaign', str(path), '-o', str(out), '--workers', '1']) == 2
    error = capsys.readouterr().err.strip()
    assert error.count('\n') == 0 and 'results.csv' in error and 'bagfault did not write it' in error
    assert sorted(p.name for p in out.iterdir()) == ['results.csv']
    assert main(['campaign', str(path), '-o', str(out), '--workers', '1', '--force']) == 0  # 0.02 + 0.2 > 0.1
    assert (out / 'results.csv').read_text().startswith('job,kind,bag,seed,')
    assert main(['campaign', str(path), '-o', str(out), '--workers', '1', '--resume']) == 0  # its files are ours now


def test_the_heatmap_colours_agree_with_the_rate_table(corpus: Path, tmp_path: Path) -> None:
    """The table shows a rate as hue 120 x rate (green at 100 %, red at 0 %); the heatmap of two parameters
    must draw the same way round (it drew 100 % in deep red: plotly.js knows no 'RdYlGn')."""
    import re

    path = campaign_file(corpus, f"""
        campaign: grid
        scenario: drift.yaml
        bags: [bags/a.mcap]
        sweep:
          {BIAS}: [0.05, 0.2]
          faults.bias.start: [1.0, 1.5]
    """)
    assert main(['campaign', str(path), '-o', str(corpus / 'out'), '--workers', '1']) == 1
    page = corpus / 'out' / 'report.html'
    heatmap = next(f for name, f in figures(page).items() if name.startswith('heatmap:'))['data'][0]
    assert heatmap['z'] == [[0.0, 0.0], [100.0, 100.0]]  # 0.02 + 0.05 < 0.1 < 0.02 + 0.2, whatever the start

    def hue(at: float) -> int:
        stop = next(color for position, color in heatmap['colorscale'] if position == at)
        return int(re.match(r'hsl\((\d+),', stop).group(1))

    assert (hue(0.0), hue(1.0)) == (0, 120)
    html = page.read_text()
    assert 'background:hsl(120,65%,82%)' in html and 'background:hsl(0,65%,82%)' in html  # the table, same way
    assert rendered(page, tmp_path / 'profile')['errors'] == '0'


def test_a_campaign_hashes_each_bag_once(corpus: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The plan hashes each bag (BLAKE3, as `b3sum`) and hands the digests to its jobs: a job does not read the
    bag a second time to hash it (here its hashing is made to fail, and the job still runs, with the plan's
    digest in its output's provenance); a bag changed since the plan is hashed again."""
    import blake3

    from bagfault.api import job as run_job
    from bagfault.campaign.loader import load_campaign
    from bagfault.campaign.plan import make_plan
    from bagfault.io import sources

    path = one_bag(corpus, 'once')
    plan = make_plan(load_campaign(path))
    bag = corpus / 'bags' / 'a.mcap'
    ((*_, size, _, _, digest),) = plan.file_digests[str(bag)]
    assert (size, digest) == (bag.stat().st_size, blake3.blake3(bag.read_bytes()).hexdigest())
    spec = plan.jobs[0].spec(plan.campaign, tmp_path / 'out.mcap', plan.file_digests)
    sources._known.clear()

    def no_hashing(*_args: object) -> str:
        raise AssertionError('the job hashed the bag again')

    monkeypatch.setattr(sources, '_blake3', no_hashing)
    result = run_job(spec)
    assert result['status'] == 'passed', result
    from mcap.reader import make_reader
    with (tmp_path / 'out.mcap').open('rb') as stream:
        provenance = next(m for m in make_reader(stream).iter_metadata() if m.name == 'bagfault')
    assert digest in provenance.metadata['inputs']
    sources._known.clear()
    bag.write_bytes(bag.read_bytes())  # the same bytes, written again: its ctime changed, so it is not trusted
    result = run_job(plan.jobs[0].spec(plan.campaign, tmp_path / 'again.mcap', plan.file_digests))
    assert result['status'] == 'error' and 'hashed the bag again' in result['message']


def test_only_rays_own_start_failure_makes_a_ray_test_skip() -> None:
    """The suite under load says why a Ray test did not run, and never skips one for a bagfault error."""
    from support.raycluster import started_by_ray

    skip_if_ray_did_not_start('bagfault: error: campaign.yaml: scenario: no such file\n')  # judged by the test
    with pytest.raises(pytest.skip.Exception, match=r'Ray itself could not start a local instance here: .*GCS'):
        skip_if_ray_did_not_start('bagfault: error: --ray: cannot start or reach a local Ray instance: GCS timed out')

    def failing() -> None:
        raise TimeoutError('the head did not start within 30 s')

    with pytest.raises(pytest.skip.Exception, match=r'Ray itself could not start a Ray cluster.*within 30 s'):
        started_by_ray(failing)
    assert started_by_ray(lambda: 7) == 7
