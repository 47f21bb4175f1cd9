"""Shared fixtures: paths of generated and third-party bags, output readers."""

from __future__ import annotations

import os
import signal
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
# the suite's caches (kept input digests, downloaded bags) in a folder of its own, not the user's ~/.cache
os.environ['XDG_CACHE_HOME'] = str(Path(tempfile.gettempdir()) / 'bagfault-test-cache')
os.environ.pop('BAGFAULT_CACHE', None)

from support.helpers import ANCHORS, EXTERNAL, FIXTURES, need

pytest_plugins = ['pytester']

LIVE_FIXTURES = frozenset({'graph', 'tester', 'live_env'})  # each starts real rclpy processes on a leased domain


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """`live` on every test that starts a ROS graph (by its fixtures, or marked in its module), `closed_loop` on
    those of bagfault test, `campaign` on those under tests/campaign: `pytest -m "not live"` runs without ROS."""
    for item in items:
        fixtures = set(getattr(item, 'fixturenames', ()))
        if fixtures & LIVE_FIXTURES:
            item.add_marker(pytest.mark.live)
        if 'tester' in fixtures:
            item.add_marker(pytest.mark.closed_loop)
        if item.path.parent.name == 'campaign':
            item.add_marker(pytest.mark.campaign)


@pytest.fixture(autouse=True)
def _sigint_as_found() -> Iterator[None]:
    """Every test leaves SIGINT's handler and this thread's signal mask as it found them: a worker left with SIGINT
    ignored or blocked passes that on to every process a later test starts (seen: a stopped `bagfault explore`
    that heard no SIGINT, in full suites beside another). The test that changed it fails, saying so."""
    before = (signal.getsignal(signal.SIGINT), signal.pthread_sigmask(signal.SIG_BLOCK, []))
    yield
    after = (signal.getsignal(signal.SIGINT), signal.pthread_sigmask(signal.SIG_BLOCK, []))
    if after != before:
        signal.signal(signal.SIGINT, before[0])
        signal.pthread_sigmask(signal.SIG_SETMASK, before[1])
        pytest.fail(f'this test left SIGINT handled by {after[0]!r} with the mask {sorted(after[1])} (it found '
                    f'{before[0]!r}, {sorted(before[1])}); restored', pytrace=False)


@pytest.fixture
def rover_bag() -> Path:
    """20 s MCAP with the multi-injector scenario's raw topics."""
    return FIXTURES / 'rover_20s.mcap'


@pytest.fixture
def rover_sqlite() -> Path:
    """3 s rosbag2 sqlite3 directory with the same streams."""
    return FIXTURES / 'rover_3s_sqlite3'


@pytest.fixture(scope='session')
def scenarios() -> Path:
    """bagfault's own scenario files, one per layout of ros2_fault_injection (tests/fixtures/scenarios)."""
    return FIXTURES / 'scenarios'


@pytest.fixture(scope='session')
def anchors() -> Path:
    """Folder of the anchor's scenario files."""
    return need(ANCHORS)


@pytest.fixture(scope='session')
def external() -> Path:
    """Folder of third-party bags."""
    return need(EXTERNAL)


@pytest.fixture(scope='session')
def quirks_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """6 s MCAP with a real robot bag's quirks: its own /clock, an undefined type, a best-effort /imu, a topic
    without a leading slash (tests/fixtures/quirks.py)."""
    sys.path.insert(0, str(FIXTURES))
    try:
        import quirks
    finally:
        sys.path.remove(str(FIXTURES))
    return quirks.write(tmp_path_factory.mktemp('quirks') / 'quirks.mcap')
