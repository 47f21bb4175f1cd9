"""Where the search looks next: fresh draws that make interactions common, and refinements of near misses.

A fresh draw takes 1..max_faults candidates (each count as likely:
swarm testing, so single faults and combinations both get runs), chosen to
cover the pairs of candidates drawn least so far (a greedy covering array:
every pair of faults meets early), every dimension uniform in its range,
and, for three draws in four with two or more faults, the windows placed to
overlap the first one's (two faults that only hurt together need to be
active together; uniform starts make that rare).

A refinement starts from a passing run whose margins came closest to
failing: each margin is taken relative to the same assertion's margin in
the baseline run (no fault), so 1 is "as far as with no fault" and 0 is
"at the edge", and a run's closeness is its smallest such ratio (assertions
of a failure already found alone are left out: the search goes for the
others). The closest runs are mutated, one dimension nudged, the faults
made stronger, a fault added over a window, a window moved onto another,
a fault dropped, and each pick of a parent lowers its priority, so no near
miss takes every run. Half the proposals after the first `batch` are
refinements while some run is closer than 0.95; the others stay fresh.

`uniform` is the comparison of the benchmark: uniform draws, no coverage,
no overlap, no margins.
"""

from __future__ import annotations

import math
import random
from typing import TYPE_CHECKING, Literal

from bagfault.explore.candidate import Candidate, Drawn, ordered, quantize

if TYPE_CHECKING:
    from collections.abc import Sequence

    from bagfault.explore.records import Outcome, RunRecord
    from bagfault.spec.model import Explore, ExploreFault

Strategy = Literal['guided', 'uniform']
OVERLAP = 0.75  # share of fresh multi-fault draws whose windows are placed to overlap
REFINE = 0.5  # share of proposals that refine a near miss (when one is closer than NEAR)
NEAR = 0.95
ELITES = 6  # the closest runs a parent is picked from
WEAR = 0.05  # what each pick adds to a parent's closeness


