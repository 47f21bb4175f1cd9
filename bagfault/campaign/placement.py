"""Which node runs which job on a Ray cluster: a bag's jobs go to the nodes that hold the bag (locality).

Each node keeps its own cache of bucket bags, so every node that runs a job of
a bag downloads that bag once. Ray alone spreads a bag's jobs over every node
(on three nodes three downloads per bag). Here a node with a free CPU takes, in
this order: a waiting job of a bag it holds; a job of a bag no node holds yet
(it then holds that bag); else a job of the bag whose holders have the most
rounds still to run, but only when that is more than `STEAL_ROUNDS` rounds, so
that a second download is paid only where it shortens the campaign by more than
a job's length. Pure bookkeeping: the Ray engine asks and dispatches.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

STEAL_ROUNDS = 2.0  # a node takes a bag another holds only when its holders have more rounds than this to run


@dataclass
class Placement:
    """The waiting jobs by bag, the nodes and their CPUs, who holds which bag and what runs where."""

    waiting: dict[str, deque[int]] = field(default_factory=dict)  # bag -> job indices in table order
    slots: dict[str, int] = field(default_factory=dict)  # node -> CPUs
    holders: dict[str, set[str]] = field(default_factory=dict)  # bag -> nodes that ran (or run) one of its jobs
    busy: dict[str, int] = field(default_factory=dict)  # node -> its running jobs

    @classmethod
    def of(cls, bags: list[str], slots: dict[str, int]) -> Placement:
        """Jobs 0..n-1 whose bags are `bags[i]`, on nodes with `slots` CPUs each."""
        placement = cls(slots=dict(slots), busy=dict.fromkeys(slots, 0))
        for index, bag in enumerate(bags):
            placement.waiting.setdefault(bag, deque()).append(index)
        return placement

    @property
    def pending(self) -> int:
        """Jobs not yet handed out."""
        return sum(len(jobs) for jobs in self.waiting.values())

    def nodes(self, slots: dict[str, int]) -> None:
        """The cluster's nodes now: a node gone holds nothing and runs nothing; a new one starts empty."""
        for node in set(self.slots) - set(slots):
            del self.busy[node]
            for holding in self.holders.values():
                holding.discard(node)
        self.slots = dict(slots)
        for node in slots:
            self.busy.setdefault(node, 0)

    def assign(self, limit: int | None = None) -> list[tuple[int, str]]:
        """Fill free CPUs one node at a time, round the nodes (so each first claims a bag of its own): a list of
        (job, node); at most `limit` jobs running in all when given."""
        handed: list[tuple[int, str]] = []
        progress = True
        while progress:
            progress = False
            for node in self.slots:
                if limit is not None and sum(self.busy.values()) >= limit:
                    return handed
                if self.busy[node] >= self.slots[node]:
                    continue
                index = self._next(node)
                if index is not None:
                    handed.append((index, node))
                    self.busy[node] += 1
                    progress = True
        return handed

    def finished(self, node: str) -> None:
        """A job handed to `node` ended (it may have run elsewhere: Ray moves a task off a lost node)."""
        if self.busy.get(node, 0) > 0:
            self.busy[node] -= 1

    def _held_or_free(self, node: str) -> str | None:
        """A bag with waiting jobs that the node holds, else one nobody holds yet; None when there is neither."""
        own = [bag for bag, jobs in self.waiting.items() if jobs and node in self.holders.get(bag, ())]
        free = [bag for bag, jobs in self.waiting.items() if jobs and not self.holders.get(bag)]
        return (own or free)[0] if own or free else None

    def _stolen(self) -> str | None:
        """The bag whose waiting jobs would take its holders the most rounds, when that is more than STEAL_ROUNDS
        (a node then takes it too and downloads it); None otherwise."""
        rounds = {b: len(jobs) / max(1, sum(self.slots.get(n, 0) for n in self.holders[b]))
                  for b, jobs in self.waiting.items() if jobs}
        if not rounds or max(rounds.values()) <= STEAL_ROUNDS:
            return None
        return max(rounds, key=rounds.__getitem__)

    def _next(self, node: str) -> int | None:
        """The job `node` takes next (it then holds that job's bag), or None."""
        bag = self._held_or_free(node)
        if bag is None:
            bag = self._stolen()
        if bag is None:
            return None
        self.holders.setdefault(bag, set()).add(node)
        return self.waiting[bag].popleft()
