"""Field path resolution against the output's topic types, for assertions."""

from __future__ import annotations

from typing import TYPE_CHECKING

from bagfault.errors import AssertionSetupError, FieldPathError
from bagfault.faults.fieldpath import FieldPath

if TYPE_CHECKING:
    from bagfault.assertions.runner import AssertionRunner


def resolve_on_topic(runner: AssertionRunner, topic: str, text: str) -> FieldPath | None:
    """Parse and resolve a numeric path on a topic's type; None if the topic is absent."""
    try:
        path = FieldPath.parse(text)
    except FieldPathError as exc:
        raise AssertionSetupError(str(exc)) from None
    msgtype = runner.topic_types.get(topic)
    if msgtype is None:
        return path
    codec = runner.catalog.codec(msgtype)
    if codec is None:
        raise AssertionSetupError(f'cannot decode {msgtype} on {topic}: {runner.catalog.why_not(msgtype)}')
    try:
        resolved = path.resolve(msgtype, codec.store)
    except FieldPathError as exc:
        raise AssertionSetupError(str(exc)) from None
    if not resolved.numeric:
        raise AssertionSetupError(f'{text!r} on {topic} is a {resolved.leaf}, not a number')
    return resolved
