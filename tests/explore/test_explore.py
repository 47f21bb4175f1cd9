"""`bagfault explore` offline: the planted failures of tests/fixtures/scenarios/explore_space.yaml found and shrunk
to their known minimal causes (derived by hand in that file), reproducible for any number of workers, resumable
after a stop, and its bad inputs refused before any run."""

from __future__ import annotations

import json
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
from support.helpers import FIXTURES, make_bag, sha256
from support.html_check import rendered

from bagfault import api
from bagfault.cli import main
from bagfault.explore.explorer import Explorer

SPACE = FIXTURES / 'scenarios' / 'explore_space.yaml'
RESOLUTION = 0.01


def space_in(folder: Path, text: str | None = None) -> Path:
    """The space file and its 6 s bag (/imu every 20 ms, /odom every 40 ms) in `folder`."""
    folder.mkdir(parents=True, exist_ok=True)
    make_bag(folder / 'explore_small.mcap', [('/imu', 'sensor_msgs/msg/Imu', 50.0),
                                             ('/odom', 'nav_msgs/msg/Odometry', 25.0)], 6.0)
    path = folder / 'space.yaml'
    path.write_text(text if text is not None else SPACE.read_text())
    return path


@pytest.fixture(scope='module')
def explored(tmp_path_factory: pytest.TempPathFactory):
    folder = tmp_path_factory.mktemp('explore')
    space = space_in(folder / 'space')
    result = api.explore(space, directory=folder / 'out', budget=100, workers=2, save_failures=folder / 'suite')
    return result, folder


def by_assertions(result):
    return {f.assertions: f for f in result.failures}


def values(failure, fault):
    return dict(failure.minimal.drawn(fault).values)


def test_each_planted_failure_is_found_and_shrunk_to_its_known_minimal_cause(explored):
    result, _ = explored
    found = by_assertions(result)
    assert result.failed and len(result.runs) - sum(f.unused_runs for f in result.failures) <= 100
    yaw = found[frozenset({'yaw_rate_ok'})]
    assert yaw.state == 'shrunk' and yaw.minimal.ids == ('yaw',)
    v = values(yaw, 'yaw')
    assert 0.4 < v['config.angular_velocity_z_bias'] <= 0.4 + RESOLUTION * 1.0
    assert v['config.linear_acceleration_x_bias'] == 0.0  # the decoy at its weakest
    assert v['duration'] == 0.1 and v['start'] == 3.0  # any window holding one message: the shortest, the latest
    accel = found[frozenset({'accel_ok'})]
    assert accel.minimal.ids == ('shock_a', 'shock_b')  # only together
    total = values(accel, 'shock_a')['config.linear_acceleration_z_bias'] + \
        values(accel, 'shock_b')['config.linear_acceleration_z_bias']
    assert 2.19 < total <= 2.19 + 2 * RESOLUTION * 2.0 + 0.004  # each within resolution (+ the grid)
    silence = found[frozenset({'odom_alive'})]
    assert silence.minimal.ids == ('odom_silence',)
    v = values(silence, 'odom_silence')
    assert 0.44 < v['duration'] <= 0.48 + RESOLUTION * 1.4 and v['start'] == 3.0
    # an assertion naming a candidate is judged only in the runs that draw it: never a failure of its own
    assert not any('imu_alive_during_silence' in f.assertions for f in result.failures)
    assert all(r.outcome.status != 'error' for r in result.runs)
    baseline = result.runs[0]
    assert baseline.purpose == 'baseline' and baseline.candidate.faults == () and baseline.outcome.status == 'passed'
    assert set(baseline.outcome.margins) == {'yaw_rate_ok', 'accel_ok', 'odom_alive'}  # no odom_silence drawn


def test_each_minimal_scenario_replays_as_it_is(explored, tmp_path):
    """`bagfault run` of failures/<name>.min.yaml, as written, fails exactly the failure's assertions, and its
    output is the faulty bag the exploration kept, byte for byte."""
    result, folder = explored
    for failure in result.failures:
        if failure.replay is None:
            continue
        minimal = folder / 'out' / 'failures' / f'{failure.name}.min.yaml'
        assert minimal.read_text().startswith('# bagfault explore: ')
        scenario = api.load_scenario(minimal)
        again = api.run(scenario, scenario.bags, tmp_path / f'{failure.name}.mcap')
        assert {a.id for a in again.assertions if a.state != 'passed'} == failure.assertions
        assert failure.replay.status == 'failed' and failure.replay.failing == failure.assertions
        assert sha256(tmp_path / f'{failure.name}.mcap') == sha256(folder / 'out' / 'failures' / f'{failure.name}.mcap')


