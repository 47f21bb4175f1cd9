"""`topic_hz`: the rate over a rolling window reaches `min_hz` (anchor meaning)."""

from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar

from bagfault.assertions.base import AssertionType
from bagfault.schema import ConfigField

if TYPE_CHECKING:
    from bagfault.scenario.model import AssertionSpec, Scenario


class TopicHzAssertion(AssertionType):
    """Passes once count(messages in the last `window` s) / window >= min_hz."""

    type_name = 'topic_hz'
    description = 'A topic is observed at or above min_hz over a rolling window.'
    fields: ClassVar[tuple[ConfigField, ...]] = (
        ConfigField('topic', 'non_empty_string', 'Topic to measure.', required=True),
        ConfigField('message_type', 'non_empty_string', 'Expected type of the topic, e.g. nav_msgs/msg/Odometry.', required=True),
        ConfigField('min_hz', 'double', 'Minimum rate, in Hz (> 0).', required=True),
        ConfigField('window', 'double', 'Rolling window, in seconds (> 0).', required=True),
    )

    @classmethod
    def check(cls, spec: AssertionSpec, scenario: Scenario) -> list[tuple[str, str]]:
        """min_hz and window must be positive."""
        return [
            (key, f'{spec.params[key]} must be greater than 0')
            for key in ('min_hz', 'window')
            if isinstance(spec.params.get(key), float) and spec.params[key] <= 0.0
        ]
