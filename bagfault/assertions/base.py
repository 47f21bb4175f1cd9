"""Assertion type base: declared keys, checks before the run, and the runtime contract.

At run time each assertion is an instance fed by the runner, in time
order, with fault events and output messages of the topics it names. It
decides once: `passed` or `failed`, at a bag time, with a message that
names that time and what was observed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar, Final

from bagfault.schema import Key
from bagfault.units import NS

if TYPE_CHECKING:
    from bagfault.assertions.runner import AssertionRunner
    from bagfault.events import AssertionState, FaultEvent
    from bagfault.spec.model import AssertionSpec, Scenario

PENDING: Final = 'pending'
PASSED: Final = 'passed'
FAILED: Final = 'failed'
END_OF_BAG = 'not observed before the end of the bag'


@dataclass
class AssertionResult:
    """Outcome of one assertion."""

    id: str
    type: str
    state: AssertionState = PENDING
    time: int | None = None
    message: str = ''
    value: float | None = None  # what was measured, in the assertion's own unit (see `unit`)
    unit: str = ''
    # how far from failing, in `margin_unit`: positive passed with that much to spare, negative failed by that
    # much, None where the verdict has no distance (a crash, a sequence out of order, a type never seen)
    margin: float | None = None
    margin_unit: str = ''
    wall_ns: int = 0  # wall time spent evaluating it (JUnit's testcase time)

TICK = 100_000_000  # ns: the anchor's assertion timer (fault_assertion_runner.cpp), looks every 100 ms


class AssertionType:
    """One assertion type: its keys (besides id, type, within), its checks, its runtime."""

    type_name: ClassVar[str] = ''
    description: ClassVar[str] = ''
    fields: ClassVar[tuple[Key, ...]] = ()
    takes_within: ClassVar[bool] = True

    # -- before the run -----------------------------------------------------
    @classmethod
    def check(cls, spec: AssertionSpec, scenario: Scenario) -> list[tuple[str, str]]:
        """Semantic problems as (key, message) pairs; key '' means the assertion itself."""
        return []

    @classmethod
    def field(cls, key: str) -> Key | None:
        """Schema entry for a key."""
        return next((x for x in cls.fields if x.name == key), None)

    # -- runtime --------------------------------------------------------------
    def __init__(self, spec: AssertionSpec, runner: AssertionRunner) -> None:
        self.spec = spec
        self.runner = runner
        self.params = spec.params
        self.result = AssertionResult(spec.id, spec.type)

    @property
    def pending(self) -> bool:
        """True until the assertion has decided."""
        return self.result.state == PENDING

    def topics(self) -> set[str]:
        """Output topics whose messages this assertion needs."""
        return set()

    def decoded_topics(self) -> set[str]:
        """Topics whose messages must be decoded for this assertion."""
        return set()

    def prepare(self) -> None:
        """Check against the output's topics and types once they are known; raise AssertionSetupError."""

    def deadline(self) -> int | None:
        """Bag time (ns) after which a pending assertion fails."""
        if self.spec.within is None or not self.takes_within:
            return None
        return self.runner.origin + round(self.spec.within * NS)

    def on_event(self, event: FaultEvent) -> None:
        """A fault event (the runner already updated the active fault set)."""

    def on_message(self, topic: str, time: int, message: Any) -> None:
        """A message on one of `topics()` (decoded if in `decoded_topics()`, else raw bytes)."""

    def on_deadline(self, time: int) -> None:
        """The `within` deadline passed while pending."""
        self.fail(time, f'{self.waiting_for()} within {self.spec.within:g} s (deadline {self.runner.t(time)})')

    def on_fault_status(self, code: str, status: str, time: int) -> None:
        """The fault manager oracle changed a fault's status."""

    def on_result(self, other: AssertionType) -> None:
        """Another assertion decided (for `sequence`)."""

    def finish(self, time: int) -> None:
        """End of the bag while still pending."""
        self.fail(time, f'{self.waiting_for()}: {END_OF_BAG}')

    def waiting_for(self) -> str:
        """What the assertion waits for, for failure messages."""
        return f'{self.spec.type} {self.spec.id}'

    # -- decisions ------------------------------------------------------------
    def passed(self, time: int, message: str, value: float | None = None, unit: str = '',
               margin: float | None = None, margin_unit: str | None = None) -> None:
        """Decide: passed at `time`, having measured `value` (campaigns tabulate it), `margin` from failing (in
        `margin_unit`, default `unit`)."""
        if self.pending:
            self.result.state, self.result.time, self.result.message = PASSED, time, message
            self._measured(value, unit, margin, margin_unit)
            self.runner.decided(self)

    def fail(self, time: int, message: str, value: float | None = None, unit: str = '',
             margin: float | None = None, margin_unit: str | None = None) -> None:
        """Decide: failed at `time`, having measured `value`, `margin` past failing (0 or negative)."""
        if self.pending:
            self.result.state, self.result.time, self.result.message = FAILED, time, message
            self._measured(value, unit, margin, margin_unit)
            self.runner.decided(self)

    def _measured(self, value: float | None, unit: str, margin: float | None, margin_unit: str | None) -> None:
        result = self.result
        result.value = value if value is None or math.isfinite(value) else None  # (nan, inf: said in the message)
        result.unit = unit
        if margin is not None and math.isfinite(margin):
            result.margin, result.margin_unit = float(margin), unit if margin_unit is None else margin_unit


def fault_reference_problem(
    spec: AssertionSpec,
    scenario: Scenario,
    key: str,
) -> list[tuple[str, str]]:
    """Problem list for a key that must name a fault of the scenario."""
    value: Any = spec.params.get(key)
    if value is None or scenario.fault(str(value)) is not None or str(value) in scenario.skipped_faults:
        return []  # (a skipped fault was named where its injector was: it never activates, as in the anchor)
    if scenario.explore is not None and str(value) in scenario.explore.ids:
        return []  # a candidate of the explore space: judged in the runs that draw it
    ids = [f.id for f in scenario.faults] + ([f.id for f in scenario.explore.faults] if scenario.explore else [])
    known = ', '.join(dict.fromkeys(ids)) or 'none'
    return [(key, f'unknown fault {value!r} (faults: {known})')]


def window_problems(spec: AssertionSpec, scenario: Scenario) -> list[tuple[str, str]]:
    """`during` and `outside` must name faults and cannot both be given."""
    problems = fault_reference_problem(spec, scenario, 'during') + fault_reference_problem(spec, scenario, 'outside')
    if 'during' in spec.params and 'outside' in spec.params:
        problems.append(('outside', "give either 'during' or 'outside', not both"))
    return problems


def range_problems(spec: AssertionSpec, low: str = 'min', high: str = 'max') -> list[tuple[str, str]]:
    """min <= max when both are given."""
    params = spec.params
    if low in params and high in params and params[low] > params[high]:
        return [(high, f'{params[high]} is below {low} {params[low]}')]
    return []
