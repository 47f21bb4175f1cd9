"""`fault_status` and `fault_count`: what the fault manager oracle concluded, and when."""

from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar

from bagfault.assertions.base import AssertionType, fault_reference_problem, range_problems
from bagfault.errors import AssertionSetupError
from bagfault.fault_manager.model import STATUSES, valid_code
from bagfault.schema import Key
from bagfault.units import NS

if TYPE_CHECKING:
    from bagfault.assertions.runner import AssertionRunner
    from bagfault.events import FaultEvent
    from bagfault.spec.model import AssertionSpec, Scenario



class FaultStatusAssertion(AssertionType):
    """A fault code reaches a status within `within` s after a scenario fault activates (or never does)."""

    type_name = 'fault_status'
    description = ('A fault code reaches PREFAILED/CONFIRMED/HEALED/CLEARED within `within` s after the fault '
                   '`after` activates (from time zero without `after`), or `never` does. A status that already '
                   'held when `after` activated is no detection: the assertion fails, naming when it began.')
    fields: ClassVar[tuple[Key, ...]] = (
        Key('code', 'non_empty_string', 'Fault code in the fault manager.', required=True),
        Key('status', 'non_empty_string', 'PREFAILED, PREPASSED, CONFIRMED, HEALED or CLEARED.',
                    required=True),
        Key('after', 'non_empty_string', 'Scenario fault whose activation starts the clock.'),
        Key('never', 'boolean', 'Passes when the status is never reached (after the trigger, if given).'),
    )

    @classmethod
    def check(cls, spec: AssertionSpec, scenario: Scenario) -> list[tuple[str, str]]:
        """Known status, valid code, known trigger fault, never without within."""
        params = spec.params
        problems = fault_reference_problem(spec, scenario, 'after')
        if params.get('status') not in STATUSES:
            problems.append(('status', f"{params.get('status')!r} is not one of {', '.join(STATUSES)}"))
        if not valid_code(str(params.get('code', ''))):
            problems.append(('code', f"{params.get('code')!r} is not a fault code"))
        if params.get('never') and spec.within is not None:
            problems.append(('never', 'never and within exclude each other'))
        return problems

    def __init__(self, spec: AssertionSpec, runner: AssertionRunner) -> None:
        super().__init__(spec, runner)
        self.armed: int | None = None
        self.held_since: int | None = None  # when the code last reached the status, while it still holds

    def prepare(self) -> None:
        """Needs the fault manager."""
        if self.runner.fault_manager is None:
            raise AssertionSetupError('fault_status needs the fault manager (add a fault_manager section or a report)')

    def deadline(self) -> int | None:
        """From time zero without `after`; armed at the trigger otherwise."""
        return None if 'after' in self.params else super().deadline()

    def start_clock(self, time: int) -> None:
        """The trigger fault activated."""
        self.armed = time
        fault = self.runner.fault_manager.manager.faults.get(self.params['code'])
        if fault is not None and fault.status == self.params['status']:
            # a detection is a transition after its cause: a status that already held is none
            since = self.held_since if self.held_since is not None else fault.first_occurred
            text = (f"{self.params['code']} was already {self.params['status']} at {self.runner.t(since)}, "
                    f"before {self.params['after']} activated at {self.runner.t(time)}")
            self.fail(time, text, (since - time) / NS, 's')
        elif self.spec.within is not None and self.pending:
            self.runner.schedule(self, time + round(self.spec.within * NS))

    def on_event(self, event: FaultEvent) -> None:
        """Arm at the first activation of the trigger fault."""
        if self.armed is None and event.fault_id == self.params.get('after') and event.state == 'active':
            self.start_clock(event.time)

    def on_fault_status(self, code: str, status: str, time: int) -> None:
        """The fault manager changed a status."""
        if code != self.params['code']:
            return
        if status != self.params['status']:
            self.held_since = None
            return
        if 'after' in self.params and self.armed is None:
            self.held_since = time
            return
        since = f", {(time - self.armed) / NS:.3f} s after {self.params['after']} activated" if self.armed else ''
        text = f'{code} reached {status} at {self.runner.t(time)}{since}'
        seconds = (time - (self.armed if self.armed is not None else self.runner.origin)) / NS
        if self.params.get('never'):
            self.fail(time, text, seconds, 's')
        else:
            spare = None if self.spec.within is None else self.spec.within - seconds
            self.passed(time, text, seconds, 's', margin=spare)

    def on_deadline(self, time: int) -> None:
        """Not reached in time."""
        fault = self.runner.fault_manager.manager.faults.get(self.params['code'])
        seen = f' (status {fault.status})' if fault else ' (never reported)'
        after = f" after {self.params['after']} activated at {self.runner.t(self.armed)}" if self.armed else ''
        self.fail(time, f"{self.params['code']} did not reach {self.params['status']} within "
                        f'{self.spec.within:g} s{after}{seen}')

    def finish(self, time: int) -> None:
        """never passes at the end; otherwise the reason it was not reached."""
        if self.params.get('never'):
            self.passed(time, f"{self.params['code']} never reached {self.params['status']}")
        elif 'after' in self.params and self.armed is None:
            self.fail(time, f"fault {self.params['after']} never activated: not observed before the end of the bag")
        else:
            super().finish(time)

    def waiting_for(self) -> str:
        """Failure text."""
        return f"{self.params['code']} did not reach {self.params['status']}"


class FaultCountAssertion(AssertionType):
    """The number of CONFIRMED faults at the end of the bag is within [min, max]."""

    type_name = 'fault_count'
    description = 'Number of CONFIRMED faults at the end of the bag within [min, max] (muted ones optional).'
    fields: ClassVar[tuple[Key, ...]] = (
        Key('min', 'integer', 'Fewest confirmed faults.', minimum=0),
        Key('max', 'integer', 'Most confirmed faults.', minimum=0),
        Key('exclude_muted', 'boolean', 'Leave out muted (correlated) faults.'),
    )
    takes_within = False

    @classmethod
    def check(cls, spec: AssertionSpec, scenario: Scenario) -> list[tuple[str, str]]:
        """Needs min or max."""
        problems = range_problems(spec)
        if not {'min', 'max'} & set(spec.params):
            problems.append(('', "give 'min' and/or 'max'"))
        return problems

    def prepare(self) -> None:
        """Needs the fault manager."""
        if self.runner.fault_manager is None:
            raise AssertionSetupError('fault_count needs the fault manager (add a fault_manager section or a report)')

    def finish(self, time: int) -> None:
        """Count and decide."""
        result = self.runner.fault_manager.manager.list_faults(include_muted=not self.params.get('exclude_muted'))
        codes = sorted(f.fault_code for f in result.faults)
        low, high = self.params.get('min', 0), self.params.get('max')
        text = f'{len(codes)} confirmed faults at {self.runner.t(time)}: {", ".join(codes) or "none"}'
        room = float(min(len(codes) - low, *([high - len(codes)] if high is not None else [])))
        if len(codes) < low or (high is not None and len(codes) > high):
            self.fail(time, f'{text}; expected [{low}, {high if high is not None else "inf"}]', len(codes), 'faults',
                      margin=room)
        else:
            self.passed(time, text, len(codes), 'faults', margin=room)


