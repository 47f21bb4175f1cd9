"""Fault changes asked from outside a running pass (a Foxglove parameter edit during `play`).

The asker's thread checks a change with the schema at once (`FaultState.check`,
the same check as live parameters) and queues it; the pipeline applies
queued changes between two messages, at the bag time of the next one, as
`manual` fault events, so the output and the oracles see exactly when a
fault was switched.
"""

from __future__ import annotations

import queue
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from bagfault.engine.fault_state import FaultState

if TYPE_CHECKING:
    from bagfault.spec.model import FaultSpec, Scenario


@dataclass(frozen=True)
class FaultChange:
    """Switch a fault (`key` None, `value` a bool) or set one config key."""

    fault_id: str
    key: str | None
    value: Any


class FaultControl:
    """A thread-safe queue of checked changes for the faults of one `FaultState` (which lasts across passes)."""

    def __init__(self, state: FaultState | Scenario) -> None:
        self.state = state if isinstance(state, FaultState) else FaultState(state)
        self.scenario = self.state.scenario
        self._queue: queue.SimpleQueue[FaultChange] = queue.SimpleQueue()

    def ask(self, fault_id: str, key: str | None, value: object) -> Any:
        """Check and queue a change; returns the value as it will be applied."""
        checked = self.state.check(fault_id, key, value)
        self._queue.put(FaultChange(fault_id, key, checked))
        return checked

    def fault(self, fault_id: str) -> FaultSpec | None:
        """The fault with its current config."""
        return self.state.fault(fault_id)

    def take(self) -> list[FaultChange]:
        """Every change queued so far, in order."""
        changes = []
        while True:
            try:
                changes.append(self._queue.get_nowait())
            except queue.Empty:
                return changes
