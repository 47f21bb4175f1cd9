"""Shrinking a failure to its minimal cause, one run at a time.

In order: confirm the original (it must fail `confirm` runs in a row); the
fewest faults (ddmin over the fault set: drop one fault at a time while the
rest still fails, until no single fault can go); then each config dimension
toward its weakest value, each duration toward the shortest (from its end,
then from its start: the end kept, the start later), each start as late as
the failure allows, each by trying the end of its range first and
else bisecting to `resolution` of its range; then again, one step of
`resolution` per dimension first, while a pass still moves something (up to
PASSES): a start moved later may allow a shorter window. A step is kept
only when its candidate fails `confirm` runs in a row with exactly the
failure's set of assertions; a run that could not run keeps nothing. The search is a
generator: it yields the candidate to run and is sent (run index, outcome),
so the driver runs the steps of several failures side by side, in rounds,
and the result depends only on the outcomes, never on how many workers ran
them.
"""

from __future__ import annotations

from collections.abc import Callable, Generator
from typing import TYPE_CHECKING, Literal

from bagfault.explore.candidate import Candidate, quantize
from bagfault.explore.records import ShrinkStep

if TYPE_CHECKING:
    from bagfault.explore.records import Failure, Outcome, Purpose
    from bagfault.spec.model import Dimension, Explore

# the benchmark's comparisons: `halving` shrinks every dimension without the margins' guesses, `faults` is ddmin over
# the fault set only
ShrinkMode = Literal['full', 'halving', 'faults']
Runs = Generator[Candidate, tuple[int, 'Outcome'], bool]
PASSES = 3  # passes over every dimension: one more whenever a pass moved something (a later start may allow a
            # shorter window, a shorter window of one fault a shorter one of the other)


