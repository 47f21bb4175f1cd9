"""Assertion types by name."""

from __future__ import annotations

from bagfault.assertions.base import AssertionType
from bagfault.assertions.fault_event import FaultEventAssertion
from bagfault.assertions.fault_status import FaultCountAssertion, FaultStatusAssertion
from bagfault.assertions.field_delta import FieldDeltaAssertion
from bagfault.assertions.field_range import FieldRangeAssertion
from bagfault.assertions.message_count import MessageCountAssertion
from bagfault.assertions.path_latency import PathLatencyAssertion
from bagfault.assertions.sequence import SequenceAssertion
from bagfault.assertions.topic_gap import TopicGapAssertion
from bagfault.assertions.topic_hz import TopicHzAssertion

ASSERTION_TYPES: dict[str, type[AssertionType]] = {
    cls.type_name: cls
    for cls in (
        FaultEventAssertion,
        TopicHzAssertion,
        TopicGapAssertion,
        FieldRangeAssertion,
        FieldDeltaAssertion,
        MessageCountAssertion,
        SequenceAssertion,
        FaultStatusAssertion,
        FaultCountAssertion,
        PathLatencyAssertion,
    )
}
