"""`fault_event`: a named fault reaches `active` or `inactive` (anchor meaning)."""

from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar

from bagfault.assertions.base import TICK, AssertionType, fault_reference_problem
from bagfault.schema import Key
from bagfault.units import NS

if TYPE_CHECKING:
    from bagfault.events import FaultEvent
    from bagfault.spec.model import AssertionSpec, Scenario


class FaultEventAssertion(AssertionType):
    """Passes at the first matching fault event."""

    type_name = 'fault_event'
    description = 'A named fault reaches state active or inactive (before `within`, if given).'
    fields: ClassVar[tuple[Key, ...]] = (
        Key('fault_id', 'non_empty_string', 'Fault to watch.', required=True),
        Key('state', 'non_empty_string', 'Expected state: active or inactive.', required=True),
    )

    @classmethod
    def check(cls, spec: AssertionSpec, scenario: Scenario) -> list[tuple[str, str]]:
        """fault_id must exist, state must be active or inactive."""
        problems = fault_reference_problem(spec, scenario, 'fault_id')
        state = spec.params.get('state')
        if state is not None and state not in {'active', 'inactive'}:
            problems.append(('state', f"{state!r} is not 'active' or 'inactive'"))
        return problems

    def deadline(self) -> int | None:
        """The anchor's 100 ms look that first finds `within` passed (fault_assertion_runner.cpp's timer calls
        update(elapsed), which fails only when elapsed > within): an event between `within` and that look
        still passes, as in the anchor."""
        if self.spec.within is None:
            return None
        within = round(self.spec.within * NS)
        return self.runner.origin + (within // TICK + 1) * TICK

    def on_event(self, event: FaultEvent) -> None:
        """Pass when the watched fault reaches the expected state."""
        if event.fault_id == self.params['fault_id'] and event.state == self.params['state']:
            seconds = (event.time - self.runner.origin) / NS
            self.passed(event.time, f'fault {event.fault_id} reached {event.state} at {self.runner.t(event.time)} '
                                    f'({event.source})', seconds, 's',
                        margin=None if self.spec.within is None else self.spec.within - seconds)

    def waiting_for(self) -> str:
        """Failure text."""
        return f"fault {self.params['fault_id']} did not reach {self.params['state']}"
