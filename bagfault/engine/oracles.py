"""The observers that judge a run: the fault manager oracle first, then the assertion runner."""

from __future__ import annotations

from typing import TYPE_CHECKING

from bagfault.assertions.runner import AssertionRunner
from bagfault.events import AssertionEvent, FaultEvent, ScenarioStatus
from bagfault.fault_manager.model import FaultManagerEvent

if TYPE_CHECKING:
    from collections.abc import Callable, Mapping
    from pathlib import Path

    from bagfault.engine.result import RunResult
    from bagfault.engine.run import Observer
    from bagfault.events import Event, EventKind
    from bagfault.fault_manager.observer import FaultManagerObserver
    from bagfault.io.types import TypeCatalog
    from bagfault.spec.model import Scenario

Schema = tuple[str, str, str]  # msgtype, schema encoding, schema text


class Oracles:
    """Fault manager and assertion runner of one pass, and the event kinds they write."""

    def __init__(self, scenario: Scenario, schemas: Mapping[str, Schema], catalog: TypeCatalog,
                 emit: Callable[[Event], None], blackbox_base: Path | None = None,
                 blackbox_numbers: dict[str, int] | None = None) -> None:
        manager = scenario.fault_manager_config
        kinds: list[EventKind] = [FaultManagerEvent] if manager is not None else []
        if scenario.assertions:
            kinds += [AssertionEvent, ScenarioStatus]
        every: list[EventKind] = [FaultEvent, *kinds] if scenario.assertions else kinds
        for kind in every:  # every definition before the first codec: the codecs then come of one build
            catalog.add_definition(kind.msgtype, kind.definition)
        self.fault_manager: FaultManagerObserver | None = None
        if manager is not None:
            from bagfault.fault_manager.observer import FaultManagerObserver  # noqa: PLC0415 - only when used

            self.fault_manager = FaultManagerObserver(manager, scenario, dict(schemas), catalog, emit, blackbox_base,
                                                      blackbox_numbers)
        self.runner: AssertionRunner | None = None
        if scenario.assertions:
            topics = {topic: entry[0] for topic, entry in schemas.items()}
            topics.update({kind.topic: kind.msgtype for kind in every})
            self.runner = AssertionRunner(scenario, topics, catalog, emit, self.fault_manager)
            if self.fault_manager is not None:
                self.fault_manager.status_listeners.append(self.runner.on_fault_status)
        self.event_kinds: list[EventKind] = kinds
        self.observers: list[Observer] = [o for o in (self.fault_manager, self.runner) if o is not None]

    def publish(self) -> None:
        """The output is complete: black boxes take their names."""
        if self.fault_manager is not None:
            self.fault_manager.snapshots.publish()

    def discard(self) -> None:
        """The run failed: remove black boxes."""
        if self.fault_manager is not None:
            self.fault_manager.snapshots.discard()

    def fill(self, result: RunResult) -> None:
        """Copy verdicts and the fault table into a result."""
        if self.runner is not None:
            result.assertions, result.assertion_events = self.runner.results, self.runner.events
        if self.fault_manager is not None:
            result.fault_manager = self.fault_manager.summary()
        for who, observer in (('the assertions', self.runner), ('the fault manager', self.fault_manager)):
            for topic, count in sorted(getattr(observer, 'undecodable', {}).items()):
                result.notes.append(f'{count} message{"s" if count != 1 else ""} on {topic} could not be decoded; '
                                    f'{who} skipped them')
