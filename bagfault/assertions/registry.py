"""Assertion types by name."""

from __future__ import annotations

from bagfault.assertions.base import AssertionType
from bagfault.assertions.fault_event import FaultEventAssertion
from bagfault.assertions.topic_hz import TopicHzAssertion

ASSERTION_TYPES: dict[str, type[AssertionType]] = {
    cls.type_name: cls for cls in (FaultEventAssertion, TopicHzAssertion)
}
