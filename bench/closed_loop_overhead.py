"""Where the time of a closed-loop run goes beyond the bag: `bagfault test` on the closed-loop example.

    python bench/closed_loop_overhead.py [--repeat 3] [--json bench/results/closed-loop-overhead.json]

Runs the example of examples/closed_loop (its 12 s rover bag, the monitor.py
system under test) through `api.test` in this process, `--repeat` times, with
a clock on the phases (the link's methods wrapped, nothing else changed):
domain lease and system start, the system's start until ready, ready until
the first message is played, the bag, the tail, stopping the system and
completing the recording. Overhead is everything but the bag's 12 s.
Needs rclpy (the `live` extra). Not a test: numbers depend on the machine.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from datetime import date
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
EXAMPLE = ROOT / 'examples' / 'closed_loop'
sys.path.insert(0, str(ROOT))


def one_run(folder: Path) -> dict[str, float]:
    """One `api.test` of the example; seconds of each phase."""
    from bagfault import api
    from bagfault.closedloop import link as link_module
    from bagfault.closedloop import process as process_module

    marks: dict[str, float] = {}
    cls = link_module.SystemLink
    originals = (cls.prepare, cls.gate, cls.finish, process_module.SystemProcess.stop)

    def prepare(self: Any, routing: Any) -> Any:
        marks.setdefault('prepare', time.monotonic())
        try:
            return originals[0](self, routing)
        finally:
            marks['ready'] = marks['prepare'] + self.ready_seconds

    def gate(self: Any, bag_time: int) -> None:
        originals[1](self, bag_time)
        marks.setdefault('first message', time.monotonic())
        marks['last message'] = time.monotonic()

    def finish(self: Any, run: Any) -> None:
        originals[2](self, run)
        marks['tail ended'] = time.monotonic()

    def stop(self: Any, timeout: float) -> Any:
        marks.setdefault('stop', time.monotonic())
        try:
            return originals[3](self, timeout)
        finally:
            marks['stopped'] = time.monotonic()

    cls.prepare, cls.gate, cls.finish = prepare, gate, finish  # type: ignore[method-assign]
    process_module.SystemProcess.stop = stop  # type: ignore[method-assign]
    try:
        started = time.monotonic()
        result = api.test(EXAMPLE / 'test_imu_drift.bagfault.yaml', [folder / 'rover.mcap'], folder / 'loop.mcap',
                          force=True)
        ended = time.monotonic()
    finally:
        cls.prepare, cls.gate, cls.finish = originals[:3]  # type: ignore[method-assign]
        process_module.SystemProcess.stop = originals[3]  # type: ignore[method-assign]
    if result.failed:
        raise SystemExit(f'the example failed: {[a.message for a in result.assertions if a.state != "passed"]}')
    return {
        'lease and start': marks['prepare'] - started,
        'start until ready': marks['ready'] - marks['prepare'],
        'ready until first message': marks['first message'] - marks['ready'],
        'bag (first to last message)': marks['last message'] - marks['first message'],
        'tail': marks['tail ended'] - marks['last message'],
        'stop the system': marks['stopped'] - marks['stop'],
        'the rest (verdicts, recording)': ended - marks['tail ended'] - (marks['stopped'] - marks['stop']),
        'total': ended - started,
        'overhead (total - 12 s)': ended - started - 12.0,
    }


def main() -> int:
    """Make the example's bag, run it `--repeat` times, print medians per phase."""
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--repeat', type=int, default=3)
    parser.add_argument('--json', type=Path, default=None)
    args = parser.parse_args()
    runs = []
    with tempfile.TemporaryDirectory() as scratch:
        folder = Path(scratch)
        subprocess.run([sys.executable, str(EXAMPLE / 'make_bag.py'), str(folder / 'rover.mcap')], check=True,
                       stdout=subprocess.DEVNULL)
        for _ in range(args.repeat):
            runs.append(one_run(folder))
    phases = {name: round(statistics.median(r[name] for r in runs), 3) for name in runs[0]}
    report = {'date': date.today().isoformat(), 'load': os.getloadavg()[0], 'repeat': args.repeat,
              'median_seconds': phases, 'runs': runs}
    for name, seconds in phases.items():
        print(f'  {name:<34}{seconds:>8.2f} s')
    path = args.json or HERE / 'results' / f'closed-loop-overhead-{report["date"]}.json'
    path.write_text(json.dumps(report, indent=1, sort_keys=True) + '\n')
    print(f'results written to {path}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
