"""Helpers of the closed-loop tests: `bagfault test` started as a user starts it, processes found by token."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / 'examples' / 'closed_loop'
SCENARIO = EXAMPLE / 'test_imu_drift.bagfault.yaml'


def rover_bag(path: Path, duration: float = 12.0) -> Path:
    """The closed-loop example's rover bag at `path`, written by its own make_bag.py (`duration` seconds)."""
    sys.path.insert(0, str(EXAMPLE))
    try:
        import make_bag
    finally:
        sys.path.remove(str(EXAMPLE))
    return Path(make_bag.write(path, duration=duration))


def rclpy_available() -> bool:
    try:
        import rclpy  # noqa: F401
    except ImportError:
        return False
    return True


@dataclass
class Outcome:
    """A finished `bagfault test`."""

    code: int
    stdout: str
    stderr: str
    seconds: float
    report: dict[str, Any] | None


def running_with(token: str) -> list[int]:
    """Processes whose command line holds `token`."""
    found = []
    for entry in Path('/proc').iterdir():
        if entry.name.isdigit():
            try:
                cmdline = (entry / 'cmdline').read_bytes()
                state = (entry / 'stat').read_text().rsplit(')', 1)[1].split()[0]
            except OSError:
                continue
            if token.encode() in cmdline and state != 'Z':
                found.append(int(entry.name))
    return found


class LoopRunner:
    """Starts `bagfault test` as a user would, in a fresh process."""

    def __init__(self, tmp: Path) -> None:
        self.tmp = tmp
        self.env = {**os.environ, 'PYTHONPATH': os.pathsep.join(filter(None, [str(ROOT), os.environ.get('PYTHONPATH')]))}
        self.env.pop('FASTRTPS_DEFAULT_PROFILES_FILE', None)  # bagfault test brings its own

    @staticmethod
    def token() -> str:
        return 'tok' + uuid.uuid4().hex[:12]

    def start(self, *args: str, name: str = 'test') -> tuple[subprocess.Popen[str], Path]:
        report = self.tmp / f'{name}.json'
        process = subprocess.Popen([sys.executable, '-m', 'bagfault.cli', 'test', *args, '--json', str(report)],
                                   env=self.env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                   cwd=self.tmp)
        return process, report

    def finish(self, process: subprocess.Popen[str], report: Path, timeout: float = 120.0) -> Outcome:
        import time

        began = time.monotonic()
        out, err = process.communicate(timeout=timeout)
        loaded = json.loads(report.read_text()) if report.exists() else None
        return Outcome(process.returncode, out, err, time.monotonic() - began, loaded)

    def run(self, *args: str, name: str = 'test') -> Outcome:
        import time

        began = time.monotonic()
        outcome = self.finish(*self.start(*args, name=name))
        outcome.seconds = time.monotonic() - began
        return outcome


# a system that publishes /temperature on a 10 Hz wall-clock timer, stamped with the wall clock
WALL_CLOCK_SYSTEM = """
import sys
import time
import rclpy
from rclpy.clock import Clock, ClockType
from rclpy.executors import ExternalShutdownException
from sensor_msgs.msg import Imu, Temperature

rclpy.init(args=sys.argv)
node = rclpy.create_node('wall_clock_status')
publisher = node.create_publisher(Temperature, '/temperature', 10)
node.create_subscription(Imu, '/imu', lambda message: None, 10)


def tick():
    message = Temperature()
    message.header.stamp.sec, message.header.stamp.nanosec = divmod(time.time_ns(), 1_000_000_000)
    publisher.publish(message)


node.create_timer(0.1, tick, clock=Clock(clock_type=ClockType.STEADY_TIME))  # wall time, whatever use_sim_time says
try:
    rclpy.spin(node)
except (KeyboardInterrupt, ExternalShutdownException):
    pass
"""
