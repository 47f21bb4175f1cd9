"""`message_count`: number of messages on a topic (optionally during a fault) within [min, max]."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, ClassVar

from bagfault.assertions.base import AssertionType, range_problems, window_problems
from bagfault.assertions.windows import DURING, OUTSIDE, describe, in_window
from bagfault.schema import Key

if TYPE_CHECKING:
    from bagfault.assertions.runner import AssertionRunner
    from bagfault.spec.model import AssertionSpec, Scenario


class MessageCountAssertion(AssertionType):
    """Counts; fails as soon as max is exceeded, decides min at the end."""

    type_name = 'message_count'
    description = 'Message count on a topic (all, or during/outside a fault) within [min, max].'
    fields: ClassVar[tuple[Key, ...]] = (
        Key('topic', 'non_empty_string', 'Topic to count.', required=True),
        Key('min', 'integer', 'Fewest accepted messages.', minimum=0),
        Key('max', 'integer', 'Most accepted messages.', minimum=0),
        DURING,
        OUTSIDE,
    )
    takes_within = False

    @classmethod
    def check(cls, spec: AssertionSpec, scenario: Scenario) -> list[tuple[str, str]]:
        """Needs min or max."""
        problems = window_problems(spec, scenario) + range_problems(spec)
        if not {'min', 'max'} & set(spec.params):
            problems.append(('', "give 'min' and/or 'max'"))
        return problems

    def __init__(self, spec: AssertionSpec, runner: AssertionRunner) -> None:
        super().__init__(spec, runner)
        self.count = 0

    def topics(self) -> set[str]:
        """The counted topic."""
        return {self.params['topic']}

    def expectation(self) -> str:
        """'[a, b]' text."""
        low = self.params.get('min', 0)
        high = self.params.get('max')
        return f'[{low}, {high}]' if high is not None else f'at least {low}'

    def on_message(self, topic: str, time: int, message: Any) -> None:
        """Count; too many fails at once."""
        if not in_window(self):
            return
        self.count += 1
        if 'max' in self.params and self.count > self.params['max']:
            self.fail(time, f'{topic}{describe(self)}: message {self.count} at {self.runner.t(time)} is more than '
                            f"max {self.params['max']}", self.count, 'messages', margin=self.room())

    def finish(self, time: int) -> None:
        """Decide on the total."""
        topic = self.params['topic']
        if self.count < self.params.get('min', 0):
            self.fail(time, f'{topic}{describe(self)}: {self.count} messages by the end of the bag at '
                            f'{self.runner.t(time)}, expected {self.expectation()}', self.count, 'messages',
                      margin=self.room())
        else:
            self.passed(time, f'{topic}{describe(self)}: {self.count} messages, expected {self.expectation()}',
                        self.count, 'messages', margin=self.room())

    def room(self) -> float:
        """Messages from the nearer bound: count - min, max - count (negative past it)."""
        sides = [self.count - self.params.get('min', 0)]
        if 'max' in self.params:
            sides.append(self.params['max'] - self.count)
        return float(min(sides))
