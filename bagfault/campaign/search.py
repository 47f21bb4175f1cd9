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
    jobs: int = 0  # run for this bag so far

    @property
    def middle(self) -> float:
        """The value a bisection runs next (to 12 decimals, so a value and its job key repeat exactly)."""
        return round((self.low + self.high) / 2, 12)


def held(search: Search, results: list[dict[str, Any]]) -> int:
    """How many of the runs brought the assertion to the wanted state."""
    until = search.until
    return sum(r.get('assertions', {}).get(until.assertion, {}).get('state') == until.state for r in results)


def find_breaking_points(plan: Plan, run_jobs: RunJobs, first_index: int) -> tuple[list[BreakingPoint], list[Job]]:
    """Bisect every bag at once, one round of jobs at a time; the points and every job run for them."""
    search = plan.campaign.search
    assert search is not None
    runs = [(seed, sample) for seed in plan.campaign.seeds for sample in range(search.samples(plan.campaign.mode))]
    brackets = {bag: _Bracket(search.low, search.high) for bag in plan.bags}
    jobs: list[Job] = []
    while True:
        wanted = _wanted(brackets)
        if not wanted:
            break
        jobs += _search_round(plan, run_jobs, brackets, _round_jobs(plan, first_index + len(jobs), wanted, runs))
    return [b.result for b in brackets.values() if b.result is not None], jobs


def _search_round(plan: Plan, run_jobs: RunJobs, brackets: dict[Bag, _Bracket],
                  round_jobs: dict[tuple[Bag, float], list[Job]]) -> list[Job]:
    """Run a round's jobs and move every bag's bracket on from their samples; the jobs run."""
    search = plan.campaign.search
    assert search is not None
    batch = [job for group in round_jobs.values() for job in group]
    outcome = _outcome(search, round_jobs, run_jobs(batch))
    for bag, bracket in brackets.items():
        _take(bag, bracket, outcome, search)
    return batch


def _wanted(brackets: dict[Bag, _Bracket]) -> list[tuple[Bag, float]]:
    """The values each bag's bracket asks for next: both ends first, then the middle; none once done."""
    wanted: list[tuple[Bag, float]] = []
    for bag, bracket in brackets.items():
        if bracket.phase == 'ends':
            wanted += [(bag, bracket.low), (bag, bracket.high)]
        elif bracket.phase == 'bisect':
            wanted.append((bag, bracket.middle))
    return wanted


def _outcome(search: Search, round_jobs: dict[tuple[Bag, float], list[Job]], results: dict[str, dict[str, Any]],
             ) -> dict[tuple[Bag, float], Sample]:
    """Each (bag, value)'s sample: how many of its runs held, and the first run that could not run."""
    return {at: Sample(at[1], held(search, [results[job.key] for job in group]), len(group),
                       next((f'job {job.index}: {results[job.key].get("message", "")}' for job in group
                             if results[job.key].get('status') == 'error'), ''))
            for at, group in round_jobs.items()}


def _round_jobs(plan: Plan, first: int, wanted: list[tuple[Bag, float]], runs: list[tuple[int, int]],
                ) -> dict[tuple[Bag, float], list[Job]]:
    """A round's jobs, numbered from `first`: each (seed, sample) run of each value wanted."""
    return {(bag, value): [search_job(plan, first + k * len(runs) + n, bag, value, seed, sample)
                           for n, (seed, sample) in enumerate(runs)]
            for k, (bag, value) in enumerate(wanted)}


def _take(bag: Bag, bracket: _Bracket, outcome: dict[tuple[Bag, float], Sample], search: Search) -> None:
    """A round's samples into the bag's bracket, which moves on; its result, once there, with the jobs it took."""
    mine = [sample for (b, _), sample in outcome.items() if b == bag]
    bracket.jobs += sum(sample.runs for sample in mine)
    bracket.samples += mine
    _advance(bag, bracket, outcome, search)
    if bracket.result is not None:
        bracket.result.jobs = bracket.jobs
        bracket.result.samples = list(bracket.samples)


def _advance(bag: Bag, bracket: _Bracket, outcome: dict[tuple[Bag, float], Sample], search: Search) -> None:
    """The bracket's next phase from the round's samples: stopped by a run that could not run (no sample of the
    system), the ends judged, or the half that holds the edge kept; done within tolerance."""
    if _stopped(bag, bracket, outcome, search):
        return
    if bracket.phase == 'ends':
        _ends(bag, bracket, outcome, search)
    elif bracket.phase == 'bisect':
        mid = bracket.middle
        at = outcome[(bag, mid)]
        if at.held == at.runs:
            bracket.high = mid
        else:
            bracket.low = mid
    if bracket.phase == 'bisect' and bracket.high - bracket.low <= search.tolerance:
        _settled(bag, bracket, search)


def _stopped(bag: Bag, bracket: _Bracket, outcome: dict[tuple[Bag, float], Sample], search: Search) -> bool:
    """True (and the bracket done, saying why) when a run of the bag's round could not run."""
    broken = next((s for (b, _), s in outcome.items() if b == bag and s.error), None)
    if broken is None or bracket.phase == 'done':
        return False
    bracket.phase, bracket.result = 'done', BreakingPoint(
        bag, search.parameter, None, None, note=f'stopped: a run at {broken.value:g} could not run ({broken.error})')
    return True


def _ends(bag: Bag, bracket: _Bracket, outcome: dict[tuple[Bag, float], Sample], search: Search) -> None:
    """After both ends: done when it holds already at low or not even at high, else bisect."""
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


def _settled(bag: Bag, bracket: _Bracket, search: Search) -> None:
    """The bracket within tolerance: the breaking point between its ends, with the samples there."""
    bracket.phase = 'done'
    below = next(s for s in reversed(bracket.samples) if s.value == bracket.low)
    above = next(s for s in reversed(bracket.samples) if s.value == bracket.high)
    bracket.result = BreakingPoint(bag, search.parameter, bracket.high, bracket.low,
                                   note=f'held in {above.held} of {above.runs} runs at {bracket.high:g}, '
                                        f'{below.held} of {below.runs} at {bracket.low:g}')
