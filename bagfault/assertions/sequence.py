"""`sequence`: other assertions must pass in the given order."""

from __future__ import annotations

import itertools
from typing import TYPE_CHECKING, ClassVar

from bagfault.assertions.base import FAILED, PASSED, AssertionType
from bagfault.schema import Key
from bagfault.units import NS

if TYPE_CHECKING:
    from bagfault.spec.model import AssertionSpec, Scenario


class SequenceAssertion(AssertionType):
    """Passes when every step passed, each no earlier than the one before."""

    type_name = 'sequence'
    description = 'A list of other assertions must pass in the given order (before `within`, if given).'
    fields: ClassVar[tuple[Key, ...]] = (
        Key('steps', 'list', 'Assertion ids, in the order they must pass.', required=True),
    )

    @classmethod
    def check(cls, spec: AssertionSpec, scenario: Scenario) -> list[tuple[str, str]]:
        """Steps are known assertion ids, at least two, no self reference or cycle."""
        steps = spec.params.get('steps')
        if not isinstance(steps, list):
            return []
        ids = {a.id: a for a in scenario.assertions}
        problems = []
        if len(steps) < 2:
            problems.append(('steps', 'a sequence needs at least two steps'))
        for step in steps:
            if not isinstance(step, str) or step not in ids:
                problems.append(('steps', f'unknown assertion {step!r}'))
            elif step == spec.id:
                problems.append(('steps', 'a sequence cannot contain itself'))
            elif _reaches(ids, step, spec.id, set()):
                problems.append(('steps', f'{step!r} contains this sequence: loop'))
        return problems

    def steps(self) -> list[AssertionType]:
        """The step assertions."""
        return [self.runner.by_id[s] for s in self.params['steps']]

    def on_result(self, other: AssertionType) -> None:
        """Re-judge the order whenever a step decides."""
        if other.spec.id not in self.params['steps']:
            return
        now = other.result.time
        assert now is not None
        steps = self.steps()

        def at(step: AssertionType) -> int:
            assert step.result.time is not None  # decided steps have a time
            return step.result.time

        for number, step in enumerate(steps):
            result = step.result
            if result.state == FAILED:
                self.fail(now, f'step {step.spec.id} failed: {result.message}')
                return
            if result.state != PASSED:
                later = [s for s in steps[number + 1:] if s.result.state == PASSED]
                if later:
                    self.fail(now, f'step {later[0].spec.id} passed at {self.runner.t(at(later[0]))} before '
                                   f'step {step.spec.id}')
                return
            if number and at(step) < at(steps[number - 1]):
                self.fail(now, f'step {step.spec.id} passed at {self.runner.t(at(step))}, before step '
                               f'{steps[number - 1].spec.id} at {self.runner.t(at(steps[number - 1]))}')
                return
        spare = min((at(b) - at(a)) / NS for a, b in itertools.pairwise(steps))  # the closest two steps came
        self.passed(now, 'steps passed in order: ' + ', '.join(
            f'{s.spec.id} ({self.runner.t(at(s))})' for s in steps), margin=spare, margin_unit='s')

    def waiting_for(self) -> str:
        """Failure text."""
        return f"sequence {' -> '.join(self.params['steps'])} did not complete"


def _reaches(ids: dict[str, AssertionSpec], start: str, target: str, seen: set[str]) -> bool:
    spec = ids.get(start)
    if spec is None or spec.type != 'sequence' or start in seen:
        return False
    seen.add(start)
    steps = spec.params.get('steps') or []
    return target in steps or any(_reaches(ids, s, target, seen) for s in steps if isinstance(s, str))
