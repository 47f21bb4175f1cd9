"""`field_range`: a field stays within [min, max] (or finite) for every message."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from bagfault.assertions.base import AssertionType, range_problems, window_problems
from bagfault.assertions.fields import resolve_on_topic
from bagfault.assertions.windows import DURING, OUTSIDE, describe, in_window
from bagfault.schema import Key

if TYPE_CHECKING:
    from bagfault.assertions.runner import AssertionRunner
    from bagfault.spec.model import AssertionSpec, Scenario


class FieldRangeAssertion(AssertionType):
    """Fails at the first message whose field leaves the range."""

    type_name = 'field_range'
    description = 'A field path stays within [min, max] and/or finite, for all messages or during/outside a fault.'
    fields: ClassVar[tuple[Key, ...]] = (
        Key('topic', 'non_empty_string', 'Topic to check.', required=True),
        Key('field', 'non_empty_string', 'Field path, e.g. pose.pose.position.x or ranges[*].', required=True),
        Key('min', 'number', 'Smallest accepted value (field unit).'),
        Key('max', 'number', 'Largest accepted value (field unit).'),
        Key('finite', 'boolean', 'Values must not be inf or nan.'),
        DURING,
        OUTSIDE,
    )
    takes_within = False

    @classmethod
    def check(cls, spec: AssertionSpec, scenario: Scenario) -> list[tuple[str, str]]:
        """Needs a bound or finite; min <= max; windows name faults."""
        problems = window_problems(spec, scenario) + range_problems(spec)
        if not {'min', 'max'} & set(spec.params) and not spec.params.get('finite'):
            problems.append(('', "give 'min', 'max' or 'finite: true'"))
        return problems

    def __init__(self, spec: AssertionSpec, runner: AssertionRunner) -> None:
        super().__init__(spec, runner)
        self.path: Any = None
        self.checked = 0
        self.low = self.params.get('min', -np.inf)
        self.high = self.params.get('max', np.inf)
        self.closest = np.inf  # the smallest distance of a value to a bound so far (the margin)

    def topics(self) -> set[str]:
        """The checked topic."""
        return {self.params['topic']}

    decoded_topics = topics

    def prepare(self) -> None:
        """Resolve the field path on the topic's type."""
        self.path = resolve_on_topic(self.runner, self.params['topic'], self.params['field'])

    def on_message(self, topic: str, time: int, message: Any) -> None:
        """Check every value of the path."""
        if not in_window(self):
            return
        values = self.path.read(message)
        self.checked += 1
        bounded = 'min' in self.params or 'max' in self.params
        bad = ~((values >= self.low) & (values <= self.high)) if bounded else np.zeros(values.shape, bool)
        if self.params.get('finite'):
            bad |= ~np.isfinite(values)
        room = None
        if bounded and values.size:
            with np.errstate(invalid='ignore'):  # inf - inf: no distance, left out of the margin
                room = np.minimum(values - self.low, self.high - values)
        if bad.any():
            index = int(np.argmax(bad))
            where = f' (element {index})' if values.size > 1 else ''
            self.fail(time, f"at {self.runner.t(time)} {topic} {self.params['field']}{where} = {values[index]:g} "
                            f'is outside {self.expectation()}', float(values[index]),
                      margin=None if room is None else float(room[index]))
        elif room is not None:
            self.closest = min(self.closest, float(room.min()))

    def expectation(self) -> str:
        """Text of the accepted range."""
        parts = []
        if 'min' in self.params or 'max' in self.params:
            parts.append(f'[{self.low:g}, {self.high:g}]')
        if self.params.get('finite'):
            parts.append('finite values')
        return ' and '.join(parts)

    def finish(self, time: int) -> None:
        """Pass if messages were checked and none failed."""
        if self.checked:
            self.passed(time, f"{self.checked} messages on {self.params['topic']}{describe(self)} kept "
                              f"{self.params['field']} within {self.expectation()}",
                        margin=self.closest if np.isfinite(self.closest) else None)
        else:
            self.fail(time, f"no message on {self.params['topic']}{describe(self)} to check: {self.waiting_for()}")

    def waiting_for(self) -> str:
        """Failure text."""
        return 'not observed before the end of the bag'