class Shrinker:
    """The shrink of one failure: `steps()` yields candidates to run and takes their outcomes."""

    def __init__(self, space: Explore, failure: Failure, found: Outcome, *, confirm: int, mode: ShrinkMode = 'full',
                 composite: Callable[[], str] = lambda: '') -> None:
        self.space = space
        self.failure = failure
        self.confirm = confirm
        self.mode = mode
        self.composite = composite  # '' or which other failures this one's assertions are all of
        self.current = failure.original
        self.latest: Outcome | None = found  # the outcome of the last run
        self.kept: Outcome | None = found  # the outcome of the last run of `current`
        self.purpose: Purpose = 'confirm'  # what the candidate it asks for now is run for
    def steps(self) -> Generator[Candidate, tuple[int, Outcome], None]:
        """Every run of the shrink; at the end `failure.minimal` holds the smallest candidate that failed."""
        failure = self.failure
        if not (yield from self._fails(self.current, 'confirm the original', already=1)):
            failure.state, failure.note = 'unconfirmed', (f'did not fail {self.confirm} runs in a row the same way: '
                                                          'not shrunk (flaky, or at the edge of a threshold)')
            return
        yield from self._fewest_faults()
        for sweep in range(PASSES if self.mode != 'faults' else 0):
            before = self.current
            for phase in ('config', 'duration', 'window', 'start'):
                yield from self._phase(phase, again=sweep > 0)
            if self.current == before or failure.note:
                break
        failure.minimal, failure.state = self.current, 'shrunk'

    def _phase(self, phase: str, *, again: bool) -> Generator[Candidate, tuple[int, Outcome], None]:
        """One phase of a pass over every fault kept: each dimension of the phase moved toward its weakest end
        (the window as a whole in the window phase), until the failure turns out to be smaller ones together."""
        for fault_id in self.current.ids:
            for dimension in self._dimensions(fault_id, phase):
                if self._composite():
                    break
                if phase == 'window':
                    yield from self._window(fault_id)
                else:
                    yield from self._toward(fault_id, dimension, again=again)

    def _composite(self) -> bool:
        """Whether the failure turned out to be smaller ones together (found meanwhile): then its dimensions
        are left as they are."""
        composite = self.composite()
        if composite and not self.failure.note:
            self.failure.note = (f'its assertions are those of {composite} together: its faults are shrunk, not '
                                 'its dimensions')
        return bool(composite)

    def _dimensions(self, fault_id: str, phase: str) -> list[Dimension]:
        fault = self.space.fault(fault_id)
        assert fault is not None
        if phase == 'window':  # a window with both ends free: its duration, shrunk from the start side
            return [d for d in fault.dimensions if d.name == 'duration'] if fault.dimension('start') else []
        return [d for d in fault.dimensions if (d.name.startswith('config.') if phase == 'config' else d.name == phase)]

    def _window(self, fault_id: str) -> Generator[Candidate, tuple[int, Outcome], None]:
        """Shorten the window from its start, its end kept (the start later by as much as the duration is
        shorter): what two overlapping faults need when neither end alone can move, or the latest part of a
        window is what fails. One step first (a window whose length is its threshold stops there), then the
        shortest, else halving the shift."""
        fault = self.space.fault(fault_id)
        assert fault is not None
        duration, start = fault.dimension('duration'), fault.dimension('start')
        assert duration is not None and start is not None
        values = dict(self.current.drawn(fault_id).values)
        room = min(values['duration'] - duration.low, start.high - values['start'])
        limit = self.space.resolution * duration.span
        if room <= 0:
            return
        failing, passing = 0.0, None
        for shift in dict.fromkeys((min(limit, room), room)):  # one step first: a window at its threshold stops
            if (yield from self._shift(fault_id, values, shift, duration, start)):
                failing = shift
            else:
                passing = shift
                break
        if passing is None or failing == 0.0:
            return
        while passing - failing > limit:
            middle = (failing + passing) / 2
            if (yield from self._shift(fault_id, values, middle, duration, start)):
                failing = middle
            else:
                passing = middle

    def _shift(self, fault_id: str, values: dict[str, float], shift: float, duration: Dimension,
               start: Dimension) -> Runs:
        drawn = self.current.drawn(fault_id)
        moved = drawn.replaced('duration', quantize(duration, values['duration'] - shift)).replaced(
            'start', quantize(start, values['start'] + shift))
        if moved == drawn:
            return False
        trial = self.current.replaced(moved)
        kept = yield from self._fails(trial, f'{fault_id}.window from {values["start"]:g}+{values["duration"]:g} to '
                                             f'{moved.value("start"):g}+{moved.value("duration"):g}')
        if kept:
            self.current = trial
        return kept

    def _fewest_faults(self) -> Generator[Candidate, tuple[int, Outcome], None]:
        """ddmin at the granularity of single faults: drop each in turn; keep a drop that still fails."""
        dropped = True
        while dropped and len(self.current.faults) > 1:
            dropped = False
            for fault_id in self.current.ids:
                trial = self.current.without(fault_id)
                if (yield from self._fails(trial, f'without {fault_id}')):
                    self.current, dropped = trial, True
                    break

    def _toward(self, fault_id: str, dimension: Dimension, *,
                again: bool = False) -> Generator[Candidate, tuple[int, Outcome], None]:
        """Move one dimension toward its weakest end (the latest start): the end itself first; else narrow the
        bracket between the value that fails and the one that passes to `resolution` of the range: a strength (a
        config key) at the point where the margin, taken as linear between the two, crosses zero (just on either
        side of it, so a margin that is linear settles in two runs), as long as the margins measured there keep
        to that line; else halfway (a time, no margins, a margin that jumps, a guess that did not halve)."""
        name = dimension.name
        target = dimension.high if name == 'start' else dimension.low
        failing = self.current.drawn(fault_id).value(name)
        if failing == target:
            return
        label = f'{fault_id}.{name.removeprefix("config.")}'
        if again:  # a later pass: one step toward the end says whether another value moved its threshold
            stepped = yield from self._one_step(fault_id, dimension, failing, target, label)
            if stepped is None or stepped == target:
                return
            failing = stepped
        at_failing = self.margin(self.kept)
        if (yield from self._try(fault_id, name, target, f'{label} {failing:g} -> {target:g}')):
            return
        yield from self._bracket(fault_id, dimension, label, (failing, at_failing, target, self.margin(self.latest)))

    def _one_step(self, fault_id: str, dimension: Dimension, failing: float, target: float,
                  label: str) -> Generator[Candidate, tuple[int, Outcome], float | None]:
        """One resolution step from the failing value toward `target`: the new failing value, or None when the
        step changes nothing or passes."""
        limit = self.space.resolution * dimension.span
        step = quantize(dimension, failing + (limit if target > failing else -limit))
        if step == failing or not (yield from self._try(fault_id, dimension.name, step,
                                                        f'{label} {failing:g} -> {step:g}')):
            return None
        return step

    def _bracket(self, fault_id: str, dimension: Dimension, label: str,
                 bracket: tuple[float, float | None, float, float | None],
                 ) -> Generator[Candidate, tuple[int, Outcome], None]:
        """Narrow (failing value, its margin, passing value, its margin) to `resolution` of the range: at the
        margin's linear root while the margins keep to the line (a strength, full mode), else halfway."""
        name = dimension.name
        failing, at_failing, passing, at_passing = bracket
        limit = self.space.resolution * dimension.span
        linear = name.startswith('config.') and self.mode == 'full'  # a strength's margin may follow it; a time's
        # rarely does
        stale = False  # the last guess did not halve the bracket: halve next
        while abs(failing - passing) > limit:
            width = abs(failing - passing)
            probe = _probe(dimension, _root(failing, at_failing, passing, at_passing, limit)
                           if linear and not stale else None, failing, passing)
            if probe is None:
                break
            point, value = probe
            before = (failing, at_failing, passing, at_passing)
            if (yield from self._try(fault_id, name, value, f'{label} {failing:g} -> {value:g}')):
                failing, at_failing = value, self.margin(self.latest)
            else:
                passing, at_passing = value, self.margin(self.latest)
            if point is not None:  # the guess: did the margin follow the line it was drawn from?
                linear = self._on_line(before, value, self.margin(self.latest))
            stale = point is not None and abs(failing - passing) > width / 2

    @staticmethod
    def _on_line(bracket: tuple[float, float | None, float, float | None], value: float,
                 observed: float | None) -> bool:
        """Whether a margin measured at `value` lies near the line through the bracket's two (within a quarter
        of the smaller of them): else it jumps (a latched bug, a crash) and only halving finds its edge."""
        failing, at_failing, passing, at_passing = bracket
        if observed is None or at_failing is None or at_passing is None:
            return False
        predicted = at_passing + (at_failing - at_passing) * (value - passing) / (failing - passing)
        return abs(observed - predicted) <= 0.25 * min(-at_failing, at_passing)

    def margin(self, outcome: Outcome | None) -> float | None:
        """The failure's margin in a run: the smallest of its assertions' (None when one has none)."""
        if outcome is None or outcome.status == 'error':
            return None
        margins = [outcome.margins.get(a, (None, ''))[0] for a in self.failure.assertions]
        return None if not margins or any(m is None for m in margins) else min(m for m in margins if m is not None)

    def _try(self, fault_id: str, name: str, value: float, change: str) -> Runs:
        trial = self.current.replaced(self.current.drawn(fault_id).replaced(name, value))
        kept = yield from self._fails(trial, change)
        if kept:
            self.current = trial
        return kept

    def _fails(self, candidate: Candidate, change: str, *, already: int = 0) -> Runs:
        """Run `candidate` until it has failed `confirm` times in a row the failure's way (`already` of them done);
        a step of the shrink path either way."""
        failure = self.failure
        runs, first, kept = 0, -1, True
        for _ in range(already, self.confirm):
            self.purpose = 'shrink' if runs == 0 and not already else 'confirm'
            index, outcome = yield candidate
            self.latest = outcome
            runs += 1
            first = index if first < 0 else first
            failure.shrink_runs += 1
            if self.purpose == 'confirm':
                failure.confirmations += 1
            if outcome.status == 'error' or outcome.failing != failure.assertions:
                kept = False
                break
        if runs:
            failure.steps.append(ShrinkStep(first, change, candidate, kept, runs))
        if kept:
            self.kept = self.latest
        return kept


