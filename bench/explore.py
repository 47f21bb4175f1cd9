"""bagfault explore against planted bugs: found within the budget, shrunk to the known minimum, replays that fail.

    python bench/explore.py [--space bench/explore/space.yaml] [--bugs bench/explore/bugs.yaml]
                            [--budget 700] [--rate 4] [--workers 2] [--replays 20]
                            [--compare | --only 0 1 2] [--resume] [--json bench/results/explore-DATE.json]

Runs `bagfault explore` (Python API) on the space, then compares each planted bug of the bugs file (its
failing assertions, its minimal faults and the threshold of each dimension listed) with the failures found:

- found: a failure with exactly the bug's assertions; `search runs` is how many search runs were made until
  its first failing run (the target: every bug within 300);
- shrunk to the known minimum: the same faults, and each listed dimension within the space's resolution (1 %
  of its range, plus the bug's `slack` for a time threshold that moves with the sample grid) of its value;
- shrink runs: confirmations, steps and the replay (target: median at most 40);
- replays: the minimal scenario, as written, run --replays times with `bagfault test`: how many fail the same
  way (target: all).

--compare runs the same budget again twice: uniform draws and no margins (search='uniform', shrink='halving':
no refinement of near misses, no guesses from margins while shrinking), and ddmin over the fault set without
shrinking dimensions (shrink='faults'); --only picks some of the three. Another space and bugs file (another
system) run the same way. Prints a table and writes JSON with the date, the command and the load.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from datetime import date
from pathlib import Path
from typing import Any

import yaml

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))


def explore(space: Path, out: Path, args: argparse.Namespace, **options: Any) -> tuple[Any, float, float]:
    """The exploration's result, its wall seconds and the cores the machine kept busy meanwhile (every process:
    bagfault's and the systems under test; on an otherwise quiet machine, the exploration's)."""
    from bagfault import api
    from bagfault.progress import ExploreProgress

    busy = busy_seconds()
    began = time.monotonic()
    result = api.explore(space, directory=out, budget=args.budget, workers=args.workers, rate=args.rate,
                         seed=args.seed, force=True, progress=ExploreProgress(enabled=sys.stderr.isatty()),
                         resume=args.resume and (out / 'runs.jsonl').exists(), **options)
    seconds = time.monotonic() - began
    return result, seconds, (busy_seconds() - busy) / seconds


def busy_seconds() -> float:
    """CPU seconds the machine has spent on anything but idling (/proc/stat, every core)."""
    fields = [int(x) for x in Path('/proc/stat').read_text().split('\n', 1)[0].split()[1:]]
    return (sum(fields[:8]) - fields[3] - fields[4]) / os.sysconf('SC_CLK_TCK')  # idle and iowait left out


def dimension_ranges(space: Path) -> dict[tuple[str, str], tuple[float, float]]:
    from bagfault.scenario import load_scenario

    explore = load_scenario(space).explore
    assert explore is not None
    return {(f.id, d.name): (d.low, d.high) for f in explore.faults for d in f.dimensions}


def judge(result: Any, bugs: list[dict[str, Any]], ranges: dict[tuple[str, str], tuple[float, float]],
          resolution: float) -> list[dict[str, Any]]:
    """Each bug: found, when, shrunk to its minimum (and what is off), shrink runs."""
    rows = []
    by_set = {f.assertions: f for f in result.failures}
    for bug in bugs:
        failure = by_set.get(frozenset(bug['fails']))
        row: dict[str, Any] = {'bug': bug['id'], 'fails': sorted(bug['fails']), 'found': failure is not None}
        if failure is None:
            rows.append(row)
            continue
        row.update(failure=failure.name, search_runs=failure.search_runs, found_at_run=failure.found_at_run,
                   shrink_runs=failure.shrink_runs, state=failure.state, note=failure.note,
                   minimal=failure.minimal.describe() if failure.minimal else None)
        minimal = failure.minimal
        offs = [_off(minimal, known, bug.get('slack', {}), ranges, resolution)
                for known in [bug['minimum'], *bug.get('alternatives', [])]]
        row['shrunk_to_known'] = any(not off for off in offs)
        row['off'] = [] if row['shrunk_to_known'] else min(offs, key=len)
        rows.append(row)
    return rows


def _off(minimal: Any, known: dict[str, dict[str, float]], slack: dict[str, float],
         ranges: dict[tuple[str, str], tuple[float, float]], resolution: float) -> list[str]:
    """What of a minimal candidate differs from one known minimal cause (nothing: it is that cause)."""
    if minimal is None or set(minimal.ids) != set(known):
        return [f'faults {list(minimal.ids) if minimal else None}, not {sorted(known)}']
    off = []
    for fault, dims in known.items():
        values = dict(minimal.drawn(fault).values)
        for name, expected in dims.items():
            low, high = ranges[(fault, name)]
            tolerance = resolution * (high - low) + slack.get(name, 0.0) + 1e-9
            if abs(values[name] - expected) > tolerance:
                off.append(f'{fault}.{name} = {values[name]:g}, the threshold is {expected:g} (+- {tolerance:.3g})')
    return off


def replay(result: Any, rows: list[dict[str, Any]], times: int, args: argparse.Namespace) -> None:
    """Each found bug's minimal scenario run `times` times as `bagfault test` does: how many fail its way."""
    from bagfault.api import job
    from bagfault.campaign.engines import LocalEngine

    specs, owners = [], []
    for row in rows:
        if not row.get('failure'):
            continue
        minimal = result.directory / 'failures' / f'{row["failure"]}.min.yaml'
        scenario = yaml.safe_load(minimal.read_text())
        bags = [str((minimal.parent / b).resolve()) for b in scenario['bags']]
        for _ in range(times):
            specs.append({'mode': result.mode, 'scenario_text': minimal.read_text(),
                          'scenario_source': str(minimal.resolve()), 'bag': bags[0], 'bags': bags,
                          'seed': result.seed, 'remote': None, 'digests': [], 'output': None, 'timeout': 1800.0,
                          'rate': args.rate})
            owners.append(row)
    for row in rows:
        row['replays_failed'] = 0
        row['replays'] = times if row.get('failure') else 0
    failing: dict[int, Any] = {}

    def done(index: int, outcome: dict[str, Any]) -> None:
        failing[index] = {k for k, a in (outcome.get('assertions') or {}).items() if a.get('state') != 'passed'}

    engine = LocalEngine(args.workers, job)
    try:
        engine.run(specs, done)
    finally:
        engine.close()
    for index, row in enumerate(owners):
        row['replays_failed'] += failing.get(index) == set(row['fails'])


