"""Closed-loop tests: the example system of examples/closed_loop run for real by `bagfault test`."""

from __future__ import annotations

from pathlib import Path

import pytest
from support.loop import LoopRunner, rclpy_available, rover_bag


@pytest.fixture(scope='session')
def example_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The example's rover bag, written by its own make_bag.py."""
    return rover_bag(tmp_path_factory.mktemp('closed_loop') / 'rover.mcap')


@pytest.fixture
def tester(tmp_path: Path) -> LoopRunner:
    """`bagfault test` in a fresh process (skips without rclpy)."""
    if not rclpy_available():
        pytest.skip("rclpy not installed (pip install '.[live]')")
    return LoopRunner(tmp_path)
