"""Fault changes asked from outside a running pass (a Foxglove parameter edit during `play`).

The asker's thread checks a change with the schema at once (`check_change`,
the same check as live parameters) and queues it; the pipeline applies
queued changes between two messages, at the bag time of the next one, as
`manual` fault events, so the output and the oracles see exactly when a
fault was switched.
"""

from __future__ import annotations

import queue
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from bagfault.errors import FieldValueError, InjectorConfigError
from bagfault.injectors.registry import get_injector_type

if TYPE_CHECKING:
    from bagfault.spec.model import Scenario


@dataclass(frozen=True)
class FaultChange:
    """Switch a fault (`key` None, `value` a bool) or set one config key."""

    fault_id: str
    key: str | None
    value: Any


def check_change(scenario: Scenario, fault_id: str, key: str | None, value: object) -> Any:
    """The value as it will be applied; FieldValueError with the schema's reason otherwise."""
    fault = scenario.fault(fault_id)
    if fault is None:
        raise FieldValueError(f'no fault {fault_id!r} (faults: {", ".join(f.id for f in scenario.faults) or "none"})')
    if key is None:
        if not isinstance(value, bool):
            raise FieldValueError(f'{fault_id}.active: {value!r} is not true or false')
        return value
    spec = scenario.injector(fault.injector_id)
    assert spec is not None
    cls = get_injector_type(spec.type)
    assert cls is not None
    schema_field = cls.field(key)
    if schema_field is None:
        raise FieldValueError(f'{key!r} is not a config key of injector type {spec.type!r}')
    coerced = schema_field.coerce(value)
    try:
        cls.check_fault({**fault.config, key: coerced}, spec.options)
    except InjectorConfigError as exc:
        raise FieldValueError(str(exc)) from None
    return coerced


class FaultControl:
    """A thread-safe queue of checked changes for one scenario."""

    def __init__(self, scenario: Scenario) -> None:
        self.scenario = scenario
        self._queue: queue.SimpleQueue[FaultChange] = queue.SimpleQueue()

    def ask(self, fault_id: str, key: str | None, value: object) -> Any:
        """Check and queue a change; returns the value as it will be applied."""
        checked = check_change(self.scenario, fault_id, key, value)
        self._queue.put(FaultChange(fault_id, key, checked))
        return checked

    def take(self) -> list[FaultChange]:
        """Every change queued so far, in order."""
        changes = []
        while True:
            try:
                changes.append(self._queue.get_nowait())
            except queue.Empty:
                return changes
