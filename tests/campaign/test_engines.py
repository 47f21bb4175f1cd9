"""A campaign on a real multi-node Ray cluster on this machine (ray.cluster_utils.Cluster: a head and two worker
nodes, each its own raylet, kept on 127.0.0.1), over bags in a bucket (moto's S3 server): jobs land on more
than one node and each node fills its own cache; a worker node killed mid-campaign loses no job; a driver
killed with SIGKILL is finished by --resume; a bag's jobs go to the node that holds it. Every table is compared
with the same campaign on a local pool.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
from support.corpus import SCENARIO, campaign_file
from support.hold import hold_plugin
from support.raycluster import RAY_ENV, started_by_ray

pytest.importorskip('ray', reason='campaign extra not installed')
pq = pytest.importorskip('pyarrow.parquet', reason='campaign extra not installed')
pytest.importorskip('boto3', reason='moto[server] (test extra) not installed')
from support.s3 import BUCKET, S3Server  # noqa: E402 - after the skips: it needs boto3

BIAS = 'faults.bias.config.angular_velocity_z_bias'
CAMPAIGN = f"""
    campaign: cluster
    scenario: drift.yaml
    bags: [%s]
    sweep:
      {BIAS}: [0.05, 0.1, 0.2]
    seeds: [0, 1, 2]
