"""`topic_hz`: the rate over a rolling window reaches `min_hz`, sampled as ros2_fault_injection samples it.

The anchor's runner looks every 100 ms (from its start) at the messages
received in the last `window` seconds and passes when count / window >=
min_hz; it fails at the first look after `within`. Here the looks are at
bag time zero + k x 100 ms, each counting the messages of [t - window, t]
(a message exactly `window` old still counts, as there).
"""

from __future__ import annotations

from collections import deque
from typing import TYPE_CHECKING, Any, ClassVar

from bagfault.assertions.base import END_OF_BAG, TICK, AssertionType
from bagfault.schema import Key
from bagfault.units import NS

if TYPE_CHECKING:
    from bagfault.assertions.runner import AssertionRunner
    from bagfault.spec.model import AssertionSpec, Scenario



class TopicHzAssertion(AssertionType):
    """Passes once count(messages in the last `window` s) / window >= min_hz."""

    type_name = 'topic_hz'
    description = 'A topic is observed at or above min_hz over a rolling window.'
    fields: ClassVar[tuple[Key, ...]] = (
        Key('topic', 'non_empty_string', 'Topic to measure.', required=True),
        Key('message_type', 'non_empty_string', 'Expected type of the topic, e.g. nav_msgs/msg/Odometry.',
                    required=True),
        Key('min_hz', 'number', 'Minimum rate, in Hz (> 0).', required=True),
        Key('window', 'number', 'Rolling window, in seconds (> 0).', required=True),
    )

    @classmethod
    def check(cls, spec: AssertionSpec, scenario: Scenario) -> list[tuple[str, str]]:
        """min_hz and window must be positive."""
        return [
            (key, f'{spec.params[key]} must be greater than 0')
            for key in ('min_hz', 'window')
            if isinstance(spec.params.get(key), float) and spec.params[key] <= 0.0
        ]

    def __init__(self, spec: AssertionSpec, runner: AssertionRunner) -> None:
        super().__init__(spec, runner)
        self.window = round(self.params['window'] * NS)
        self.times: deque[int] = deque()
        self.best = 0.0
        self.wrong_type: str | None = None

    def topics(self) -> set[str]:
        """The measured topic."""
        return {self.params['topic']}

    def prepare(self) -> None:
        """Remember a type mismatch: the anchor subscribes with `message_type`, so it hears none of the topic's
        messages and fails at its first look after `within`, as with a silent topic."""
        have = self.runner.topic_types.get(self.params['topic'])
        if have is not None and have != self.params['message_type']:
            self.wrong_type = have

    def deadline(self) -> int | None:
        """The first look."""
        return self.runner.origin + TICK

    def on_deadline(self, time: int) -> None:
        """A look: pass when the rate is reached, fail after `within`, else look again 100 ms later. The window
        keeps a message whose age is exactly `window` (topic_hz_assertion.cpp drops an age *above* it)."""
        times = self.times
        while times and times[0] < time - self.window:
            times.popleft()
        rate = len(times) / self.params['window']
        self.best = max(self.best, rate)
        if rate >= self.params['min_hz']:
            self.passed(time, f"{self.params['topic']} at {rate:.2f} Hz over {self.params['window']:g} s at "
                              f"{self.runner.t(time)} (min {self.params['min_hz']:g} Hz)", rate, 'Hz',
                        margin=rate - self.params['min_hz'])
        elif self.spec.within is not None and time - self.runner.origin > round(self.spec.within * NS):
            self.fail(time, f'{self.waiting_for()} within {self.spec.within:g} s (looked at {self.runner.t(time)})',
                      self.best, 'Hz', margin=self.best - self.params['min_hz'])
        else:
            self.runner.schedule(self, time + TICK)

    def finish(self, time: int) -> None:
        """The bag ended before the rate was reached: failed by what the best window lacked."""
        self.fail(time, f'{self.waiting_for()}: {END_OF_BAG}', self.best, 'Hz',
                  margin=self.best - self.params['min_hz'])

    def on_message(self, topic: str, time: int, message: Any) -> None:
        """Counted at the next look (none of another type: the anchor's subscription never gets them)."""
        if self.wrong_type is None:
            self.times.append(time)

    def waiting_for(self) -> str:
        """Failure text with the best rate seen (and why none was counted, for a topic of another type)."""
        wrong = f", none of type {self.params['message_type']} (it carries {self.wrong_type})" if self.wrong_type \
            else ''
        return (f"{self.params['topic']} did not reach {self.params['min_hz']:g} Hz "
                f"(best {self.best:.2f} Hz over {self.params['window']:g} s{wrong})")
