"""The one fault state of a run, and the one injection step.

`FaultState` holds what can change while a run goes: which faults are on
(its scheduler, set when a pass starts), the config values changed from
outside (a ROS parameter, a Foxglove edit, a reload), and builds the
injector instances from both. The loaded `Scenario` is never edited: a
changed value makes a new `FaultSpec` here (`dataclasses.replace`), and
whatever needs a fault's current config asks this state. The offline
pipeline, the live session, the fault controls and the Foxglove view all
change faults through it, under its lock (the view and ROS parameters ask
from other threads).

`inject` is the injection step both the pipeline and the live session run:
messages through an injector's active faults, and the `on_malformed` policy
for one that cannot take a fault (forward it untouched, drop it, or stop).
"""

from __future__ import annotations

import threading
from dataclasses import replace
from typing import TYPE_CHECKING, Any

from bagfault.engine.build import build_injector
from bagfault.errors import FieldValueError, InjectorConfigError, MalformedMessageError
from bagfault.events import FaultEvent
from bagfault.injectors.registry import get_injector_type

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

    from bagfault.engine.scheduler import FaultScheduler
    from bagfault.events import FaultSource
    from bagfault.faults.active import ActiveFault
    from bagfault.injectors.base import Injector, RawMessage
    from bagfault.io.types import TypeCatalog
    from bagfault.spec.model import FaultSpec, InjectorSpec, Scenario


def config_text(value: object) -> str:
    """A config value as the anchor writes it in event details ('true', '0.5')."""
    return ('true' if value else 'false') if isinstance(value, bool) else str(value)


