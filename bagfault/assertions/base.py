"""Assertion type base: declared keys, semantic checks, and the runtime contract."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, ClassVar

from bagfault.schema import ConfigField

if TYPE_CHECKING:
    from bagfault.scenario.model import AssertionSpec, Scenario

WITHIN = ConfigField('within', 'double', 'Deadline in seconds from bag time zero.', None, min=0.0)


class AssertionType:
    """One assertion type: its keys (besides id, type, within) and checks."""

    type_name: ClassVar[str] = ''
    description: ClassVar[str] = ''
    fields: ClassVar[tuple[ConfigField, ...]] = ()

    @classmethod
    def check(cls, spec: AssertionSpec, scenario: Scenario) -> list[tuple[str, str]]:
        """Semantic problems as (key, message) pairs; key '' means the assertion itself."""
        return []

    @classmethod
    def field(cls, key: str) -> ConfigField | None:
        """Schema entry for a key."""
        return next((x for x in cls.fields if x.key == key), None)


def fault_reference_problem(
    spec: AssertionSpec,
    scenario: Scenario,
    key: str,
) -> list[tuple[str, str]]:
    """Problem list for a key that must name a fault of the scenario."""
    value: Any = spec.params.get(key)
    if value is None or scenario.fault(str(value)) is not None:
        return []
    known = ', '.join(dict.fromkeys(f.id for f in scenario.faults)) or 'none'
    return [(key, f'unknown fault {value!r} (faults: {known})')]
