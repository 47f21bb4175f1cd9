"""View tests: the Foxglove client against play (no ROS) and proxy (a private ROS graph)."""

from __future__ import annotations

import pytest
from support.livegraph import graph_fixture

graph = pytest.fixture(graph_fixture, name='graph')
