"""The breaking point of one parameter, per bag, by bisection.

Each value is run `repeat` times per seed (one sample per job). The rule:
a value *holds* when the `until` assertion reaches its state in every
sample; one sample that misses it and the value does not hold. Bisection
assumes that once a value holds, every larger one does (a bias large
enough to be detected stays detected). The result is the interval the
samples are sure of: the smallest value that held in all of its samples
and the largest that did not (with how many of its samples held), within
the tolerance. Offline runs are byte-identical per seed, so the same
campaign gives the same point; closed-loop samples vary with the system's
scheduling, which the repeats and the all-samples rule absorb.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from bagfault.campaign.plan import search_job

if TYPE_CHECKING:
    from collections.abc import Callable

    from bagfault.campaign.model import Search
    from bagfault.campaign.plan import Bag, Job, Plan

    RunJobs = Callable[[list[Job]], dict[str, dict[str, Any]]]


@dataclass
class BreakingPoint:
    """Per bag: the smallest value of the parameter at which `until` held, and the bracket around it."""

    bag: Bag
    parameter: str
    value: float | None  # None: did not hold even at `high`
    below: float | None  # the largest value known not to hold (None: it held at `low`)
    jobs: int = 0
    note: str = ''
    samples: list[Sample] = field(default_factory=list)  # every value run, in the order the search ran them

    def describe(self) -> dict[str, Any]:
        """campaign.json's record: the interval, the rule's note and every sample behind it."""
        return {'bag': str(self.bag), 'parameter': self.parameter, 'holds_from': self.value, 'not_at': self.below,
                'jobs': self.jobs, 'note': self.note,
                'samples': [{'value': s.value, 'held': s.held, 'runs': s.runs} for s in self.samples]}


@dataclass(frozen=True)
class Sample:
    """A value of the search and how many of its runs brought the assertion to its state."""

    value: float
    held: int
    runs: int
    error: str = ''  # the first reason a run of this value could not run (then it decides nothing)

    def describe(self) -> str:
        """'0.48: 2 of 3'."""
        return f'{self.value:g}: {self.held} of {self.runs}'


@dataclass
class _Bracket:
    low: float
    high: float
    phase: str = 'ends'  # ends: low and high not yet run; bisect; done
    result: BreakingPoint | None = None
    samples: list[Sample] = field(default_factory=list)


def held(search: Search, results: list[dict[str, Any]]) -> int:
    """How many of the runs brought the assertion to the wanted state."""
    until = search.until
    return sum(r.get('assertions', {}).get(until.assertion, {}).get('state') == until.state for r in results)


def find_breaking_points(plan: Plan, run_jobs: RunJobs, first_index: int) -> tuple[list[BreakingPoint], list[Job]]:
    """Bisect every bag at once, one round of jobs at a time; the points and every job run for them."""
    search = plan.campaign.search
    assert search is not None
    seeds = plan.campaign.seeds
    repeat = search.samples(plan.campaign.mode)
    runs = [(seed, sample) for seed in seeds for sample in range(repeat)]
    brackets = {bag: _Bracket(search.low, search.high) for bag in plan.bags}
    counts = dict.fromkeys(plan.bags, 0)
    jobs: list[Job] = []
    while True:
        wanted: list[tuple[Bag, float]] = []
        for bag, bracket in brackets.items():
            if bracket.phase == 'ends':
                wanted += [(bag, bracket.low), (bag, bracket.high)]
            elif bracket.phase == 'bisect':
                wanted.append((bag, round((bracket.low + bracket.high) / 2, 12)))
        if not wanted:
            break
        round_jobs = {(bag, value): [search_job(plan, first_index + len(jobs) + k * len(runs) + n, bag, value, seed,
                                                sample) for n, (seed, sample) in enumerate(runs)]
                      for k, (bag, value) in enumerate(wanted)}
        batch = [job for group in round_jobs.values() for job in group]
        jobs += batch
        results = run_jobs(batch)
        outcome = {at: Sample(at[1], held(search, [results[job.key] for job in group]), len(group),
                              next((f'job {job.index}: {results[job.key].get("message", "")}' for job in group
                                    if results[job.key].get('status') == 'error'), ''))
                   for at, group in round_jobs.items()}
        for bag, bracket in brackets.items():
            counts[bag] += sum(len(group) for (b, _), group in round_jobs.items() if b == bag)
            bracket.samples += [sample for (b, _), sample in outcome.items() if b == bag]
            _advance(bag, bracket, outcome, search)
            if bracket.result is not None:
                bracket.result.jobs = counts[bag]
                bracket.result.samples = list(bracket.samples)
    return [b.result for b in brackets.values() if b.result is not None], jobs


def _advance(bag: Bag, bracket: _Bracket, outcome: dict[tuple[Bag, float], Sample], search: Search) -> None:
    broken = next((s for (b, _), s in outcome.items() if b == bag and s.error), None)
    if broken is not None and bracket.phase != 'done':  # a run that could not run is no sample of the system
        bracket.phase, bracket.result = 'done', BreakingPoint(
            bag, search.parameter, None, None,
            note=f'stopped: a run at {broken.value:g} could not run ({broken.error})')
        return
    if bracket.phase == 'ends':
        low, high = outcome[(bag, bracket.low)], outcome[(bag, bracket.high)]
        if low.held == low.runs:
            bracket.phase, bracket.result = 'done', BreakingPoint(
                bag, search.parameter, bracket.low, None, note=f'holds already at low = {bracket.low:g} '
                f'({low.held} of {low.runs})')
        elif high.held < high.runs:
            bracket.phase, bracket.result = 'done', BreakingPoint(
                bag, search.parameter, None, bracket.high, note=f'does not hold up to high = {bracket.high:g} '
                f'({high.held} of {high.runs} at high)')
        else:
            bracket.phase = 'bisect'
    elif bracket.phase == 'bisect':
        mid = round((bracket.low + bracket.high) / 2, 12)
        at = outcome[(bag, mid)]
        if at.held == at.runs:
            bracket.high = mid
        else:
            bracket.low = mid
    if bracket.phase == 'bisect' and bracket.high - bracket.low <= search.tolerance:
        bracket.phase = 'done'
        below = next(s for s in reversed(bracket.samples) if s.value == bracket.low)
        above = next(s for s in reversed(bracket.samples) if s.value == bracket.high)
        bracket.result = BreakingPoint(bag, search.parameter, bracket.high, bracket.low,
                                       note=f'held in {above.held} of {above.runs} runs at {bracket.high:g}, '
                                            f'{below.held} of {below.runs} at {bracket.low:g}')
