"""`bagfault test --repeat N`: the same closed loop N times, each isolated, folded into one result.

A live loop is not bit-exact (the faults and their noise are), so each
assertion gets a pass rate and the spread of the bag time it decided at
(its measured detection or reaction time); the run fails when any run
failed an assertion.
"""

from __future__ import annotations

import statistics
from dataclasses import replace
from typing import TYPE_CHECKING

from bagfault.assertions.base import AssertionResult
from bagfault.units import NS

if TYPE_CHECKING:
    from collections.abc import Sequence

    from bagfault.engine.result import RunResult
    from bagfault.events import AssertionState


def decided_seconds(result: RunResult, assertion: AssertionResult) -> float | None:
    """When an assertion decided, in seconds from the run's time zero."""
    origin = result.stats.origin
    if assertion.time is None or origin is None:
        return None
    return (assertion.time - origin) / NS


def fold(results: Sequence[RunResult]) -> RunResult:
    """One result for N runs: per assertion 'passed k of N runs', decision-time spread, first failure."""
    last = results[-1]
    folded: list[AssertionResult] = []
    for index, first in enumerate(results[0].assertions):
        runs = [next((a for a in r.assertions if a.id == first.id), None) for r in results]
        states = [a.state if a is not None else 'pending' for a in runs]
        passed = states.count('passed')
        times = [t for r, a in zip(results, runs, strict=True) if a is not None
                 and (t := decided_seconds(r, a)) is not None]
        text = f'passed {passed} of {len(results)} runs ({100 * passed / len(results):.0f}%)'
        if times:
            text += (f'; decided at {min(times):.3f} to {max(times):.3f} s (median {statistics.median(times):.3f} s'
                     + (f', stdev {statistics.stdev(times):.3f} s)' if len(times) > 1 else ')'))
        failures = [(n, a) for n, a in enumerate(runs, 1) if a is not None and a.state == 'failed']
        if failures:
            number, failed = failures[0]
            text += f'; run {number}: {failed.message}'
        state: AssertionState = 'failed' if failures else 'passed' if passed == len(results) else 'pending'
        base = last.assertions[index] if index < len(last.assertions) else first
        folded.append(replace(base, state=state, message=text))
    notes = [*last.notes, f'{len(results)} runs, each on its own ROS domain; verdicts are pass rates']
    return replace(last, assertions=folded, notes=notes, repeats=list(results), assertion_events=[])
