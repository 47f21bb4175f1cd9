"""Offline explore on two workers: the cores kept busy and the time, with and without runs ahead of a lone shrink.

    python bench/explore_offline.py [--seconds 60] [--budget 80] [--workers 2] [--repeat 3]
                                    [--json bench/results/explore-offline-DATE.json]

The test suite's offline space (tests/fixtures/scenarios/explore_space.yaml: three planted failures) on a
bag of --seconds (/imu at 50 Hz, /odom at 25 Hz, from bagfault.demo.synthetic), explored alternately with
runs ahead (as bagfault does) and without them (the reference: no round gets a run ahead), each in a
process of its own. Prints each exploration's wall seconds, the cores the machine kept busy meanwhile
(/proc/stat: every process, so only on a quiet machine is it the exploration's), the runs made and those
unused, and whether both found the same failures with the same minimal causes.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from datetime import date
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
SPACE = HERE.parent / 'tests' / 'fixtures' / 'scenarios' / 'explore_space.yaml'

ONE = """
import json, sys, time
from pathlib import Path
from bagfault import api
from bagfault.explore.explorer import Explorer
sys.path.insert(0, {bench!r})
from explore import busy_seconds
if not {ahead!r}:
    Explorer._ahead = lambda self, failure: []
busy, start = busy_seconds(), time.monotonic()
result = api.explore(Path({space!r}), directory=Path({out!r}), budget={budget!r}, workers={workers!r})
seconds = time.monotonic() - start
print(json.dumps({{'seconds': seconds, 'cores_busy': (busy_seconds() - busy) / seconds, 'runs': len(result.runs),
                  'unused': sum(f.unused_runs for f in result.failures),
                  'failures': sorted([sorted(f.assertions), f.minimal.describe() if f.minimal else None]
                                     for f in result.failures)}}))
"""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--seconds', type=float, default=60.0, help='bag length')
    parser.add_argument('--budget', type=int, default=80)
    parser.add_argument('--workers', type=int, default=2)
    parser.add_argument('--repeat', type=int, default=3, help='alternating pairs')
    parser.add_argument('--json', type=Path, default=None)
    args = parser.parse_args()
    sys.path.insert(0, str(HERE.parent))
    from bagfault.demo import synthetic

    load = os.getloadavg()[0]
    runs: dict[str, list[dict[str, Any]]] = {'ahead': [], 'reference': []}
    with tempfile.TemporaryDirectory(prefix='bagfault-explore-offline-') as scratch:
        folder = Path(scratch)
        streams = [synthetic.Stream('/imu', 'sensor_msgs/msg/Imu', 50.0),
                   synthetic.Stream('/odom', 'nav_msgs/msg/Odometry', 25.0)]
        synthetic.write_mcap(folder / 'explore_small.mcap', synthetic.messages(streams, args.seconds))
        (folder / 'space.yaml').write_text(SPACE.read_text())
        for repetition in range(args.repeat):
            for kind in ('ahead', 'reference'):
                code = ONE.format(bench=str(HERE), ahead=kind == 'ahead', space=str(folder / 'space.yaml'),
                                  out=str(folder / f'{kind}{repetition}'), budget=args.budget, workers=args.workers)
                done = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, check=True,
                                      cwd=HERE.parent)
                runs[kind].append(json.loads(done.stdout.splitlines()[-1]))
                row = runs[kind][-1]
                print(f'{kind:<10} {row["seconds"]:6.1f} s  {row["cores_busy"]:.2f} cores busy  {row["runs"]} runs, '
                      f'{row["unused"]} unused', flush=True)
    same = all(r['failures'] == runs['reference'][0]['failures'] for kind in runs for r in runs[kind])
    summary = {kind: {'median_seconds': statistics.median(r['seconds'] for r in rows),
                      'median_cores_busy': statistics.median(r['cores_busy'] for r in rows)}
               for kind, rows in runs.items()}
    print(f'load {load:.2f} before; medians: with runs ahead {summary["ahead"]["median_seconds"]:.1f} s, '
          f'{summary["ahead"]["median_cores_busy"]:.2f} cores; without {summary["reference"]["median_seconds"]:.1f} s, '
          f'{summary["reference"]["median_cores_busy"]:.2f} cores; the same failures and minimal causes: {same}')
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({'date': date.today().isoformat(), 'command': ' '.join(sys.argv),
                                         'load_before': load, 'summary': summary, 'same_failures': same,
                                         'runs': runs}, indent=1) + '\n')
        print(f'written {args.json}')


if __name__ == '__main__':
    main()
