"""Assertion runner: every output record and fault event, in time order, on bag time.

Pending assertions stay internal. When one passes or fails the runner
emits an AssertionEvent at that bag time and a ScenarioStatus, and a last
ScenarioStatus at the end. Deadlines (`within`, from bag time zero) fire
exactly at their time: the pipeline calls the runner before it writes a
record, so a failure at 4.0 s lands before the first record after 4.0 s.
"""

from __future__ import annotations

import heapq
import itertools
from time import perf_counter_ns
from typing import TYPE_CHECKING, Any

from bagfault.assertions.base import FAILED, PASSED, PENDING, AssertionType
from bagfault.assertions.registry import ASSERTION_TYPES
from bagfault.errors import AssertionSetupError
from bagfault.events import AssertionEvent, FaultEvent, ScenarioStatus
from bagfault.units import NS

if TYPE_CHECKING:
    from collections.abc import Callable

    from bagfault.events import ScenarioState
    from bagfault.io.types import TypeCatalog
    from bagfault.spec.model import Scenario



class AssertionRunner:
    """Feeds assertions, keeps time, reports decisions through `emit`."""

    def __init__(
        self,
        scenario: Scenario,
        topics: dict[str, str],
        catalog: TypeCatalog,
        emit: Callable[[AssertionEvent | ScenarioStatus], None],
        fault_manager: Any = None,
    ) -> None:
        self.scenario = scenario
        self.topic_types = topics
        self.catalog = catalog
        self.emit = emit
        self.origin = 0
        self.now = 0
        self.fault_manager = fault_manager
        self.active: dict[str, int] = {}
        self.checks: list[AssertionType] = [ASSERTION_TYPES[a.type](a, self) for a in scenario.assertions]
        self.by_id = {c.spec.id: c for c in self.checks}
        self.events: list[AssertionEvent | ScenarioStatus] = []
        self._deadlines: list[tuple[int, int, AssertionType]] = []
        self._sequence = itertools.count()
        self._listeners: dict[str, list[AssertionType]] = {}
        self._codecs: dict[str, Any] = {}
        self.undecodable: dict[str, int] = {}  # topic -> messages the assertions could not decode (skipped)
        problems = []
        for check in self.checks:
            try:
                check.prepare()
            except AssertionSetupError as exc:
                problems.append(f'{scenario.name}: assertion {check.spec.id!r}: {exc}')
        if problems:
            raise AssertionSetupError('\n'.join(problems))
        for check in self.checks:
            for topic in check.topics():
                self._listeners.setdefault(topic, []).append(check)
            for topic in check.decoded_topics():
                if topic in topics and topic not in self._codecs:
                    codec = catalog.codec(topics[topic])
                    if codec is None:
                        raise AssertionSetupError(f'{scenario.name}: assertion {check.spec.id!r}: '
                                                  f'cannot decode {topics[topic]} '
                                          f'on {topic}: {catalog.why_not(topics[topic])}')
                    self._codecs[topic] = codec

    @property
    def topics(self) -> set[str]:
        """Topics any assertion listens to."""
        return set(self._listeners)

    def wanted_topics(self) -> set[str]:
        """Topics whose messages must pass through here (chunk copy skips the others; deadlines keep their
        times)."""
        return set(self._listeners)

    def t(self, time: int) -> str:
        """'12.345 s' from bag time zero."""
        return f'{(time - self.origin) / NS:.3f} s'

    def start(self, origin: int) -> None:
        """Bag time zero is known: arm deadlines."""
        self.origin = self.now = origin
        for check in self.checks:
            deadline = check.deadline()
            if deadline is not None:
                heapq.heappush(self._deadlines, (deadline, next(self._sequence), check))

    def advance(self, time: int) -> None:
        """Fire every deadline earlier than `time`."""
        deadlines = self._deadlines
        while deadlines and deadlines[0][0] < time:
            deadline, _, check = heapq.heappop(deadlines)
            if check.pending:
                self.now = deadline
                check.on_deadline(deadline)
        self.now = max(self.now, time)

    def schedule(self, check: AssertionType, deadline: int) -> None:
        """Arm a deadline found during the run (fault_status after a trigger)."""
        heapq.heappush(self._deadlines, (deadline, next(self._sequence), check))

    def on_fault_status(self, code: str, status: str, time: int) -> None:
        """The fault manager changed a status."""
        self.advance(time)
        for check in self.checks:
            if check.pending:
                check.on_fault_status(code, status, time)

    def on_event(self, event: FaultEvent) -> None:
        """A fault changed state."""
        self.advance(event.time)
        if event.state == 'active':
            self.active[event.fault_id] = event.time
        elif event.state == 'inactive':
            self.active.pop(event.fault_id, None)
        for check in self.checks:
            if check.pending:
                check.on_event(event)

    def on_message(self, topic: str, time: int, data: bytes | memoryview) -> None:
        """An output message."""
        if self._deadlines and self._deadlines[0][0] < time:
            self.advance(time)
        else:
            self.now = time
        listeners = self._listeners.get(topic)
        if not listeners:
            return
        codec = self._codecs.get(topic)
        message = data
        if codec is not None:
            try:
                message = codec.decode(data)
            except Exception:  # noqa: BLE001 - a malformed message cannot be judged: counted, not a verdict
                self.undecodable[topic] = self.undecodable.get(topic, 0) + 1
                return
        for check in listeners:
            if check.pending:
                began = perf_counter_ns()
                check.on_message(topic, time, message)
                check.result.wall_ns += perf_counter_ns() - began

    def decided(self, check: AssertionType) -> None:
        """Called by an assertion when it passes or fails."""
        result = check.result
        assert result.time is not None
        event = AssertionEvent(result.time, result.id, result.type, result.state, result.message)
        self.events.append(event)
        self.emit(event)
        for other in self.checks:
            if other is not check and other.pending:
                other.on_result(check)
        self._status(result.time)

    def _status(self, time: int) -> None:
        results = [c.result for c in self.checks]
        failed = [r for r in results if r.state == FAILED]
        pending = sum(r.state == PENDING for r in results)
        state: ScenarioState = 'failed' if failed else 'running' if pending else 'passed'
        status = ScenarioStatus(
            time=time, state=state, pending_count=pending,
            passed_count=sum(r.state == PASSED for r in results), failed_count=len(failed),
            failed_assertion_ids=[r.id for r in failed], failed_messages=[r.message for r in failed],
        )
        self.events.append(status)
        self.emit(status)

    def finish(self, time: int) -> None:
        """End of input: fire remaining deadlines, fail what is still pending, final status."""
        self.advance(time + 1)
        self.now = time
        for check in self.checks:
            if check.pending:
                check.finish(time)
        if self.checks:
            self._status(time)

    @property
    def results(self) -> list[Any]:
        """One result per assertion, in scenario order."""
        return [c.result for c in self.checks]

    @property
    def failed(self) -> bool:
        """True when any assertion failed."""
        return any(c.result.state == FAILED for c in self.checks)
