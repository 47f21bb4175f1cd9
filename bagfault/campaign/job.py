"""One job: the scenario's run (or closed-loop test) on one bag with one seed, as a plain result dict.

The engines call it in a process of its own per job, through the API
(`bagfault.api.job`, which hands it the API's `run` and `test`, so the
campaign never imports the API): a crash, a hang or a
leak of one job never touches the others (the engine kills it at its
timeout), and every job starts from the same fresh state, so results do not
depend on which worker ran what.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

from bagfault.units import NS

if TYPE_CHECKING:
    from collections.abc import Callable

    from bagfault.engine.result import RunResult


@contextlib.contextmanager
def _local(spec: dict[str, Any]) -> Iterator[str]:
    """The job's bag on local disk: as given, or a bucket's bag from this machine's cache (fetched once); the
    digests known of its files (hashed by the plan, or when the cache got them) are not computed again."""
    from bagfault.io.sources import remember_digests  # noqa: PLC0415

    remember_digests({tuple(item[:5]): item[5] for item in spec.get('digests') or []})
    if not spec.get('remote'):
        yield spec['bag']
        return
    from bagfault.io.objects import RemoteBag, fetched  # noqa: PLC0415

    with fetched(RemoteBag.from_dict(spec['remote'])) as bag:
        remember_digests(bag.digests)
        yield str(bag.path)


def _run(spec: dict[str, Any], output: Path | None, run: Callable[..., RunResult],
         test: Callable[..., RunResult]) -> RunResult:
    """The job's scenario run on its bag (staged here from a bucket, if it is in one) by `run` or `test`."""
    from bagfault.scenario import parse_scenario  # noqa: PLC0415

    scenario = parse_scenario(spec['scenario_text'], source=Path(spec['scenario_source']))
    with _local(spec) as bag:
        bags = spec.get('bags') or [bag]  # an exploration's run plays every bag given, as `run` and `test` do
        if spec['mode'] == 'test':
            return test(scenario, bags, output, seed=spec['seed'], rate=spec.get('rate', 1.0),
                        clock_check=spec.get('clock_check', True))
        assert output is not None
        return run(scenario, bags, output, seed=spec['seed'])


def _assertions(result: RunResult) -> dict[str, dict[str, Any]]:
    """Each assertion's state, message, value and margin, and when it was decided (seconds from time zero)."""
    origin = result.stats.origin
    return {a.id: {'state': a.state, 'message': a.message, 'value': a.value, 'unit': a.unit,
                   'margin': a.margin, 'margin_unit': a.margin_unit,
                   't_s': None if a.time is None or origin is None else round((a.time - origin) / NS, 9)}
            for a in result.assertions}


def _detections(result: RunResult) -> dict[str, float]:
    """Each fault code the fault manager confirmed, with the time of its first confirmation."""
    detections: dict[str, float] = {}
    for event in (result.fault_manager or {}).get('events', []):
        if event.get('status') == 'CONFIRMED' and event.get('fault_code') not in detections:
            detections[event['fault_code']] = event.get('t_s')
    return detections


def run_job(spec: dict[str, Any], run: Callable[..., RunResult], test: Callable[..., RunResult]) -> dict[str, Any]:
    """Run a job spec (see Job.spec) with the API's `run` or `test`; the result row's job-specific part."""
    started = time.monotonic()
    output = Path(spec['output']) if spec.get('output') else None
    try:
        result = _run(spec, output, run, test)
    except Exception as exc:  # noqa: BLE001 - any failure of a job is its row, never the campaign's end
        message = ' '.join(str(exc).split()) or type(exc).__name__
        return {'status': 'error', 'message': message[:2000], 'assertions': {}, 'detections': {}, 'warnings': [],
                'seconds': round(time.monotonic() - started, 3), 'output': None}
    assertions, detections = _assertions(result), _detections(result)
    failed = [a for a in result.assertions if a.state != 'passed']
    return {'status': 'failed' if failed else 'passed',
            'message': '; '.join(f'{a.id}: {a.message}' for a in failed)[:2000],
            'assertions': assertions, 'detections': detections, 'warnings': list(result.warnings),
            'seconds': round(time.monotonic() - started, 3), 'output': str(output) if output else None}

