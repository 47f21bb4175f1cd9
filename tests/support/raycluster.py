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


@contextlib.contextmanager
def local_cluster(monkeypatch: pytest.MonkeyPatch, workers: int = 1) -> Iterator[Any]:
    """A head and `workers` worker nodes of one CPU each; shut down on exit."""
    from ray._private import ray_constants
    from ray.cluster_utils import Cluster

    monkeypatch.setattr(ray_constants, 'ENABLE_RAY_CLUSTER', False)  # read at import: this process imported Ray
    for key, value in RAY_ENV.items():
        monkeypatch.setenv(key, value)
    cluster = Cluster(initialize_head=True, head_node_args={'num_cpus': 1, 'include_dashboard': False})
    try:
        for _ in range(workers):
            cluster.add_node(num_cpus=1)
        cluster.wait_for_nodes()
        assert cluster.address.startswith('127.0.0.1:'), cluster.address
        yield cluster
    finally:
        cluster.shutdown()