class Search:
    """Proposes candidates; `observe` tells it every outcome, in run order."""

    def __init__(self, space: Explore, seed: int, strategy: Strategy = 'guided') -> None:
        self.space = space
        self.rng = random.Random(f'bagfault explore {seed}')
        self.strategy = strategy
        self.drawn: dict[str, int] = {f.id: 0 for f in space.faults}
        self.pairs: dict[tuple[str, str], int] = {}
        self.baseline: dict[str, float] = {}
        self.scores: list[tuple[float, int, Candidate]] = []  # (closeness, run, candidate) of passing runs
        self.picked: dict[int, int] = {}
        self.proposed = 0
        self.ignored: set[str] = set()  # assertions of a failure found alone

    # -- what happened ---------------------------------------------------------------------------------------
    def observe(self, record: RunRecord, known: Sequence[frozenset[str]]) -> None:
        """A run's outcome (every run, search or not); `known` the failures found so far."""
        self.ignored = {next(iter(f)) for f in known if len(f) == 1}
        outcome = record.outcome
        if record.purpose == 'baseline':
            self.baseline = {k: m for k, (m, _) in outcome.margins.items() if m is not None and m > 0}
            return
        if outcome.status == 'passed' and record.candidate.faults:
            closeness = self.closeness(outcome)
            if closeness is not None:
                self.scores.append((closeness, record.index, record.candidate))

    def closeness(self, outcome: Outcome) -> float | None:
        """The smallest margin relative to the baseline's (None: no assertion has both)."""
        ratios = [m / self.baseline[k] for k, (m, _) in outcome.margins.items()
                  if m is not None and k in self.baseline and k not in self.ignored]
        return min(ratios) if ratios else None

    def best(self) -> float | None:
        """The closest any passing run came so far."""
        return min((s for s, _, _ in self.scores), default=None)

    # -- what next -------------------------------------------------------------------------------------------
    def propose(self) -> tuple[Candidate, Literal['search', 'refine']]:
        """The next candidate to run, and whether it is fresh or a refinement."""
        self.proposed += 1
        if self.strategy == 'uniform':
            return self._uniform(), 'search'
        warm = self.proposed > self.space.batch
        if warm and self.scores and self.rng.random() < REFINE:
            parent = self._parent()
            if parent is not None:
                return self._count(self._mutate(parent)), 'refine'
        return self._count(self._fresh()), 'search'

    def _count(self, candidate: Candidate) -> Candidate:
        ids = candidate.ids
        for n, a in enumerate(ids):
            self.drawn[a] += 1
            for b in ids[n + 1:]:
                self.pairs[(a, b)] = self.pairs.get((a, b), 0) + 1
        return candidate

    def _uniform(self) -> Candidate:
        k = self.rng.randint(1, self.space.max_faults)
        chosen = self.rng.sample(self.space.faults, k)
        return ordered(self.space, [self._values(f) for f in chosen])

    def _fresh(self) -> Candidate:
        k = self.rng.randint(1, self.space.max_faults)
        chosen: list[ExploreFault] = []
        for _ in range(k):
            rest = [f for f in self.space.faults if f not in chosen]
            chosen.append(min(rest, key=lambda f: (sum(self._pair(f.id, c.id) for c in chosen), self.drawn[f.id],
                                                   self.rng.random())))
        drawn = [self._values(f) for f in chosen]
        if len(drawn) > 1 and self.rng.random() < OVERLAP:
            drawn = [drawn[0], *(self._over(d, drawn[0]) for d in drawn[1:])]
        return ordered(self.space, drawn)

    def _pair(self, a: str, b: str) -> int:
        return self.pairs.get((a, b), 0) + self.pairs.get((b, a), 0)

    def _values(self, fault: ExploreFault) -> Drawn:
        return Drawn(fault.id, tuple((d.name, quantize(d, self.rng.uniform(d.low, d.high))) for d in fault.dimensions))

    def _window(self, drawn: Drawn) -> tuple[float, float]:
        fault = self.space.fault(drawn.fault)
        assert fault is not None
        values = dict(drawn.values)
        start = values.get('start', fault.start or 0.0)
        duration = values.get('duration', fault.duration)
        return start, math.inf if duration is None else duration

    def _over(self, drawn: Drawn, anchor: Drawn) -> Drawn:
        """`drawn` with its start moved so its window overlaps `anchor`'s (when its start is a dimension)."""
        fault = self.space.fault(drawn.fault)
        assert fault is not None
        dimension = fault.dimension('start')
        if dimension is None:
            return drawn
        start, duration = self._window(anchor)
        own = self._window(drawn)[1]
        low = max(dimension.low, start - 0.9 * own) if math.isfinite(own) else dimension.low
        high = min(dimension.high, start + 0.9 * duration)
        if low > high:
            return drawn
        return drawn.replaced('start', quantize(dimension, self.rng.uniform(low, high)))

    def _parent(self) -> Candidate | None:
        ranked = sorted(((s + WEAR * self.picked.get(i, 0), i, c) for s, i, c in self.scores))[:ELITES]
        if not ranked or ranked[0][0] >= NEAR:
            return None
        weights = [max(0.01, 1.0 - score) for score, _, _ in ranked]  # the closer to failing, the likelier
        _, index, candidate = self.rng.choices(ranked, weights)[0]
        self.picked[index] = self.picked.get(index, 0) + 1
        return candidate

    def _mutate(self, parent: Candidate) -> Candidate:
        kind = self.rng.choices(('nudge', 'stronger', 'add', 'shift', 'drop'), (35, 30, 15, 15, 5))[0]
        regrouped = self._regroup(kind, parent)
        if regrouped is not None:
            return regrouped
        drawn = self.rng.choice(parent.faults)
        fault = self.space.fault(drawn.fault)
        assert fault is not None
        if not fault.dimensions:
            return self._fresh()
        if kind == 'stronger':
            return parent.replaced(self._stronger(fault, drawn))
        dimension = self.rng.choice(fault.dimensions)
        step = self.rng.choice((0.05, 0.15, 0.3)) * dimension.span
        value = quantize(dimension, drawn.value(dimension.name) + self.rng.gauss(0.0, step))
        return parent.replaced(drawn.replaced(dimension.name, value))

    def _regroup(self, kind: str, parent: Candidate) -> Candidate | None:
        """`add` a fault (the one least often paired with those drawn, over one of them), `drop` one, or `shift`
        one over another; None for another kind, or when the candidate has too many or too few faults for it."""
        rng, space = self.rng, self.space
        faults = list(parent.faults)
        if kind == 'add' and len(faults) < space.max_faults:
            rest = [f for f in space.faults if f.id not in parent.ids]
            added = min(rest, key=lambda f: (sum(self._pair(f.id, d.fault) for d in faults), rng.random()))
            return ordered(space, [*faults, self._over(self._values(added), rng.choice(faults))])
        if kind == 'drop' and len(faults) > 1:
            faults.remove(rng.choice(faults))
            return ordered(space, faults)
        if kind == 'shift' and len(faults) > 1:
            moved, anchor = rng.sample(faults, 2)
            return parent.replaced(self._over(moved, anchor))
        return None

    def _stronger(self, fault: ExploreFault, drawn: Drawn) -> Drawn:
        """Every dimension but the start moved part of the way toward its strongest end."""
        for dimension in fault.dimensions:
            if dimension.name != 'start':
                value = drawn.value(dimension.name)
                drawn = drawn.replaced(dimension.name, quantize(
                    dimension, value + self.rng.uniform(0.1, 0.6) * (dimension.high - value)))
        return drawn
