"""Live tests: real separate processes on their own ROS_DOMAIN_ID, over the loopback discovery profile."""

from __future__ import annotations

import pytest
from support.livegraph import graph_fixture

graph = pytest.fixture(graph_fixture, name='graph')