def test_explore_json_and_the_report(explored, tmp_path):
    result, folder = explored
    document = json.loads((folder / 'out' / 'explore.json').read_text())
    assert document['tool']['name'] == 'bagfault' and document['runs_used'] == len(result.runs)
    assert [r['index'] for r in document['runs']] == list(range(len(result.runs)))
    run = document['runs'][1]
    assert {'scenario_sha256', 'seed', 'status', 'failing', 'margins', 'faults', 'purpose'} <= set(run)
    for entry in document['failures']:
        assert entry['minimal'] == f'failures/{entry["name"]}.min.yaml'
        assert (folder / 'out' / entry['minimal']).exists() and (folder / 'out' / entry['original']).exists()
        assert entry['shrink_runs'] == sum(s['runs'] for s in entry['steps']) + (entry['replay'] is not None)
    page = rendered(folder / 'out' / 'report.html', tmp_path / 'profile')
    assert page['errors'] == '0' and int(page['figures']) >= 2


def test_saved_failures_are_a_regression_suite_pytest_runs(explored):
    """--save-failures writes test_<name>.bagfault.yaml files: the pytest plugin collects each assertion as a test
    and the failing ones fail (until the cause is fixed)."""
    result, folder = explored
    saved = sorted((folder / 'suite').glob('test_*.bagfault.yaml'))
    assert len(saved) == sum(f.minimal is not None for f in result.failures) == len(result.saved)
    done = subprocess.run([sys.executable, '-m', 'pytest', str(folder / 'suite'), '-q', '-p', 'no:cacheprovider',
                           '-n', '0', '-rf', '--rootdir', str(folder / 'suite')],
                          capture_output=True, text=True, cwd=folder / 'suite', check=False)
    assert done.returncode == 1, done.stdout + done.stderr
    failed = {line.split('::')[-1].split(' ')[0] for line in done.stdout.splitlines() if line.startswith('FAILED')}
    assert failed == set().union(*(f.assertions for f in result.failures if f.minimal is not None))


def comparable(folder: Path) -> dict[str, object]:
    """explore.json less what depends on the machine (run times, the engine), and every failure file's bytes."""
    document = json.loads((folder / 'explore.json').read_text())
    document.pop('engine')
    document.pop('bagfault_mark')  # over the whole document, run times included
    for run in document['runs']:
        run.pop('seconds')
    files = {p.name: sha256(p) for p in sorted((folder / 'failures').iterdir())}
    return {'document': document, 'files': files}


def test_the_same_seed_gives_the_same_runs_for_any_workers_and_after_a_stop(tmp_path):
    """Byte for byte, offline: one worker, two workers, and a run stopped by SIGINT after a few runs then resumed."""
    space = space_in(tmp_path / 'space')
    one = api.explore(space, directory=tmp_path / 'one', budget=36, workers=1, seed=7)
    api.explore(space, directory=tmp_path / 'two', budget=36, workers=2, seed=7)
    assert comparable(tmp_path / 'one') == comparable(tmp_path / 'two')
    assert one.failures
    command = [sys.executable, '-m', 'bagfault', 'explore', str(space), '-o', str(tmp_path / 'stopped'),
               '--budget', '36', '--seed', '7', '--workers', '2']
    inherited = (signal.getsignal(signal.SIGINT), signal.pthread_sigmask(signal.SIG_BLOCK, []))

    def as_from_a_shell() -> None:  # SIGINT's default action, unblocked, whatever this test process was left with
        signal.signal(signal.SIGINT, signal.SIG_DFL)  # (twice in full suites beside another, the stopped explore
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})  # heard no SIGINT and ran to its end)

    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               preexec_fn=as_from_a_shell)  # noqa: PLW1509 - two calls, no lock taken
    log = tmp_path / 'stopped' / 'runs.jsonl'
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and (not log.exists() or len(log.read_text().splitlines()) < 8):
        time.sleep(0.05)
    waited = time.monotonic() - deadline + 60
    process.send_signal(signal.SIGINT)
    out, err = process.communicate(timeout=60)
    assert process.returncode == 2 and '--resume continues' in err and 'Traceback' not in err, \
        (process.returncode, f'SIGINT after {waited:.2f} s', inherited, out[-1500:], err[-1500:])
    indices = {json.loads(line)['index'] for line in log.read_text().splitlines()}
    made = len(indices)  # two workers finish out of order: the log may hold a run past one the stop cut short
    assert 8 <= made < 36
    resumed = api.explore(space, directory=tmp_path / 'stopped', budget=36, workers=2, seed=7, resume=True)
    assert resumed.ran == len(resumed.runs) - made
    assert comparable(tmp_path / 'stopped') == comparable(tmp_path / 'one')
    assert main(['explore', str(space), '-o', str(tmp_path / 'one'), '--budget', '36']) == 2  # no resume: refused


