"""A real multi-node Ray cluster on this machine (ray.cluster_utils.Cluster), every node on 127.0.0.1."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from typing import Any

import pytest

RAY_ENV = {
    'RAY_USAGE_STATS_ENABLED': '0',
    'RAY_AUTH_MODE': 'disabled',
    'RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER': '0',  # every node on 127.0.0.1, never the machine's address
    'RAY_health_check_period_ms': '500',  # a dead node is known in about a second, not thirty
    'RAY_health_check_timeout_ms': '500',
    'RAY_health_check_failure_threshold': '2',
}


def started_by_ray(start: Any, what: str = 'a Ray cluster') -> Any:
    """`start()` (Ray's own code starting nodes); when Ray itself fails to start them (a head that timed out on
    a machine loaded by two suites), the test is skipped saying so and why, never failed or silently passed.
    Only Ray's start is covered: what bagfault does with the cluster is judged by the test."""
    try:
        return start()
    except Exception as exc:  # Ray's start raises many kinds
        pytest.skip(f'Ray itself could not start {what} on this machine: {" ".join(str(exc).split())[:300]}')


def skip_if_ray_did_not_start(stderr: str) -> None:
    """After `bagfault campaign --ray` (a local instance) exited 2: skip when its one line says Ray itself could
    not start, with that line as the reason; any other error is the test's to judge."""
    if '--ray: cannot start or reach a local Ray instance' in stderr:
        pytest.skip(f'Ray itself could not start a local instance here: {stderr.strip()[-300:]}')


@contextlib.contextmanager
def local_cluster(monkeypatch: pytest.MonkeyPatch, workers: int = 1) -> Iterator[Any]:
    """A head and `workers` worker nodes of one CPU each; shut down on exit."""
    from ray._private import ray_constants
    from ray.cluster_utils import Cluster

    monkeypatch.setattr(ray_constants, 'ENABLE_RAY_CLUSTER', False)  # read at import: this process imported Ray
    for key, value in RAY_ENV.items():
        monkeypatch.setenv(key, value)
    cluster = started_by_ray(lambda: Cluster(initialize_head=True,
                                             head_node_args={'num_cpus': 1, 'include_dashboard': False}))
    try:
        for _ in range(workers):
            started_by_ray(lambda: cluster.add_node(num_cpus=1))
        started_by_ray(cluster.wait_for_nodes)
        assert cluster.address.startswith('127.0.0.1:'), cluster.address
        yield cluster
    finally:
        cluster.shutdown()
