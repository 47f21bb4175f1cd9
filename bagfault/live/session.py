"""A live session: the offline fault state, injectors and run loop (oracles, sink) on a live clock.

No rclpy here. The proxy node hands each received message (serialized
bytes) with the ROS time to `receive`, publishes what comes back (now, or
later for delayed messages) and reports every publication to `sent`. Fault
switches, config changes and reloads come from parameters and services.
Everything runs under one lock, with the time read inside it, so the
recording and the oracles see one time-ordered stream, as offline.
"""

from __future__ import annotations

import copy
import json
import threading
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

from bagfault.engine.fault_state import FaultState, inject
from bagfault.engine.run import NullSink, Run
from bagfault.errors import (
    EngineError,
    LiveError,
    ReloadError,
)
from bagfault.events import FaultEvent
from bagfault.faults.active import ActiveFault
from bagfault.injectors.base import Injector, RawMessage
from bagfault.spec.model import describe_config_update

if TYPE_CHECKING:
    from collections.abc import Callable
    from pathlib import Path

    from bagfault.engine.result import RunStats
    from bagfault.engine.run import OutputChannel, Sink
    from bagfault.events import FaultSource
    from bagfault.io.types import TypeCatalog
    from bagfault.spec.model import InjectorSpec, Scenario


SERVICE_CALLS_TOPIC = '/bagfault/service_calls'  # JSON of each call through a service injector


@dataclass(eq=False)
class LiveTopic:
    """A topic injector wired for live mode, with its counters."""

    spec: InjectorSpec
    msgtype: str
    injector: Injector
    active: list[ActiveFault] = field(default_factory=list)
    received: int = 0
    forwarded: int = 0
    malformed: int = 0
    last_error: str = ''

    @property
    def input_topic(self) -> str:
        """Topic the proxy subscribes to."""
        assert self.spec.input_topic is not None
        return self.spec.input_topic

    @property
    def output_topic(self) -> str:
        """Topic the proxy publishes on."""
        assert self.spec.output_topic is not None
        return self.spec.output_topic


@dataclass(frozen=True)
class FaultStatus:
    """What /diagnostics and the parameters show of one fault."""

    fault_id: str
    injector_id: str
    active: bool
    config: dict[str, Any]


def _layout(scenario: Scenario) -> list[tuple[Any, ...]]:
    """What a reload may not change: injector ids, types, endpoints, QoS."""
    return [
        (i.id, i.type, i.input_topic, i.output_topic, i.qos_depth, i.proxy_service, i.target_service,
         sorted((k, repr(v)) for k, v in i.options.items()))
        for i in scenario.injectors
    ]


