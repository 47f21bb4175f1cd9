"""Fault activation and deactivation on bag time.

Every schedule is a lazy sequence of (time, state) toggles; the scheduler
merges them, applies each toggle at its exact bag time and reports it as a
FaultEvent. Nothing here reads a clock: the caller says what time it is.

Schedules (times in seconds from bag time zero):
- `active_on_startup`: active at zero (source `startup`), until `duration`;
- `start` [+ `duration`]: active in [start, start + duration) (`scheduled`);
- `repeat: {period, on}` inside the start/duration window;
- `probability_per_second` with `hold`, seeded, inside the window;
- `after: {fault, delay}`: follows another fault's activations;
- `--activate FAULT[@START[+DURATION]]` replaces the fault's schedule (`cli`).
Manual-only faults stay inactive until activated.
"""

from __future__ import annotations

import heapq
from typing import TYPE_CHECKING

from bagfault.engine.activation import Activation
from bagfault.events import FaultEvent
from bagfault.faults.active import ActiveFault
from bagfault.faults.rng import FaultRandom
from bagfault.units import MS, NS

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator, Sequence

    from bagfault.events import FaultSource
    from bagfault.spec.model import FaultSpec, Scenario



def seconds_to_ns(seconds: float) -> int:
    """Seconds (float) to integer nanoseconds, rounded."""
    return round(seconds * NS)


def _ms(seconds: float) -> int:
    """Whole milliseconds, truncated toward zero, as the anchor's static_cast<int64_t>(seconds * 1000)."""
    return int(seconds * 1000.0)


def _anchor_window(fault: FaultSpec) -> tuple[int, int | None]:
    """`active_on_startup` / `start` + `duration` as ros2_fault_injection schedules them: whole milliseconds,
    and timers of at least 1 ms (a `start: 0` fault activates 1 ms after time zero)."""
    if fault.active_on_startup:
        end = None if fault.duration is None else max(_ms(fault.duration), 1) * MS
        return 0, end
    start = _ms(fault.start or 0.0)
    end = None if fault.duration is None else max(start + _ms(fault.duration), 1) * MS
    return max(start, 1) * MS, end


def _window(fault: FaultSpec) -> tuple[int, int | None]:
    """The start/duration window of the extended schedules (repeat, random), in exact nanoseconds."""
    begin = 0 if fault.active_on_startup else seconds_to_ns(fault.start or 0.0)
    end = None if fault.duration is None else begin + seconds_to_ns(fault.duration)
    return begin, end


def _plain(begin: int, end: int | None) -> Iterator[tuple[int, bool]]:
    yield begin, True
    if end is not None:
        yield end, False


def _repeat(fault: FaultSpec) -> Iterator[tuple[int, bool]]:
    assert fault.repeat is not None
    begin, end = _window(fault)
    period, on = seconds_to_ns(fault.repeat.period), seconds_to_ns(fault.repeat.on)
    if on >= period:
        yield from _plain(begin, end)
        return
    cycle = begin
    while end is None or cycle < end:
        yield cycle, True
        off = cycle + on
        yield (off if end is None else min(off, end)), False
        cycle += period


def _random(fault: FaultSpec, random: FaultRandom) -> Iterator[tuple[int, bool]]:
    assert fault.probability_per_second is not None and fault.hold is not None
    stream = random.stream('schedule')
    begin, end = _window(fault)
    hold = seconds_to_ns(fault.hold)
    clock = begin
    while True:
        clock += seconds_to_ns(float(stream.exponential(1.0 / fault.probability_per_second)))
        if end is not None and clock >= end:
            return
        yield clock, True
        clock += hold
        yield (clock if end is None else min(clock, end)), False