def _probe(dimension: Dimension, point: float | None, failing: float, passing: float,
           ) -> tuple[float | None, float] | None:
    """The guess and the value to try next: the guess quantized, or (None and) halfway when the guess lands on
    an end of the bracket (or there is none); None when halfway does too (the bracket cannot narrow)."""
    value = quantize(dimension, point if point is not None else (failing + passing) / 2)
    if value not in (failing, passing):
        return point, value
    value = quantize(dimension, (failing + passing) / 2)
    return None if value in (failing, passing) else (None, value)


def _root(failing: float, at_failing: float | None, passing: float, at_passing: float | None,
          limit: float) -> float | None:
    """Where the margin, taken as linear between the failing value and the passing one, crosses zero: just on
    the side of it nearer the middle of the bracket (half a `limit` away, inside the bracket), so a margin that is
    linear settles in two runs; None unless the failing margin is at most 0 and the passing one above."""
    if at_failing is None or at_passing is None or not at_failing <= 0 < at_passing:
        return None
    side = 1.0 if failing > passing else -1.0  # from passing toward failing
    width = abs(failing - passing)
    root = passing + (failing - passing) * at_passing / (at_passing - at_failing)
    nearer_failing = (abs(root - passing) + limit / 2) < width / 2
    point = root + side * limit / 2 if nearer_failing else root - side * limit / 2
    return min(max(point, min(failing, passing) + limit / 2), max(failing, passing) - limit / 2)