class LiveSession:
    """A proxy's run loop over the one fault state (engine/fault_state.py); thread-safe."""

    def __init__(
        self,
        scenario: Scenario,
        catalog: TypeCatalog,
        types: dict[str, str],
        clock: Callable[[], int],
        *,
        seed: int,
        sink: Sink | None = None,
        blackbox_base: Path | None = None,
        observed: dict[str, str] | None = None,
        offers: Callable[[str], dict[str, str] | None] | None = None,
    ) -> None:
        self.state = FaultState(scenario)  # the loaded scenario stays as the file says (reloads compare with it)
        self.catalog = catalog
        self.clock = clock
        self.seed = seed
        self.lock = threading.RLock()
        self.manual: dict[str, bool] = {}  # fault -> state last set at run time (parameter, service)
        self.listeners: list[Callable[[list[FaultEvent]], None]] = []
        self.topics: list[LiveTopic] = []
        catalog.add_definition(FaultEvent.msgtype, FaultEvent.definition)
        for spec in scenario.injectors:
            if spec.is_service:
                continue
            msgtype = types[spec.id]
            self.topics.append(LiveTopic(spec, msgtype, self._build(spec, msgtype)))
        self.observed = dict(observed or {})
        schemas = {}
        for name, msgtype in self.observed.items():
            schemas[name] = (msgtype, *catalog.schema(msgtype))
        for topic in self.topics:
            schemas[topic.input_topic] = schemas[topic.output_topic] = (topic.msgtype, *catalog.schema(topic.msgtype))
        self.run = Run(scenario, sink if sink is not None else NullSink(), catalog, schemas,
                       blackbox_base=blackbox_base)
        self.run.event_channel(FaultEvent)
        # a topic's channel is registered with its first message, when its publishers are known: the recording
        # keeps the QoS they offer and their type hash (`offers`), as `bagfault record` does
        self.offers = offers if offers is not None else lambda topic: None
        self._calls: OutputChannel | None = None
        self._string: Any = None

    def _channel(self, topic: str, msgtype: str) -> OutputChannel:
        """The run's channel of a topic, registered at its first use with what its publishers offer."""
        return self.run.channel(topic, msgtype, self.offers(topic))

    def register_channels(self) -> None:
        """Every topic's channel, those without a message too (before the recording is finished)."""
        with self.lock:
            for topic in self.topics:
                self._channel(topic.input_topic, topic.msgtype)
                self._channel(topic.output_topic, topic.msgtype)
            for name, msgtype in self.observed.items():
                self._channel(name, msgtype)

    @property
    def scenario(self) -> Scenario:
        """The scenario as loaded (or reloaded); its faults' current config is the state's."""
        return self.state.scenario

    @property
    def stats(self) -> RunStats:
        """Counts and times of the session so far."""
        return self.run.stats

    # -- wiring -------------------------------------------------------------------
    def _build(self, spec: InjectorSpec, msgtype: str) -> Injector:
        return self.state.injector(spec, msgtype, self.catalog)

    def _refresh_active(self) -> None:
        assert self.state.started
        for topic in self.topics:
            topic.active = self.state.active_of(topic.spec.id)

    def _publish_events(self, events: list[FaultEvent]) -> None:
        if not events:
            return
        self._refresh_active()
        for event in events:
            self.run.event(event)
        for listener in self.listeners:
            listener(events)

    # -- clock ------------------------------------------------------------------------
    def start(self) -> None:
        """Bag time zero is now: scheduler origin, startup faults, oracles."""
        with self.lock:
            now = self.clock()
            self.run.begin(now)
            self._publish_events(self.state.start(now, self.seed))
            self._refresh_active()

    @property
    def started(self) -> bool:
        """True after `start`."""
        return self.state.started

    def advance(self) -> None:
        """Apply scheduled changes due by now."""
        with self.lock:
            self._publish_events(self.state.advance(self.clock()))

    # -- messages ---------------------------------------------------------------------
    def receive(self, topic: LiveTopic, data: bytes) -> list[RawMessage]:
        """A message arrived on the input topic: record it and return what to publish, with due times."""
        with self.lock:
            now = self.clock()
            self._publish_events(self.state.advance(now))
            topic.received += 1
            self.run.read(1, now)
            self.run.message(self._channel(topic.input_topic, topic.msgtype), now, now, data)
            message = RawMessage(now, now, data, topic.received)

            def malformed(_message: RawMessage, reason: str) -> str:
                topic.malformed += 1
                topic.last_error = reason
                self.run.stats.malformed[topic.input_topic] = topic.malformed
                self.run.stats.malformed_first.setdefault(topic.input_topic, (now, reason))
                return f'{topic.input_topic}: a message'

            return inject(topic.injector, topic.active, [message], batch=False, malformed=malformed)

    def sent(self, topic: LiveTopic, data: bytes | memoryview) -> int:
        """A message was published on the output topic: record and observe it; return its time."""
        with self.lock:
            now = self.clock()
            topic.forwarded += 1
            self.run.message(self._channel(topic.output_topic, topic.msgtype), now, now, data)
            return now

    def observe(self, name: str, data: bytes) -> None:
        """A message on a topic the oracles watch (the system under test's /diagnostics, an asserted topic)."""
        with self.lock:
            now = self.clock()
            self.run.read(1, now)
            self.run.message(self._channel(name, self.observed[name]), now, now, data)

    def service_call(self, service: str, target: str, outcome: str, success: bool, message: str,
                     delay_ms: int) -> None:
        """A call through a service injector, kept in the run (recording) on /bagfault/service_calls as JSON:
        which service, what happened (forwarded, forced_failure, unavailable, timeout), the answer."""
        with self.lock:
            now = self.clock()
            if self._calls is None:
                self._calls = self.run.channel(SERVICE_CALLS_TOPIC, 'std_msgs/msg/String')
                self._string = self.catalog.codec('std_msgs/msg/String')
            assert self._string is not None
            text = json.dumps({'service': service, 'target': target, 'outcome': outcome, 'success': success,
                               'message': message, 'delay_ms': delay_ms}, sort_keys=True)
            data = self._string.encode(self._string.store.types['std_msgs/msg/String'](data=text))
            self.run.message(self._calls, now, now, data)

    # -- runtime control --------------------------------------------------------------
    def set_active(self, fault_id: str, active: bool, source: FaultSource = 'manual') -> None:
        """Switch a fault on or off now (a parameter or service call)."""
        with self.lock:
            if not self.state.started:
                raise LiveError('the proxy has not started yet')
            if self.state.fault(fault_id) is None:
                raise LiveError(f'no fault {fault_id!r}')
            event = self.state.switch(fault_id, active, self.clock(), source)
            if source == 'manual':
                self.manual[fault_id] = active
            self._publish_events([event] if event is not None else [])

    def check_config(self, fault_id: str, key: str, value: object) -> Any:
        """The value as the schema accepts it; FieldValueError with the schema's reason otherwise."""
        return self.state.check(fault_id, key, value)

    def set_config(self, fault_id: str, key: str, value: object) -> list[tuple[LiveTopic, RawMessage]]:
        """Change one config value now; a `config_updated` event; returns messages the old injector held."""
        with self.lock:
            coerced = self.check_config(fault_id, key, value)
            fault = self.state.configure(fault_id, key, coerced)
            held = self._rebuild(fault.injector_id)
            event = FaultEvent(self.clock(), fault.id, fault.injector_id, 'config_updated', 'manual',
                               describe_config_update(key, fault.config_text[key]))
            self._publish_events([event])
            return held

    def _rebuild(self, injector_id: str) -> list[tuple[LiveTopic, RawMessage]]:
        """New injector instance for changed faults (injectors compile their faults); flush the old one."""
        held: list[tuple[LiveTopic, RawMessage]] = []
        for topic in self.topics:
            if topic.spec.id == injector_id:
                held += [(topic, m) for m in topic.injector.flush(self.clock())]
                topic.injector = self._build(topic.spec, topic.msgtype)
        return held

    def reload(self, scenario: Scenario) -> tuple[list[tuple[LiveTopic, RawMessage]], list[str]]:
        """Take new fault definitions; the injector layout must stay as it is (anchor's rules).

        What was changed at run time survives where the file did not change it (FaultState.reloaded).
        Returns the messages old injectors held and what was kept.
        """
        with self.lock:
            if _layout(scenario) != _layout(self.scenario):
                raise ReloadError('reload rejected: injector ids, types, endpoints, QoS and count must stay the same')
            if not self.state.started:
                raise ReloadError('reload rejected: the proxy has not started yet')
            previous = self.state
            state, events, kept, manual = previous.reloaded(scenario, self.clock(), self.seed, self.manual)
            self.state = state
            try:
                held = [item for topic in self.topics for item in self._rebuild(topic.spec.id)]
            except EngineError as exc:
                self.state = previous
                for topic in self.topics:
                    topic.injector = self._build(topic.spec, topic.msgtype)
                raise ReloadError(f'reload rejected: {exc}') from None
            self.manual = manual
            self._publish_events(events)
            return held, kept

    def active_faults(self, injector_id: str) -> list[ActiveFault]:
        """Faults of one injector active now (service injectors ask per call)."""
        with self.lock:
            if not self.state.started:
                return []
            return self.state.active_of(injector_id)

    # -- status ---------------------------------------------------------------------------
    def faults(self) -> list[FaultStatus]:
        """Every fault with its state and config, in file order."""
        with self.lock:
            active = self.state.active()
            return [FaultStatus(f.id, f.injector_id, f.id in active, copy.deepcopy(f.config))
                    for f in self.state.faults()]

    def flush(self) -> list[tuple[LiveTopic, RawMessage]]:
        """Messages injectors still hold (reorder windows), to publish before stopping."""
        with self.lock:
            now = self.clock()
            return [(topic, m) for topic in self.topics for m in topic.injector.flush(now)]

    def finish(self) -> RunStats:
        """End of the session: pending assertions are decided at the current time."""
        with self.lock:
            now = self.clock()
            if not self.started:
                self.start()
            self.run.end(now)
            self.run.stats.last_time = now
            return replace(self.run.stats)