class FaultState:
    """The scenario's faults as they are now: switched by the scheduler, changed from outside, built into
    injectors. Thread-safe: every method takes the state's lock."""

    def __init__(self, scenario: Scenario) -> None:
        self.scenario = scenario  # as loaded, never edited
        self.lock = threading.RLock()
        self._scheduler: FaultScheduler | None = None
        self.changed: dict[str, dict[str, Any]] = {}  # fault -> config values set while running
        self._specs: dict[str, FaultSpec] = {f.id: f for f in scenario.faults}

    @property
    def scheduler(self) -> FaultScheduler | None:
        """The pass's scheduler, once it started; its events describe the faults' current config."""
        return self._scheduler

    @scheduler.setter
    def scheduler(self, scheduler: FaultScheduler | None) -> None:
        if scheduler is not None:
            scheduler.current = self.fault
        self._scheduler = scheduler

    # -- reading ---------------------------------------------------------------------------
    def fault(self, fault_id: str) -> FaultSpec | None:
        """A fault with its current config."""
        with self.lock:
            return self._specs.get(fault_id)

    def faults(self) -> list[FaultSpec]:
        """Every fault with its current config, in file order."""
        with self.lock:
            return [self._specs[f.id] for f in self.scenario.faults]

    def faults_of(self, injector_id: str) -> list[FaultSpec]:
        """The faults of one injector with their current config, in file order."""
        with self.lock:
            return [self._specs[f.id] for f in self.scenario.faults_of(injector_id)]

    def active_of(self, injector_id: str) -> list[ActiveFault]:
        """The faults of one injector active now (none before the pass starts)."""
        with self.lock:
            if self.scheduler is None:
                return []
            return self.scheduler.active_of(self.faults_of(injector_id))

    def injector(self, spec: InjectorSpec, msgtype: str, catalog: TypeCatalog) -> Injector:
        """A new instance of an injector, compiled for its faults' current config."""
        with self.lock:
            return build_injector(spec, msgtype, self.faults_of(spec.id), catalog, self.scenario.name)

    # -- changing -------------------------------------------------------------------------------
    def check(self, fault_id: str, key: str | None, value: object) -> Any:
        """A change as it will be applied (a switch: `key` None and a bool); FieldValueError with the schema's
        reason otherwise. Checked against the fault's current config, as the injector will see it."""
        fault = self.fault(fault_id)
        if fault is None:
            names = ', '.join(f.id for f in self.scenario.faults) or 'none'
            raise FieldValueError(f'no fault {fault_id!r} (faults: {names})')
        if key is None:
            if not isinstance(value, bool):
                raise FieldValueError(f'{fault_id}.active: {value!r} is not true or false')
            return value
        spec = self.scenario.injector(fault.injector_id)
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

    def configure(self, fault_id: str, key: str, value: object) -> FaultSpec:
        """Set one config value (already checked); the fault as it is now."""
        with self.lock:
            fault = self._specs[fault_id]
            fault = replace(fault, config={**fault.config, key: value},
                            config_text={**fault.config_text, key: config_text(value)})
            self._specs[fault_id] = fault
            self.changed.setdefault(fault_id, {})[key] = value
            return fault

    def switch(self, fault_id: str, on: bool, time: int, source: FaultSource) -> FaultEvent | None:
        """Turn a fault on or off at `time`; the event, or None when it already was."""
        with self.lock:
            assert self.scheduler is not None
            return self.scheduler.set_state(fault_id, on, time, source)

    def start(self, origin: int, seed: int) -> list[FaultEvent]:
        """A live pass starts at bag time `origin`: its scheduler, and the events due then (startup faults)."""
        from bagfault.engine.scheduler import FaultScheduler  # noqa: PLC0415

        with self.lock:
            self.scheduler = FaultScheduler(self.scenario, origin, seed)
            return self.scheduler.advance(origin)

    def advance(self, now: int) -> list[FaultEvent]:
        """The scheduled changes due by `now`, applied; their events (none before the pass starts)."""
        with self.lock:
            if self.scheduler is None:
                return []
            due = self.scheduler.next_time()
            return self.scheduler.advance(now) if due is not None and due <= now else []

    @property
    def started(self) -> bool:
        """True once a pass started (a scheduler switches the faults)."""
        return self._scheduler is not None

    def active(self) -> dict[str, int]:
        """Faults on now, with the bag time each switched on (a copy)."""
        with self.lock:
            return dict(self.scheduler.active) if self.scheduler is not None else {}

    def reloaded(self, scenario: Scenario, now: int, seed: int,
                 manual: dict[str, bool]) -> tuple[FaultState, list[FaultEvent], list[str], dict[str, bool]]:
        """The state of a reloaded scenario at bag time `now`, what a live pass kept from this one.

        A config value set at run time stays unless the file now gives that key another value; a fault switched
        from outside (`manual`: fault -> state) keeps its state while that state still holds. Returns the new
        state, the events of the change (`reload`), what was kept ('fault.key=value') and the switches kept."""
        with self.lock:
            assert self.scheduler is not None
            old_active = set(self.scheduler.active)
            keep: dict[str, dict[str, Any]] = {}
            kept: list[str] = []
            for fault in scenario.faults:
                loaded = self.scenario.fault(fault.id)
                for key, value in self.changed.get(fault.id, {}).items():
                    if loaded is not None and fault.config.get(key) == loaded.config.get(key):
                        keep.setdefault(fault.id, {})[key] = value
                        kept.append(f'{fault.id}.{key}={value}')
            state = FaultState(scenario)
            for fault_id, values in keep.items():
                for key, value in values.items():
                    state.configure(fault_id, key, value)
            state.start(self.scheduler.origin, seed)
            assert state.scheduler is not None
            state.scheduler.advance(now)
            switched = {}
            for fault_id, on in manual.items():
                still = (fault_id in old_active) == on  # nothing has switched it since
                if still and scenario.fault(fault_id) is not None:
                    state.scheduler.set_state(fault_id, on, self.scheduler.active.get(fault_id, now), 'manual')
                    switched[fault_id] = on
                    kept.append(f'{fault_id}.active={"true" if on else "false"}')
            before = {f.id: f for f in self.faults()}
            events = [FaultEvent(now, f.id, f.injector_id, 'inactive', 'reload', f.describe_config())
                      for f in self.faults() if f.id in old_active and f.id not in state.scheduler.active]
            for fault in state.faults():
                old = before.get(fault.id)
                if old is None or old.config != fault.config:
                    events.append(FaultEvent(now, fault.id, fault.injector_id, 'config_updated', 'reload',
                                             fault.describe_config()))
                if fault.id in state.scheduler.active and fault.id not in old_active:
                    state.scheduler.active[fault.id] = now
                    events.append(FaultEvent(now, fault.id, fault.injector_id, 'active', 'reload',
                                             fault.describe_config()))
            return state, events, kept, switched


def inject(injector: Injector, active: Sequence[ActiveFault], messages: list[RawMessage], *, batch: bool,
           malformed: Callable[[RawMessage, str], str]) -> list[RawMessage]:
    """Messages through an injector's active faults (all at once when `batch`). One that cannot take a fault
    follows the injector's `on_malformed`: forwarded untouched, dropped, or (`error`) MalformedMessageError;
    `malformed(message, reason)` counts it and says where it was, for that error."""
    if not active and not injector.busy:
        if injector.tracks_history:
            injector.watch(messages)
        return messages
    if batch:
        try:
            return injector.process_batch(messages, active)
        except Exception:  # noqa: BLE001 - a message that cannot take the fault: judged one by one below
            pass
    policy = injector.spec.options.get('on_malformed', 'forward')
    out: list[RawMessage] = []
    for message in messages:
        try:
            out += injector.process(message, active)
        except Exception as exc:  # noqa: BLE001 - malformed data is the input's problem: the on_malformed policy
            reason = f'{type(exc).__name__}: {exc}'
            where = malformed(message, reason)
            if policy == 'error':
                raise MalformedMessageError(f'{where} cannot take the fault of injector {injector.spec.id!r} '
                                            f'({reason}); on_malformed is error') from None
            if policy != 'drop':
                out.append(message)
    return out