def test_a_space_where_nothing_fails_exits_0(tmp_path, capsys):
    data = yaml.safe_load(SPACE.read_text())
    faults = {f['id']: f for f in data['explore']['faults']}
    faults['yaw']['config']['angular_velocity_z_bias'] = [0.0, 0.3]  # 0.4 fails
    faults['shock_a']['config']['linear_acceleration_z_bias'] = [0.0, 1.0]  # together above 2.19 fails
    faults['shock_b']['config']['linear_acceleration_z_bias'] = [0.0, 1.0]
    faults['odom_silence']['duration'] = [0.1, 0.3]  # 0.44 s fails
    space = space_in(tmp_path / 'space', yaml.safe_dump(data))
    assert main(['explore', str(space), '-o', str(tmp_path / 'out'), '--budget', '12']) == 0
    out = capsys.readouterr().out
    assert '12 of 12 runs' in out and '0 failures found' in out


BAD = [
    ('config: {angular_velocity_z_bias: [0.0, 1.0], linear_acceleration_x_bias: [0.0, 3.0]}',
     'config: {angular_velocity_z_bias: [1.0, 0.0]}', 'angular_velocity_z_bias: [1, 0] is inverted'),
    ('config: {angular_velocity_z_bias: [0.0, 1.0], linear_acceleration_x_bias: [0.0, 3.0]}',
     'config: {angular_velocity_z_bias: [0.5, 0.5]}', 'angular_velocity_z_bias: [0.5, 0.5] is an empty range'),
    ('config: {angular_velocity_z_bias: [0.0, 1.0], linear_acceleration_x_bias: [0.0, 3.0]}',
     'config: {angular_velocity_z_bais: [0.0, 1.0]}', "a key injector type 'imu' lacks (did you mean "
                                                      "'angular_velocity_z_bias'?)"),
    ('config: {drop_probability: 1.0}', 'config: {drop_probability: [0.0, 1.5]}',
     'drop_probability: the high end 1.5: 1.5 is above the maximum 1.0'),
    ('{id: odom_silence, injector_id: odom', '{id: odom_silence, injector_id: lidar',
     "unknown injector 'lidar' (injectors: imu, odom)"),
    ('max_faults: 3', 'max_faults: 0', 'explore.max_faults: 0 is not an integer from 1 to 16'),
    ('budget: 120', 'budget: 0', 'explore.budget: 0 is not an integer from 1 to 100000'),
    ('start: [0, 3], duration: [0.1, 1.5], config: {drop_probability: 1.0}', 'duration: [0, 1.5], config: {}',
     'duration[0]: 0 must be greater than 0'),
]


@pytest.mark.parametrize(('old', 'new', 'said'), BAD, ids=[b[2].split(':')[0].split(' ')[0] for b in BAD])
def test_a_bad_space_is_one_line_and_exit_2_before_any_run(old, new, said, tmp_path, capsys):
    assert old in SPACE.read_text()
    space = space_in(tmp_path / 'space', SPACE.read_text().replace(old, new, 1))
    assert main(['explore', str(space), '-o', str(tmp_path / 'out')]) == 2
    err = capsys.readouterr().err
    assert said in err and f'{space}:' in err and 'Traceback' not in err
    assert len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / 'out').exists()  # nothing written
    assert main(['validate', str(space)]) == 2  # validate says the same