def summary(name: str, rows: list[dict[str, Any]], result: Any, seconds: float, cores: float) -> dict[str, Any]:
    found = [r for r in rows if r['found']]
    shrinks = [r['shrink_runs'] for r in found]
    known = [r for r in found if r.get('shrunk_to_known')]
    out = {'strategy': name, 'bugs': len(rows), 'found': len(found), 'shrunk_to_known': len(known),
           'max_search_runs_to_find': max((r['search_runs'] for r in found), default=None),
           'median_shrink_runs': statistics.median(shrinks) if shrinks else None,
           'runs': len(result.runs), 'failures': len(result.failures), 'seconds': round(seconds, 1),
           'cores_busy': round(cores, 2),
           'load_after': round(os.getloadavg()[0], 2), 'rows': rows}
    print(f'\n== {name}: {out["found"]}/{out["bugs"]} bugs found (the last after {out["max_search_runs_to_find"]} '
          f'search runs), {out["shrunk_to_known"]} shrunk to the known minimum, median {out["median_shrink_runs"]} '
          f'runs per shrink; {out["runs"]} runs, {out["failures"]} failures, {seconds:.0f} s, {cores:.2f} cores busy, '
          f'load {out["load_after"]}')
    for r in rows:
        if not r['found']:
            print(f'   {r["bug"]:24} NOT FOUND')
            continue
        replays = f', replays {r["replays_failed"]}/{r["replays"]} failed' if 'replays' in r else ''
        print(f'   {r["bug"]:24} search runs {r["search_runs"]:4}  shrink runs {r["shrink_runs"]:3}  '
              f'{"minimum" if r["shrunk_to_known"] else "OFF: " + "; ".join(r["off"])}{replays}')
        print(f'   {"":24} {r["minimal"]}')
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--space', type=Path, default=HERE / 'explore' / 'space.yaml')
    parser.add_argument('--bugs', type=Path, default=HERE / 'explore' / 'bugs.yaml')
    parser.add_argument('--budget', type=int, default=700)
    parser.add_argument('--rate', type=float, default=4.0)
    parser.add_argument('--workers', type=int, default=2)
    parser.add_argument('--seed', type=int, default=None)
    parser.add_argument('--replays', type=int, default=20)
    parser.add_argument('--compare', action='store_true', help='also uniform draws and ddmin only')
    parser.add_argument('--resume', action='store_true', help='continue the explorations found in --out')
    parser.add_argument('--only', type=int, nargs='+', choices=(0, 1, 2),
                        help='0 guided (with the replays), 1 uniform without margins, 2 ddmin only')
    parser.add_argument('--out', type=Path, default=HERE / 'data' / 'explore')
    parser.add_argument('--json', type=Path, default=HERE / 'results' / f'explore-{date.today()}.json')
    args = parser.parse_args()
    maker = args.space.parent / 'make_bag.py'
    if maker.exists():
        subprocess.run([sys.executable, str(maker)], check=True, capture_output=True)
    bugs = yaml.safe_load(args.bugs.read_text())['bugs']
    ranges = dimension_ranges(args.space)
    from bagfault.scenario import load_scenario

    resolution = load_scenario(args.space).explore.resolution  # type: ignore[union-attr]
    report: dict[str, Any] = {'date': str(date.today()), 'command': ' '.join(sys.argv), 'space': str(args.space),
                              'budget': args.budget, 'rate': args.rate, 'workers': args.workers,
                              'load_before': round(os.getloadavg()[0], 2), 'strategies': []}
    strategies = [('guided search, margins, full shrink', {}),
                  ('uniform draws, no margins', {'search': 'uniform', 'shrink': 'halving'}),
                  ('ddmin only', {'shrink': 'faults'})]
    chosen = args.only if args.only else [0, 1, 2] if args.compare else [0]
    for number, (name, options) in enumerate(strategies):
        if number not in chosen:
            continue
        result, seconds, cores = explore(args.space, args.out / f'run{number}', args, **options)
        rows = judge(result, bugs, ranges, resolution)
        if number == 0 and args.replays:
            replay(result, rows, args.replays, args)
        report['strategies'].append(summary(name, rows, result, seconds, cores))
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(report, indent=1) + '\n')
    print(f'\nwritten {args.json}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
