"""The breaking point of one parameter, per bag, by bisection.

A value *holds* when, for every seed, the `until` assertion reaches its
state. Bisection assumes that once a value holds, every larger one does
(a bias large enough to be detected stays detected); the result is the
smallest value known to hold, within the tolerance.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from bagfault.campaign.plan import search_job

if TYPE_CHECKING:
    from collections.abc import Callable
    from pathlib import Path

    from bagfault.campaign.model import Search
    from bagfault.campaign.plan import Job, Plan

    RunJobs = Callable[[list[Job]], dict[str, dict[str, Any]]]


@dataclass
class BreakingPoint:
    """Per bag: the smallest value of the parameter at which `until` held, and the bracket around it."""

    bag: Path
    parameter: str
    value: float | None  # None: did not hold even at `high`
    below: float | None  # the largest value known not to hold (None: it held at `low`)
    jobs: int = 0
    note: str = ''


@dataclass
class _Bracket:
    low: float
    high: float
    phase: str = 'ends'  # ends: low and high not yet run; bisect; done
    result: BreakingPoint | None = None


def holds(search: Search, results: list[dict[str, Any]]) -> bool:
    """True when every seed's run brought the assertion to the wanted state."""
    until = search.until
    return all(r.get('assertions', {}).get(until.assertion, {}).get('state') == until.state for r in results)


def find_breaking_points(plan: Plan, run_jobs: RunJobs, first_index: int) -> tuple[list[BreakingPoint], list[Job]]:
    """Bisect every bag at once, one round of jobs at a time; the points and every job run for them."""
    search = plan.campaign.search
    assert search is not None
    seeds = plan.campaign.seeds
    brackets = {bag: _Bracket(search.low, search.high) for bag in plan.bags}
    counts = dict.fromkeys(plan.bags, 0)
    jobs: list[Job] = []
    while True:
        wanted: list[tuple[Path, float]] = []
        for bag, bracket in brackets.items():
            if bracket.phase == 'ends':
                wanted += [(bag, bracket.low), (bag, bracket.high)]
            elif bracket.phase == 'bisect':
                wanted.append((bag, round((bracket.low + bracket.high) / 2, 12)))
        if not wanted:
            break
        round_jobs = {(bag, value): [search_job(plan, first_index + len(jobs) + k * len(seeds) + n, bag, value, seed)
                                     for n, seed in enumerate(seeds)] for k, (bag, value) in enumerate(wanted)}
        batch = [job for group in round_jobs.values() for job in group]
        jobs += batch
        results = run_jobs(batch)
        verdict = {at: holds(search, [results[job.key] for job in group]) for at, group in round_jobs.items()}
        for bag, bracket in brackets.items():
            counts[bag] += sum(len(group) for (b, _), group in round_jobs.items() if b == bag)
            _advance(bag, bracket, verdict, search)
            if bracket.result is not None:
                bracket.result.jobs = counts[bag]
    return [b.result for b in brackets.values() if b.result is not None], jobs


def _advance(bag: Path, bracket: _Bracket, verdict: dict[tuple[Path, float], bool], search: Search) -> None:
    if bracket.phase == 'ends':
        if verdict[(bag, bracket.low)]:
            bracket.phase, bracket.result = 'done', BreakingPoint(bag, search.parameter, bracket.low, None,
                                                                  note=f'holds already at low = {bracket.low:g}')
        elif not verdict[(bag, bracket.high)]:
            bracket.phase, bracket.result = 'done', BreakingPoint(bag, search.parameter, None, bracket.high,
                                                                  note=f'does not hold up to high = {bracket.high:g}')
        else:
            bracket.phase = 'bisect'
    elif bracket.phase == 'bisect':
        mid = round((bracket.low + bracket.high) / 2, 12)
        if verdict[(bag, mid)]:
            bracket.high = mid
        else:
            bracket.low = mid
    if bracket.phase == 'bisect' and bracket.high - bracket.low <= search.tolerance:
        bracket.phase = 'done'
        bracket.result = BreakingPoint(bag, search.parameter, bracket.high, bracket.low,
                                       note=f'holds from {bracket.high:g} on, not at {bracket.low:g}')