def test_no_dimension_and_bad_options_are_refused(tmp_path, capsys):
    fixed = '\n'.join(line for line in SPACE.read_text().splitlines()
                      if not line.lstrip().startswith(('- {id: yaw', 'config: {angular', '- {id: shock')))
    fixed = fixed.replace('start: [0, 3], duration: [0.1, 1.5], config: {drop_probability: 1.0}',
                          'start: 1.0, duration: 1.0, config: {drop_probability: 1.0}')
    space = space_in(tmp_path / 'space', fixed.replace('max_faults: 3', 'max_faults: 1'))
    assert main(['explore', str(space), '-o', str(tmp_path / 'out')]) == 2
    assert 'explore.faults: no dimension to explore' in capsys.readouterr().err
    good = space_in(tmp_path / 'good')
    for option in (['--budget', '0'], ['--workers', '0'], ['--rate', '0']):
        assert main(['explore', str(good), '-o', str(tmp_path / 'out'), *option]) == 2
        assert option[0] in capsys.readouterr().err
    assert main(['run', str(good), str(good.parent / 'explore_small.mcap'), '-o', str(tmp_path / 'x.mcap')]) == 2
    assert 'has an explore: section' in capsys.readouterr().err
    assert not (tmp_path / 'out').exists() and not (tmp_path / 'x.mcap').exists()


def test_validate_and_the_schema_know_the_explore_section(capsys):
    assert main(['validate', str(SPACE)]) == 0
    assert 'explore space of 4 candidates' in capsys.readouterr().out
    assert main(['schema', '--json-schema', 'scenario']) == 0
    schema = json.loads(capsys.readouterr().out)
    assert {'faults', 'max_faults', 'budget', 'confirm', 'resolution', 'batch'} <= set(
        schema['$defs']['explore']['properties'])
    assert 'anyOf' in schema['$defs']['explore_fault']['properties']['start']


def test_on_a_ray_cluster_the_same_runs_as_on_the_local_pool(tmp_path, monkeypatch):
    """Runs spread over a real two-node Ray cluster: byte for byte what the local pool gives, offline."""
    pytest.importorskip('ray', reason='campaign extra not installed')
    from support.raycluster import local_cluster

    space = space_in(tmp_path / 'space')
    with local_cluster(monkeypatch) as cluster:
        address = cluster.address
        result = api.explore(space, directory=tmp_path / 'ray', budget=24, seed=7, ray=address)
    assert result.engine == f'Ray at {address} (2 CPUs)'
    api.explore(space, directory=tmp_path / 'local', budget=24, seed=7, workers=2)
    assert comparable(tmp_path / 'ray') == comparable(tmp_path / 'local')


def test_a_baseline_that_cannot_run_ends_the_exploration_with_exit_2(tmp_path, capsys):
    """The field path is checked against the bag's type when the run starts: every run would fail to run, so the
    baseline's reason is said in one line and nothing more is run."""
    text = SPACE.read_text().replace('field: angular_velocity.z, max: 0.5', 'field: angular_velocity.w, max: 0.5')
    space = space_in(tmp_path / 'space', text)
    assert main(['explore', str(space), '-o', str(tmp_path / 'out'), '--budget', '20']) == 2
    err = capsys.readouterr().err
    assert 'the baseline run (no fault) could not run' in err and 'angular_velocity.w' in err
    assert len((tmp_path / 'out' / 'runs.jsonl').read_text().splitlines()) == 1


