"""Assertion types by name, each module imported when a scenario names its type."""

from __future__ import annotations

from typing import TYPE_CHECKING

from bagfault.types_by_name import TypesByName

if TYPE_CHECKING:
    from bagfault.assertions.base import AssertionType

ASSERTION_TYPES: TypesByName[type[AssertionType]] = TypesByName({
    'fault_event': 'bagfault.assertions.fault_event:FaultEventAssertion',
    'topic_hz': 'bagfault.assertions.topic_hz:TopicHzAssertion',
    'topic_gap': 'bagfault.assertions.topic_gap:TopicGapAssertion',
    'field_range': 'bagfault.assertions.field_range:FieldRangeAssertion',
    'field_delta': 'bagfault.assertions.field_delta:FieldDeltaAssertion',
    'message_count': 'bagfault.assertions.message_count:MessageCountAssertion',
    'sequence': 'bagfault.assertions.sequence:SequenceAssertion',
    'fault_status': 'bagfault.assertions.fault_status:FaultStatusAssertion',
    'fault_count': 'bagfault.assertions.fault_status:FaultCountAssertion',
    'path_latency': 'bagfault.assertions.path_latency:PathLatencyAssertion',
})