"""
HOLD = '  - {id: hold, type: hold, input_topic: /imu, output_topic: /imu_held}\n'
HELD = '  - {id: held, injector_id: hold, active_on_startup: true, config: {level: 1.0}}\n'

def rows(path: Path) -> list[dict[str, Any]]:
    return [{k: v for k, v in row.items() if k not in ('seconds', 'cpu_s', 'output', 'key', 'bag')} | {
        'bag': row['bag'].rsplit('/', 1)[1]} for row in pq.read_table(path / 'results.parquet').to_pylist()]


@pytest.fixture
def cluster(corpus: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Any:
    """The S3 server with the corpus's bags, then a head and two worker nodes whose processes inherit the AWS
    variables and a cache folder of their own each (BAGFAULT_CACHE_NODE)."""
    server = S3Server(tmp_path)
    try:
        yield from _cluster_on(server, corpus, tmp_path, monkeypatch)
    finally:
        server.stop()


def _cluster_on(server: S3Server, corpus: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Any:
    from ray._private import ray_constants
    from ray.cluster_utils import Cluster

    monkeypatch.setattr(ray_constants, 'ENABLE_RAY_CLUSTER', False)  # read at import: this process imported Ray
    server.s3.create_bucket(Bucket=BUCKET)
    for name in ('a.mcap', 'b.mcap'):
        server.s3.upload_file(str(corpus / 'bags' / name), BUCKET, f'bags/{name}')
    plugin = hold_plugin(tmp_path / 'plugin')
    gates = tmp_path / 'gates'
    gates.mkdir()
    held = {'BAGFAULT_CACHE': str(tmp_path / 'cache'), 'HOLD_GATE': str(gates / 'open'),
            'PYTHONPATH': os.pathsep.join(filter(None, [str(plugin), os.environ.get('PYTHONPATH')]))}
    for key, value in {**server.env, **RAY_ENV, **held}.items():
        monkeypatch.setenv(key, value)
    # the drift scenario, and a hold on every job's first message: a test's hand on the campaign
    text = SCENARIO % {'bias': '0.0'}
    line = '  - {id: imu, type: imu, input_topic: /imu, output_topic: /imu_out}\n'
    assert line in text
    (corpus / 'drift.yaml').write_text(text.replace(line, line + HOLD).replace('faults:\n', 'faults:\n' + HELD))
    ray_cluster = started_by_ray(lambda: Cluster(initialize_head=True, head_node_args={
        'num_cpus': 1, 'include_dashboard': False, 'env_vars': {'BAGFAULT_CACHE_NODE': 'head'}}))
    try:
        nodes = [started_by_ray(lambda n=n: ray_cluster.add_node(num_cpus=1,
                                                                 env_vars={'BAGFAULT_CACHE_NODE': f'node{n}'}))
                 for n in (1, 2)]
        started_by_ray(ray_cluster.wait_for_nodes)
        ray_cluster.nodes = nodes  # type: ignore[attr-defined]
        ray_cluster.port = int(ray_cluster.address.rsplit(':', 1)[1])  # type: ignore[attr-defined]
        assert ray_cluster.address.startswith('127.0.0.1:'), ray_cluster.address
        yield ray_cluster
    finally:
        ray_cluster.shutdown()


def kill_node(cluster: Any, node: Any) -> None:
    """A machine lost: SIGKILL to the node's raylet and every process under it (its Ray workers, their job
    processes), then the node taken out of the cluster. (Removing the raylet alone lets a running worker
    finish its task and report it.)"""
    raylet = node.all_processes['raylet'][0].process.pid
    family = [raylet, *descendants(raylet)]
    for pid in family:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)
    cluster.remove_node(node, allow_graceful=False)


def descendants(pid: int) -> list[int]:
    """Every process under `pid` (from /proc)."""
    children: dict[int, list[int]] = {}
    for entry in Path('/proc').iterdir():
        if entry.name.isdigit():
            with contextlib.suppress(OSError):
                parent = int((entry / 'stat').read_text().rsplit(')', 1)[1].split()[1])
                children.setdefault(parent, []).append(int(entry.name))
    found, todo = [], [pid]
    while todo:
        for child in children.get(todo.pop(), []):
            found.append(child)
            todo.append(child)
    return found


def driver(campaign: Path, out: Path, port: int, *extra: str) -> subprocess.Popen[str]:
    """`bagfault campaign` as its own process (a driver to kill)."""
    return subprocess.Popen([sys.executable, '-m', 'bagfault.cli', 'campaign', str(campaign), '-o', str(out),
                             '--ray', f'127.0.0.1:{port}', *extra], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def wait_for(predicate: Any, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, what
        time.sleep(0.05)


def test_jobs_spread_over_nodes_and_survive_a_node_and_a_driver_lost(cluster: Any, corpus: Path,
                                                                     tmp_path: Path) -> None:
    gate = Path(os.environ['HOLD_GATE'])
    gate.touch()  # the local run is not held
    local = campaign_file(corpus, CAMPAIGN % 'bags/*.mcap', name='local.yaml')
    # in a process of its own: the hold plugin is on its PYTHONPATH (never in this process's injector registry)
    done = subprocess.run([sys.executable, '-m', 'bagfault.cli', 'campaign', str(local), '-o', str(tmp_path / 'local'),
                           '--workers', '2'], capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 1, done.stderr[-2000:]
    expected = rows(tmp_path / 'local')
    remote = campaign_file(corpus, CAMPAIGN % f's3://{BUCKET}/bags/*.mcap')
    cache = tmp_path / 'cache'

    # 1. a worker node killed while it holds a job (the hold says so): that job runs again elsewhere
    gate.unlink()
    run = driver(remote, tmp_path / 'nodes', cluster.port)
    wait_for(lambda: gate.with_name('reached-node1').exists(), 120, 'no job reached node1')
    kill_node(cluster, cluster.nodes[0])
    gate.touch()
    out, err = run.communicate(timeout=300)
    assert run.returncode == 1, err[-3000:]  # some jobs fail their assertion, as on the local pool
    assert rows(tmp_path / 'nodes') == expected
    assert all(not r['warnings'] for r in expected)  # the hold plugin was found everywhere
    filled = sorted(p.name for p in cache.iterdir() if any(p.glob('*/*.mcap')))
    assert len(filled) >= 2 and 'node1' in filled  # jobs ran on several nodes, each downloading for itself

    # 2. the driver killed with SIGKILL after 4 stored results; --resume finishes with the same table
    run = driver(remote, tmp_path / 'killed', cluster.port)
    jobs = tmp_path / 'killed' / 'jobs'
    wait_for(lambda: len(list(jobs.glob('*.json'))) >= 4 if jobs.is_dir() else False, 120, 'no results stored')
    run.send_signal(signal.SIGKILL)
    run.communicate(timeout=60)
    stored = len(list(jobs.glob('*.json')))
    assert stored < 18  # killed mid-campaign
    # (through `--ray auto`: the running cluster that RAY_ADDRESS names, as after `ray start`, is reused)
    resumed = subprocess.Popen([sys.executable, '-m', 'bagfault.cli', 'campaign', str(remote), '-o',
                                str(tmp_path / 'killed'), '--ray', 'auto', '--resume'], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True, env={**os.environ, 'RAY_ADDRESS': cluster.address})
    out, err = resumed.communicate(timeout=300)
    assert resumed.returncode == 1, err[-3000:]
    assert f'({18 - stored} run now' in out  # only the jobs without a stored result
    assert f'on Ray at {cluster.address} (auto) (' in out  # the cluster's GCS, found by Ray itself
    assert rows(tmp_path / 'killed') == expected

    # 3. a bag's jobs go to the node that holds it: two bags new to every cache, 9 jobs each, on the two nodes
    # left. Ray's own placement ran them all on the head here (and spread bags over every node in the bench);
    # now each node takes a bag of its own, and a bag is fetched a second time only where its holder has more
    # than 2 rounds left when the other node is free (campaign/placement.py): 2 downloads, 3 where one node ran
    # 3 jobs behind the other
    import boto3

    for name in ('a.mcap', 'b.mcap'):
        boto3.client('s3').upload_file(str(corpus / 'bags' / name), BUCKET, f'fresh/new-{name}')
    fresh = campaign_file(corpus, CAMPAIGN % f's3://{BUCKET}/fresh/*.mcap', name='fresh.yaml')
    run = driver(fresh, tmp_path / 'fresh', cluster.port)
    out, err = run.communicate(timeout=300)
    assert run.returncode == 1, err[-3000:]
    held = sorted((node.name, bag.name) for node in cache.iterdir() for bag in node.glob('*/new-*.mcap'))
    assert {bag for _, bag in held} == {'new-a.mcap', 'new-b.mcap'}
    assert {node for node, _ in held} == {'head', 'node2'}, held  # both nodes worked
    assert len(held) <= 3, held

    # 4. `--ray` without an address starts an instance of its own even where a cluster runs and RAY_ADDRESS
    # names it (as when a second suite runs beside this one): Ray would join that cluster and refuse num_cpus
    local = subprocess.run([sys.executable, '-c', 'from bagfault.api import job\nfrom bagfault.campaign.engines import RayEngine\n'
                            'engine = RayEngine(None, 1, job)\nprint(engine.description)\nengine.close()'],
                           check=False, capture_output=True, text=True, timeout=120,
                           env={**os.environ, 'RAY_ADDRESS': cluster.address})
    assert local.returncode == 0, local.stderr[-3000:]
    assert local.stdout.strip() == 'a local Ray instance (1 CPUs)'


def test_a_ray_head_that_never_answers_is_one_line_within_the_connect_timeout(corpus: Path, tmp_path: Path) -> None:
    """A head that accepts TCP connections and never answers (so the reachability probe passes): ray.init kept
    retrying for minutes without a word, as it does against a token-authenticated cluster this shell has no
    token for. Bounded (the bound lowered to 5 s here), one line, exit 2, no results folder, Ray's own retry
    warnings kept off the terminal."""
    import socket

    path = campaign_file(corpus, 'campaign: silent\nscenario: drift.yaml\nbags: [bags/a.mcap]\n')
    with socket.create_server(('127.0.0.1', 0)) as server:
        address = f'127.0.0.1:{server.getsockname()[1]}'
        out = tmp_path / 'out'
        program = ('import sys\nfrom bagfault.campaign import engines\nengines.RAY_CONNECT_TIMEOUT = 5.0\n'
                   'from bagfault.__main__ import run\n'
                   f'sys.argv = ["bagfault", "campaign", {str(path)!r}, "-o", {str(out)!r}, "--ray", {address!r}]\n'
                   'sys.exit(run())\n')
        began = time.monotonic()
        done = subprocess.run([sys.executable, '-c', program], capture_output=True, text=True, timeout=120,
                              env={**os.environ, 'RAY_USAGE_STATS_ENABLED': '0'}, check=False)
        seconds = time.monotonic() - began
    assert done.returncode == 2, done.stderr
    assert done.stderr.count('\n') == 1 and f'--ray {address}: Ray did not join the cluster within 5 s' in done.stderr
    assert seconds < 60
    assert not out.exists()


def test_a_job_s_cpu_seconds_are_its_process_s_and_its_children_s() -> None:
    """By construction: a job that burns 0.5 s of CPU itself and 0.3 s in a child it waits for (as a system under
    test), and one that only sleeps 0.6 s; each job's `cpu_s` is measured in its own process around the job."""
    from support import jobs

    from bagfault.campaign.engines import LocalEngine

    results: dict[int, dict[str, Any]] = {}
    engine = LocalEngine(2, jobs.measured)
    try:
        engine.run([{'timeout': 60.0, 'cpu': 0.5, 'child_cpu': 0.3}, {'timeout': 60.0, 'sleep': 0.6}],
                   results.__setitem__)
    finally:
        engine.close()
    burning, sleeping = results[0], results[1]
    assert 0.8 <= burning['cpu_s'] < 0.8 + 0.3, burning  # the child's interpreter start adds a few hundredths
    assert sleeping['seconds'] >= 0.6 and sleeping['cpu_s'] < 0.1, sleeping


def test_a_job_finds_every_built_in_type_loaded_by_its_fork_server() -> None:
    """Types are imported when a scenario names them (bagfault/types_by_name.py); the fork server imports them
    all once, so no job pays for them. Expected: every module of injectors/ and assertions/ whose source
    declares a `type_name`."""
    from support import jobs

    from bagfault.campaign.engines import LocalEngine

    package = Path(__file__).resolve().parents[2] / 'bagfault'
    declaring = {f'bagfault.{folder}.{path.stem}' for folder in ('injectors', 'assertions')
                 for path in (package / folder).glob('*.py') if "type_name = '" in path.read_text()}
    results: dict[int, dict[str, Any]] = {}
    engine = LocalEngine(1, jobs.loaded_modules)
    try:
        engine.run([{'timeout': 60.0, 'prefix': 'bagfault.'}], results.__setitem__)
    finally:
        engine.close()
    loaded = set(results[0]['message'].split())
    assert len(declaring) >= 15
    assert declaring - loaded == set()
