#!/usr/bin/env python3
"""Check each planted bug of rover_stack.py by hand: its trigger fails with exactly its assertions, and each
weaker variant (just below one threshold) passes, through `bagfault test` as a user runs it.

    python bench/explore/check_bugs.py [--rate 1 4] [--hogs 0 2] [--only B3] [--json OUT]

Every combination of --rate and --hogs runs every case (hogs: that many `while True: pass` processes
beside the runs, one per core on this 2-core machine). Exit 0 when every case behaved as bugs.yaml says.
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import yaml

HERE = Path(__file__).resolve().parent
BAGFAULT = [sys.executable, '-m', 'bagfault']


def base_scenario() -> dict[str, Any]:
    """space.yaml without its explore section, paths made absolute (the cases are written elsewhere)."""
    data = yaml.safe_load((HERE / 'space.yaml').read_text())
    data.pop('explore')
    data['bags'] = [str(HERE / bag) for bag in data['bags']]
    data['system_under_test']['cwd'] = str(HERE)
    return data


def cases(only: str | None) -> list[tuple[str, str, list[dict[str, Any]], set[str]]]:
    """(bug, case name, faults, failing assertions expected) of every bug."""
    out = []
    for bug in yaml.safe_load((HERE / 'bugs.yaml').read_text())['bugs']:
        if only and not bug['id'].startswith(only):
            continue
        out.append((bug['id'], 'trigger', bug['trigger'], set(bug['fails'])))
        out += [(bug['id'], f'weaker {n}', faults, set()) for n, faults in enumerate(bug['weaker'], 1)]
    return out


def run_case(folder: Path, name: str, faults: list[dict[str, Any]], rate: float) -> tuple[set[str], int, str]:
    """The failing assertions of one `bagfault test` and its exit code."""
    scenario = {**base_scenario(), 'name': name, 'faults': faults}
    path = folder / f'{name}.yaml'
    path.write_text(yaml.safe_dump(scenario, sort_keys=False))
    report = folder / f'{name}.json'
    done = subprocess.run([*BAGFAULT, 'test', str(path), '--rate', str(rate), '--json', str(report), '--force'],
                          capture_output=True, text=True, check=False)
    if done.returncode == 2 or not report.exists():
        return set(), done.returncode, done.stderr.strip().splitlines()[-1] if done.stderr.strip() else ''
    assertions = json.loads(report.read_text())['assertions']
    return {a['id'] for a in assertions if a['state'] != 'passed'}, done.returncode, ''


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--rate', type=float, nargs='+', default=[1.0, 4.0])
    parser.add_argument('--hogs', type=int, nargs='+', default=[0, 2])
    parser.add_argument('--only', help='the bugs whose id starts so')
    parser.add_argument('--json', type=Path, help='write every case and its outcome here')
    args = parser.parse_args()
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))  # the hogs are stopped (finally) on a kill too
    if not (HERE / 'rover_bench.mcap').exists():
        subprocess.run([sys.executable, str(HERE / 'make_bag.py')], check=True)
    rows, wrong = [], 0
    with tempfile.TemporaryDirectory(prefix='bagfault-bugs-') as scratch:
        for rate, hogs in itertools.product(args.rate, args.hogs):
            burners = [subprocess.Popen([sys.executable, '-c', 'while True: pass']) for _ in range(hogs)]
            try:
                for bug, case, faults, expected in cases(args.only):
                    began = time.monotonic()
                    name = f'{bug}-{case.replace(" ", "")}-r{rate:g}-h{hogs}'
                    failed, code, error = run_case(Path(scratch), name, faults, rate)
                    right = not error and failed == expected
                    wrong += not right
                    rows.append({'bug': bug, 'case': case, 'rate': rate, 'hogs': hogs, 'expected': sorted(expected),
                                 'failed': sorted(failed), 'exit': code, 'error': error, 'right': right,
                                 'seconds': round(time.monotonic() - began, 1), 'load': os.getloadavg()[0]})
                    print(f'{"ok " if right else "BAD"} {bug:24} {case:9} rate {rate:g} hogs {hogs}: failed '
                          f'{sorted(failed) or "nothing"}{" (" + error + ")" if error else ""}', flush=True)
                    if args.json:  # every case as it is decided: a stopped check keeps what it found
                        args.json.write_text(json.dumps({'date': time.strftime('%Y-%m-%d'), 'cases': rows},
                                                        indent=1) + '\n')
            finally:
                for burner in burners:
                    burner.kill()
                    burner.wait()
    print(f'{len(rows) - wrong} of {len(rows)} cases as bugs.yaml says')
    if args.json:
        args.json.write_text(json.dumps({'date': time.strftime('%Y-%m-%d'), 'cases': rows}, indent=1) + '\n')
    return 1 if wrong else 0


if __name__ == '__main__':
    sys.exit(main())
