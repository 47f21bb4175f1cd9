"""Campaigns over bags in a bucket: a local pool against 2- and 3-node Ray clusters on this machine.

    python bench/campaign_cluster.py [--bags 4] [--seconds 30] [--json bench/results/campaign_cluster.json]

A local S3 server (moto, on 127.0.0.1) holds the bags (synthetic rover logs as in bench/campaign.py); the
campaign is 48 jobs (bags x 12 IMU biases). Each engine starts with an empty object cache per node and runs
the same campaign file: the local pool (2 workers), then ray.cluster_utils clusters of 2 and 3 nodes (one CPU
each; this machine has 2 cores, so 3 nodes oversubscribe it) with each node's own cache. Reported: the jobs
phase (first job to last result), jobs per minute, and the cache hit rate (jobs that found their bag cached:
1 - downloads / jobs, downloads counted in the server's access log). Not a test: figures depend on the machine.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import socket
import subprocess
import sys
import tempfile
import time
from datetime import date
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from campaign import SCENARIO, STREAMS, clock_progress  # noqa: E402 - the same bags and scenario as bench/campaign.py

CAMPAIGN = """
campaign: bucket_bench
scenario: drift.yaml
bags: [s3://bench-fleet/routes/*.mcap]
sweep:
  faults.bias.config.angular_velocity_z_bias: [0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4, 0.45, 0.5, 0.55, 0.6]
keep: none
"""
RAY_ENV = {'RAY_USAGE_STATS_ENABLED': '0', 'RAY_AUTH_MODE': 'disabled', 'RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER': '0'}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--bags', type=int, default=4)
    parser.add_argument('--seconds', type=float, default=30.0)
    parser.add_argument('--json', type=Path, default=None)
    args = parser.parse_args()
    os.environ.update(RAY_ENV)
    with socket.socket() as probe:
        probe.bind(('127.0.0.1', 0))
        port = probe.getsockname()[1]
    folder = Path(tempfile.mkdtemp(prefix='bagfault-bucket-bench-'))
    log = folder / 'moto.log'
    server = subprocess.Popen([sys.executable, '-m', 'moto.server', '-H', '127.0.0.1', '-p', str(port)],
                              stdout=log.open('wb'), stderr=subprocess.STDOUT)
    try:
        time.sleep(2.0)
        os.environ.update(AWS_ENDPOINT_URL=f'http://127.0.0.1:{port}', AWS_ACCESS_KEY_ID='bench',
                          AWS_SECRET_ACCESS_KEY='bench', AWS_DEFAULT_REGION='us-east-1')
        return _run(args, folder, log)
    finally:
        server.terminate()
        server.wait(timeout=10)


def _run(args: argparse.Namespace, folder: Path, log: Path) -> int:
    import boto3
    from ray._private import ray_constants
    from ray.cluster_utils import Cluster

    from bagfault import api
    from bagfault.demo import synthetic

    ray_constants.ENABLE_RAY_CLUSTER = False  # every node on 127.0.0.1

    s3 = boto3.client('s3')
    s3.create_bucket(Bucket='bench-fleet')
    specs = [synthetic.Stream(t, m, r) for t, m, r in STREAMS]
    size = 0
    for k in range(args.bags):
        bag = folder / f'route{k}.mcap'
        synthetic.write_mcap(bag, synthetic.messages(specs, args.seconds, start=synthetic.DEFAULT_START + k * 10**12))
        size += bag.stat().st_size
        s3.upload_file(str(bag), 'bench-fleet', f'routes/{bag.name}')
    (folder / 'drift.yaml').write_text(SCENARIO)
    (folder / 'campaign.yaml').write_text(CAMPAIGN)

    def downloads() -> int:
        return len(re.findall(r'"GET /bench-fleet/routes/route\d+\.mcap HTTP', log.read_text(errors='replace')))

    runs = {}
    for name, nodes in (('local pool, 2 workers', 0), ('Ray, 2 nodes', 2), ('Ray, 3 nodes', 3)):
        os.environ['BAGFAULT_CACHE'] = str(folder / f'cache-{nodes}')
        cluster = None
        options: dict[str, object] = {'workers': 2}
        if nodes:
            cluster = Cluster(initialize_head=True, head_node_args={
                'num_cpus': 1, 'include_dashboard': False, 'env_vars': {'BAGFAULT_CACHE_NODE': 'head'}})
            for n in range(1, nodes):
                cluster.add_node(num_cpus=1, env_vars={'BAGFAULT_CACHE_NODE': f'node{n}'})
            cluster.wait_for_nodes()
            options = {'ray': cluster.address}
        before = downloads()
        clock = clock_progress()
        started = time.monotonic()
        try:
            result = api.campaign(folder / 'campaign.yaml', folder / f'out-{nodes}', progress=clock,
                                  **options)  # type: ignore[arg-type]
        finally:
            if cluster is not None:
                cluster.shutdown()
        seconds = time.monotonic() - started
        jobs = len(result.table.rows)
        phase = clock.last - (clock.first or started)
        fetched = downloads() - before
        runs[name] = {'jobs': jobs, 'seconds': round(seconds, 2), 'jobs_seconds': round(phase, 2),
                      'jobs_per_minute': round(60 * jobs / phase, 1), 'downloads': fetched,
                      'cache_hit_rate': round(1 - fetched / jobs, 3)}
        print(f'{name:22} {jobs} jobs, jobs phase {phase:6.1f} s: {60 * jobs / phase:6.1f} jobs/min, '
              f'{fetched} downloads, cache hit rate {1 - fetched / jobs:.0%}', flush=True)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({'date': date.today().isoformat(), 'bags': args.bags,
                                         'bag_seconds': args.seconds, 'bag_bytes': size, 'cores': os.cpu_count(),
                                         'load': os.getloadavg()[0], 'runs': runs}, indent=1) + '\n')
    return 0


if __name__ == '__main__':
    sys.exit(main())