class FaultScheduler:
    """Knows which faults are active at any bag time and emits their events."""

    def __init__(
        self,
        scenario: Scenario,
        origin: int,
        seed: int,
        activations: Sequence[Activation] = (),
    ) -> None:
        self.scenario = scenario
        self.current: Callable[[str], FaultSpec | None] = scenario.fault  # a FaultState gives its current config
        self.origin = origin
        self.random = {
            f.id: FaultRandom(_fault_seed(scenario, f, seed), f.id) for f in scenario.faults
        }
        self.active: dict[str, int] = {}
        self._order = {f.id: i for i, f in reversed(list(enumerate(scenario.faults)))}  # an id at its first place
        self._positions: dict[int, tuple[Sequence[FaultSpec], dict[str, list[int]]]] = {}  # see active_of
        self._heap: list[tuple[int, int, int, str, bool, FaultSource, int]] = []
        # each definition's schedule (a fault id defined twice has two, which both switch it, as in the anchor)
        self._sequences: dict[int, tuple[str, Iterator[tuple[int, bool]], FaultSource]] = {}
        self._counter = 0
        self._followers: dict[str, list[FaultSpec]] = {}
        requested: dict[str, list[Activation]] = {}
        for activation in activations:
            requested.setdefault(activation.fault_id, []).append(activation)
        for number, fault in enumerate(scenario.faults):
            if fault.id in requested:
                if scenario.fault(fault.id) is fault:  # once per id, whatever its definitions say
                    windows = sorted(requested[fault.id], key=lambda a: a.start)
                    self._add(number, fault.id, self._windows(windows), 'cli')
            elif fault.after is not None:
                self._followers.setdefault(fault.after.fault, []).append(fault)
            else:
                self._schedule(number, fault)

    def _schedule(self, number: int, fault: FaultSpec) -> None:
        """A definition's own schedule: repeated, random, from startup or at its start (none: a trigger's)."""
        if fault.repeat is not None:
            self._add(number, fault.id, _repeat(fault), 'scheduled')
        elif fault.probability_per_second is not None:
            self._add(number, fault.id, _random(fault, self.random[fault.id]), 'scheduled')
        elif fault.active_on_startup:
            self._add(number, fault.id, _plain(*_anchor_window(fault)), 'startup')
        elif fault.start is not None:
            self._add(number, fault.id, _plain(*_anchor_window(fault)), 'scheduled')

    @staticmethod
    def _windows(windows: list[Activation]) -> Iterator[tuple[int, bool]]:
        for window in windows:
            begin = seconds_to_ns(window.start)
            yield from _plain(begin, None if window.duration is None else begin + seconds_to_ns(window.duration))

    def _add(self, number: int, fault_id: str, sequence: Iterator[tuple[int, bool]], source: FaultSource) -> None:
        self._sequences[number] = (fault_id, sequence, source)
        self._pull(number)

    def _pull(self, number: int) -> None:
        fault_id, sequence, source = self._sequences[number]
        step = next(sequence, None)
        if step is not None:
            self._push(self.origin + step[0], fault_id, step[1], source, number)

    def _push(self, time: int, fault_id: str, state: bool, source: FaultSource, number: int = -1) -> None:
        self._counter += 1
        heapq.heappush(self._heap, (time, self._order[fault_id], self._counter, fault_id, state, source, number))

    def next_time(self) -> int | None:
        """Bag time (ns) of the next pending change, or None."""
        return self._heap[0][0] if self._heap else None

    def next_change_of(self, fault_ids: set[str]) -> int | None:
        """Bag time (ns) of the next pending change of any of these faults, or None (chunk copy asks)."""
        return min((entry[0] for entry in self._heap if entry[3] in fault_ids), default=None)

    def advance(self, now: int) -> list[FaultEvent]:
        """Apply every change due at or before `now`; return their events in order."""
        events = []
        while self._heap and self._heap[0][0] <= now:
            time, _, _, fault_id, state, source, number = heapq.heappop(self._heap)
            if source == 'startup' and not state:
                source = 'scheduled'  # the end of a startup fault's duration is a timer, as in the anchor
            if number in self._sequences:
                self._pull(number)
            event = self.set_state(fault_id, state, time, source)
            if event is not None:
                events.append(event)
        return events

    def set_state(self, fault_id: str, state: bool, time: int, source: FaultSource) -> FaultEvent | None:
        """Activate or deactivate a fault now (also for live/manual changes); a switch from outside is detailed
        as the anchor's SetFaultState details it (describe_fault), a scheduled one with its config."""
        fault = self.current(fault_id)
        if fault is None or (fault_id in self.active) == state:
            return None
        if state:
            self.active[fault_id] = time
        else:
            del self.active[fault_id]
        for follower in self._followers.get(fault_id, ()):
            self._follow(follower, state, time)
        injector = self.scenario.injector(fault.injector_id)
        return FaultEvent(
            time=time,
            fault_id=fault_id,
            injector_id=injector.id if injector else fault.injector_id,
            state='active' if state else 'inactive',
            source=source,
            details=fault.describe_fault() if source == 'manual' else fault.describe_config(),
        )

    def _follow(self, follower: FaultSpec, state: bool, time: int) -> None:
        """A fault chained `after` one that switched at `time`: on after its delay (for its duration, if it has
        one), off after its delay when it has none."""
        assert follower.after is not None
        delay = seconds_to_ns(follower.after.delay)
        if state:
            self._push(time + delay, follower.id, True, 'scheduled')
            if follower.duration is not None:
                self._push(time + delay + seconds_to_ns(follower.duration), follower.id, False, 'scheduled')
        elif follower.duration is None:
            self._push(time + delay, follower.id, False, 'scheduled')

    def active_of(self, faults: Sequence[FaultSpec]) -> list[ActiveFault]:
        """Those of `faults` active now, with their start time and random streams, in the given order.

        Asked at every change, so linear in the active faults, not in `faults` (30 000 windows of one
        injector made a run quadratic): a sequence's positions are indexed once, kept while it lives."""
        if len(self.active) * 4 >= len(faults):
            return [ActiveFault(f, self.active[f.id], self.random[f.id]) for f in faults if f.id in self.active]
        positions = self._positions_of(faults)
        chosen = sorted(i for fault_id in self.active for i in positions.get(fault_id, ()))
        return [ActiveFault(f, self.active[f.id], self.random[f.id]) for f in (faults[i] for i in chosen)]


    def _positions_of(self, faults: Sequence[FaultSpec]) -> dict[str, list[int]]:
        """Fault id -> its places in `faults` (an id defined twice is there twice), indexed once per sequence."""
        kept = self._positions.get(id(faults))
        if kept is None or kept[0] is not faults:
            positions: dict[str, list[int]] = {}
            for i, f in enumerate(faults):
                positions.setdefault(f.id, []).append(i)
            kept = (faults, positions)
            self._positions[id(faults)] = kept
        return kept[1]


def _fault_seed(scenario: Scenario, fault: FaultSpec, seed: int) -> int:
    injector = scenario.injector(fault.injector_id)
    return injector.seed if injector is not None and injector.seed is not None else seed
