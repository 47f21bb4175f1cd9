"""A private ROS graph for a test: real separate processes on their own ROS_DOMAIN_ID, over the loopback
discovery profile (the `graph` fixture of tests/live and tests/view)."""

from __future__ import annotations

import itertools
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import bagfault.live
from bagfault.closedloop.domain import DomainLease

PEERS = Path(__file__).resolve().parents[1] / 'live' / 'peers.py'
ROOT = Path(__file__).resolve().parents[2]


def rclpy_available() -> bool:
    try:
        import rclpy  # noqa: F401
    except ImportError:
        return False
    return True


class Graph:
    """Processes of one test, on one ROS domain; all stopped at the end."""

    def __init__(self, tmp: Path) -> None:
        self.tmp = tmp
        self.lease = DomainLease()  # the same leases as `bagfault test`: no two graphs share a domain
        self.domain = self.lease.domain
        self.env = {**os.environ, 'ROS_DOMAIN_ID': str(self.domain),
                    'FASTRTPS_DEFAULT_PROFILES_FILE': str(bagfault.live.LOOPBACK_PROFILE),
                    'RCUTILS_COLORIZED_OUTPUT': '0', 'PYTHONUNBUFFERED': '1',
                    'PYTHONPATH': os.pathsep.join(filter(None, [str(ROOT), os.environ.get('PYTHONPATH')]))}
        self.processes: list[subprocess.Popen[str]] = []
        self._names = itertools.count()

    def start(self, *args: str, name: str = 'proc') -> subprocess.Popen[str]:
        """Start a process; its stdout and stderr go to files named after it."""
        number = next(self._names)
        out = (self.tmp / f'{number}-{name}.out').open('w')
        err = (self.tmp / f'{number}-{name}.err').open('w')
        process = subprocess.Popen([sys.executable, *args], env=self.env, stdout=out, stderr=err, text=True,
                                   cwd=self.tmp)
        process.out_path, process.err_path = Path(out.name), Path(err.name)  # type: ignore[attr-defined]
        self.processes.append(process)
        return process

    def peer(self, *args: str, name: str = 'peer') -> subprocess.Popen[str]:
        """A helper process from peers.py."""
        return self.start(str(PEERS), *args, name=name)

    def bagfault(self, *args: str, name: str = 'bagfault') -> subprocess.Popen[str]:
        """The bagfault command line."""
        return self.start('-m', 'bagfault.cli', *args, name=name)

    def call(self, *args: str, timeout: float = 60.0) -> dict[str, Any]:
        """Run a peer to completion; its last JSON line."""
        process = self.peer(*args, name=args[0])
        process.wait(timeout=timeout)
        lines = process.out_path.read_text().splitlines()  # type: ignore[attr-defined]
        assert lines, process.err_path.read_text()  # type: ignore[attr-defined]
        return json.loads(lines[-1])

    @staticmethod
    def wait_for(process: subprocess.Popen[str], text: str, timeout: float = 30.0) -> None:
        """Wait until the process wrote `text` on stderr."""
        deadline = time.monotonic() + timeout
        path: Path = process.err_path  # type: ignore[attr-defined]
        while time.monotonic() < deadline:
            if text in path.read_text():
                return
            if process.poll() is not None:
                break
            time.sleep(0.05)
        raise AssertionError(f'{text!r} not seen; stderr:\n{path.read_text()}')

    @classmethod
    def wait_for_line(cls, process: subprocess.Popen[str], timeout: float = 30.0) -> None:
        """Wait until a peer printed its first JSON line (an echo received a message)."""
        deadline = time.monotonic() + timeout
        while not cls.lines(process):
            if time.monotonic() > deadline or process.poll() is not None:
                raise AssertionError(f'no line from the peer; stderr:\n{process.err_path.read_text()}')  # type: ignore[attr-defined]
            time.sleep(0.02)

    def burst_past_a_stopped_listener(self, listener: subprocess.Popen[str], topic: str) -> int:
        """A best-effort burst on `topic` (50 kHz for 3 s) while `listener` stands still (SIGSTOP for 2 s after
        it took the first message): more than it can take on any machine; then 20 messages at 20 Hz, which it
        hears however busy the machine (a loss is seen at the next message heard: one at the burst's end, on a
        loaded machine, had none after it). How many the publisher sent."""
        publisher = self.peer('publish-imu', topic, '--rate', '50000', '--seconds', '3', '--best-effort',
                              '--wait-subscriber', '--pause-after-first', '1', '--tail', '20', name='burst')
        self.wait_for(publisher, 'first sent')
        time.sleep(0.5)  # the listener takes the first message; then it stands still while the burst goes by
        listener.send_signal(signal.SIGSTOP)
        time.sleep(2.0)
        listener.send_signal(signal.SIGCONT)
        publisher.wait(timeout=60)
        return int(self.lines(publisher)[-1]['published'])

    @staticmethod
    def stop(process: subprocess.Popen[str], sig: int = signal.SIGINT, timeout: float = 30.0) -> int:
        """Signal a process and wait for its exit code."""
        process.send_signal(sig)
        return process.wait(timeout=timeout)

    @staticmethod
    def lines(process: subprocess.Popen[str]) -> list[dict[str, Any]]:
        """JSON lines a peer printed."""
        path: Path = process.out_path  # type: ignore[attr-defined]
        return [json.loads(line) for line in path.read_text().splitlines() if line.startswith('{')]

    def close(self) -> None:
        for process in self.processes:
            if process.poll() is None:
                process.kill()
                process.wait(timeout=10)
        self.lease.release()




def graph_fixture(tmp_path: Path) -> Any:
    """A Graph for one test, closed after it (skips without rclpy)."""
    import pytest

    if not rclpy_available():
        pytest.skip("rclpy not installed (pip install '.[live]')")
    instance = Graph(tmp_path)
    yield instance
    instance.close()
