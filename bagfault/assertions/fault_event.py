"""`fault_event`: a named fault reaches `active` or `inactive` (anchor meaning)."""

from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar

from bagfault.assertions.base import AssertionType, fault_reference_problem
from bagfault.schema import ConfigField

if TYPE_CHECKING:
    from bagfault.scenario.model import AssertionSpec, Scenario


class FaultEventAssertion(AssertionType):
    """Passes at the first matching fault event."""

    type_name = 'fault_event'
    description = 'A named fault reaches state active or inactive (before `within`, if given).'
    fields: ClassVar[tuple[ConfigField, ...]] = (
        ConfigField('fault_id', 'non_empty_string', 'Fault to watch.', required=True),
        ConfigField('state', 'non_empty_string', 'Expected state: active or inactive.', required=True),
    )

    @classmethod
    def check(cls, spec: AssertionSpec, scenario: Scenario) -> list[tuple[str, str]]:
        """fault_id must exist, state must be active or inactive."""
        problems = fault_reference_problem(spec, scenario, 'fault_id')
        state = spec.params.get('state')
        if state is not None and state not in {'active', 'inactive'}:
            problems.append(('state', f"{state!r} is not 'active' or 'inactive'"))
        return problems