def test_a_resume_runs_only_what_the_log_lacks_even_past_a_gap(tmp_path, monkeypatch):
    """A stopped round's log can hold a run past one that never ended (two workers finish out of order): a resume
    runs only the missing one and keeps the rest (each checked by its scenario's digest), and the exploration
    ends as the uninterrupted one did. Made by construction: a finished exploration's log cut after its first
    round of two runs or more, less that round's first run."""
    from bagfault.explore.explorer import Explorer

    rounds: list[tuple[int, int]] = []
    original = Explorer._run_round

    def run_round(self, engine, requests, stored, scratch):
        rounds.append((len(self.runs), len(self.runs) + len(requests)))
        return original(self, engine, requests, stored, scratch)

    monkeypatch.setattr(Explorer, '_run_round', run_round)
    space = space_in(tmp_path / 'space')
    api.explore(space, directory=tmp_path / 'whole', budget=24, workers=2, seed=3)
    monkeypatch.setattr(Explorer, '_run_round', original)
    first, last = next((a, b) for a, b in rounds if b - a >= 2)
    stopped = tmp_path / 'stopped'
    shutil.copytree(tmp_path / 'whole', stopped)
    (stopped / 'explore.json').unlink()
    lines = (stopped / 'runs.jsonl').read_text().splitlines()
    total = len(lines)
    kept = [line for line in lines if json.loads(line)['index'] < last and json.loads(line)['index'] != first]
    (stopped / 'runs.jsonl').write_text(''.join(f'{line}\n' for line in kept))
    resumed = api.explore(space, directory=stopped, budget=24, workers=2, seed=3, resume=True)
    assert resumed.ran == 1 + (total - last)  # the missing run, then every later round
    assert comparable(stopped) == comparable(tmp_path / 'whole')


def test_only_the_baseline_run_looks_for_wall_time(tmp_path, monkeypatch):
    """The job of every run says whether it holds the clock to look for wall time (in closed loop, at a rate
    other than 1): the baseline does, every run after it does not (the looking costs a second of each run).
    The engine here records the jobs it is given and passes each."""
    from bagfault.explore import explorer

    jobs: list[dict] = []

    class Recording:
        description = 'recording'

        def run(self, specs, done):
            for number, spec in enumerate(specs):
                jobs.append(spec)
                done(number, {'status': 'passed', 'message': '', 'assertions': {}, 'warnings': [], 'seconds': 0.0})

        def close(self):
            pass

    monkeypatch.setattr(explorer, 'make_engine', lambda *_: Recording())
    result = api.explore(space_in(tmp_path / 'space'), directory=tmp_path / 'out', budget=6, workers=1)
    assert result.runs[0].purpose == 'baseline' and len(jobs) == 6
    assert [job['clock_check'] for job in jobs] == [True] + [False] * 5


def test_runs_ahead_change_how_soon_a_shrink_ends_not_where(tmp_path, monkeypatch):
    """The same exploration with and without runs ahead (the reference: none): the same failures, the same shrink
    paths and minimal causes, the same runs counted; with them, a round where a shrink step stood alone holds a
    run ahead too, and each run ahead taken saves the reference's round for that step (at most one)."""
    space = space_in(tmp_path / 'space')
    rounds, made = [0], []  # rounds of each exploration; runs ahead made
    counted, aheads = Explorer._run_round, Explorer._ahead

    def count(self, *args):
        rounds[-1] += 1
        return counted(self, *args)

    def ahead_counted(self, failure):
        requests = aheads(self, failure)
        made.extend(requests)
        return requests

    monkeypatch.setattr(Explorer, '_run_round', count)
    monkeypatch.setattr(Explorer, '_ahead', ahead_counted)
    ahead = api.explore(space, directory=tmp_path / 'ahead', budget=60, workers=2, seed=3)
    monkeypatch.setattr(Explorer, '_ahead', lambda self, failure: [])
    rounds.append(0)
    reference = api.explore(space, directory=tmp_path / 'reference', budget=60, workers=2, seed=3)

    def paths(result):
        return [(f.assertions, f.state, f.minimal, [(s.change, s.candidate, s.kept, s.runs) for s in f.steps],
                 f.shrink_runs) for f in result.failures]

    assert reference.failures and paths(ahead) == paths(reference)
    unused = sum(f.unused_runs for f in ahead.failures)
    assert sum(f.unused_runs for f in reference.failures) == 0
    assert len(ahead.runs) - unused == len(reference.runs) <= 60  # unused runs are the only extra ones
    taken = len(made) - unused
    assert taken > 0
    assert rounds[1] - taken <= rounds[0] < rounds[1], (rounds, taken)
    document = json.loads((tmp_path / 'ahead' / 'explore.json').read_text())
    assert document['unused_runs'] == unused == sum(f['unused_runs'] for f in document['failures'])
