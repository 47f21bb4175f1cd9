"""`topic_gap`: no gap longer than `max_gap` seconds on a topic (catches silent sensors)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, ClassVar

from bagfault.assertions.base import AssertionType, fault_reference_problem
from bagfault.assertions.windows import DURING
from bagfault.schema import Key
from bagfault.units import NS

if TYPE_CHECKING:
    from bagfault.assertions.runner import AssertionRunner
    from bagfault.events import FaultEvent
    from bagfault.spec.model import AssertionSpec, Scenario



class TopicGapAssertion(AssertionType):
    """Watches time between messages: from bag time zero (or the fault's activation) to
    the end of the bag (or the fault's deactivation), including both edges."""

    type_name = 'topic_gap'
    description = 'No gap longer than max_gap seconds on a topic (optionally only during a fault).'
    fields: ClassVar[tuple[Key, ...]] = (
        Key('topic', 'non_empty_string', 'Topic to watch.', required=True),
        Key('max_gap', 'number', 'Longest accepted time between messages, in seconds (> 0).', required=True),
        DURING,
    )
    takes_within = False

    @classmethod
    def check(cls, spec: AssertionSpec, scenario: Scenario) -> list[tuple[str, str]]:
        """max_gap positive; during names a fault."""
        problems = fault_reference_problem(spec, scenario, 'during')
        if isinstance(spec.params.get('max_gap'), float) and spec.params['max_gap'] <= 0:
            problems.append(('max_gap', f"{spec.params['max_gap']} must be greater than 0"))
        return problems

    def __init__(self, spec: AssertionSpec, runner: AssertionRunner) -> None:
        super().__init__(spec, runner)
        self.max_gap = round(self.params['max_gap'] * NS)
        self.last: int | None = None
        self.windows = 0
        self.longest = 0

    def topics(self) -> set[str]:
        """The watched topic."""
        return {self.params['topic']}

    def deadline(self) -> int | None:
        """Without `during`, the watch starts at bag time zero (armed by a deadline at zero)."""
        return None if 'during' in self.params else self.runner.origin - 1

    def on_deadline(self, time: int) -> None:
        """Open the whole-bag window at time zero."""
        self.last = self.runner.origin
        self.windows = 1

    def _gap(self, start: int, end: int, what: str) -> None:
        gap = end - start
        self.longest = max(self.longest, gap)
        if gap > self.max_gap:
            self.fail(end, f"gap of {gap / NS:.3f} s on {self.params['topic']} from {self.runner.t(start)} to "
                           f"{self.runner.t(end)}{what} exceeds max_gap {self.params['max_gap']:g} s", gap / NS, 's',
                      margin=(self.max_gap - gap) / NS)

    def on_event(self, event: FaultEvent) -> None:
        """Open or close the fault window."""
        if event.fault_id != self.params.get('during'):
            return
        if event.state == 'active' and self.last is None:
            self.last = event.time
            self.windows += 1
        elif event.state == 'inactive' and self.last is not None:
            self._gap(self.last, event.time, f' (until {event.fault_id} ended)')
            self.last = None

    def on_message(self, topic: str, time: int, message: Any) -> None:
        """Measure the gap to the previous message (or window start)."""
        if self.last is not None:
            self._gap(self.last, time, '')
            self.last = time

    def finish(self, time: int) -> None:
        """Close the open window at the end of the bag and decide."""
        if self.last is not None:
            self._gap(self.last, time, ' (end of the bag)')
        if not self.pending:
            return
        if self.windows == 0:
            self.fail(time, f"fault {self.params['during']} was never active: nothing was checked")
        else:
            self.passed(time, f"longest gap on {self.params['topic']} {self.longest / NS:.3f} s "
                              f"(max {self.params['max_gap']:g} s)", self.longest / NS, 's',
                        margin=(self.max_gap - self.longest) / NS)
