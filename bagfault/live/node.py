"""The proxy node `/bagfault`: live topics through the offline injectors, controlled by parameters.

Per topic injector: a raw subscription on input_topic and a publisher on
output_topic with the injector's QoS. Messages no active fault touches are
republished as received, never decoded. Delayed messages wait in a
`DelayLine` (own thread, ROS time). Every fault is switchable through
parameters; `~/reload_scenario` (std_srvs/srv/Trigger) reloads the file;
`/diagnostics` shows the state. With use_sim_time the scheduler follows
/clock and starts with the first clock message.
"""

from __future__ import annotations

import heapq
import itertools
import threading
import time
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rcl_interfaces.msg import SetParametersResult
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.parameter import Parameter

from bagfault import __version__
from bagfault.errors import FieldValueError, LiveError, ReloadError, ScenarioError
from bagfault.injectors.base import Injector
from bagfault.injectors.registry import get_injector_type
from bagfault.io.mcap_sink import McapSink
from bagfault.io.types import TypeCatalog
from bagfault.live.diagnostics import diagnostic_array
from bagfault.live.params import fault_parameters
from bagfault.live.ros import interface_class, qos
from bagfault.live.session import LiveSession, LiveTopic
from bagfault.live.trigger import TriggerProxy
from bagfault.scenario import load_scenario

if TYPE_CHECKING:
    from collections.abc import Callable

    from bagfault.engine.stop import StopFlag
    from bagfault.events import FaultEvent
    from bagfault.scenario.model import Scenario

NODE_NAME = 'bagfault'
OBSERVE_WAIT = 5.0  # seconds to wait for publishers of watched topics whose type is not known
DIAGNOSTICS_TYPE = 'diagnostic_msgs/msg/DiagnosticArray'
OWN_PREFIXES = ('/fault_injection/', '/fault_manager/')
TICK = 0.01  # scheduler resolution in live mode, seconds
DIAGNOSTICS_PERIOD = 1.0
MALFORMED_LOG_EVERY = 100


class DelayLine:
    """Holds delayed messages and publishes each when the ROS clock reaches its due time."""

    def __init__(self, clock: Callable[[], int], publish: Callable[[LiveTopic, bytes], None]) -> None:
        self.clock = clock
        self.publish = publish
        self._heap: list[tuple[int, int, LiveTopic, bytes]] = []
        self._counter = itertools.count()
        self._condition = threading.Condition()
        self._stopped = False
        self._thread = threading.Thread(target=self._run, name='bagfault-delay', daemon=True)
        self._thread.start()

    def put(self, due: int, topic: LiveTopic, data: bytes) -> None:
        """Publish `data` on the topic's output at ROS time `due` (ns)."""
        with self._condition:
            heapq.heappush(self._heap, (due, next(self._counter), topic, data))
            self._condition.notify()

    def _run(self) -> None:
        while True:
            with self._condition:
                while not self._heap and not self._stopped:
                    self._condition.wait()
                if self._stopped:
                    return
                wait = (self._heap[0][0] - self.clock()) / 1e9
                if wait > 0:
                    self._condition.wait(min(wait, 0.05))  # re-read the clock: sim time may jump
                    continue
                _, _, topic, data = heapq.heappop(self._heap)
            self.publish(topic, data)

    def stop(self) -> int:
        """Stop; return how many delayed messages were still waiting (not sent)."""
        with self._condition:
            self._stopped = True
            left = len(self._heap)
            self._heap.clear()
            self._condition.notify()
        self._thread.join(timeout=2.0)
        return left


def _message_type(spec: Any) -> str | None:
    cls = get_injector_type(spec.type)
    if cls is not None and issubclass(cls, Injector) and len(cls.message_types) == 1:
        return cls.message_types[0]
    return spec.options.get('message_type') or None


class ProxyNode:
    """Builds the proxy on an rclpy context and tears it down cleanly."""

    def __init__(
        self,
        scenario: Scenario,
        context: Any,
        stop: StopFlag,
        *,
        seed: int,
        record: Path | None = None,
        use_sim_time: bool = False,
    ) -> None:
        self.scenario = scenario
        self.stop = stop
        self.seed = seed
        self.record_path = record
        overrides = [Parameter('use_sim_time', Parameter.Type.BOOL, True)] if use_sim_time else []
        self.node = Node(NODE_NAME, context=context, parameter_overrides=overrides)
        self.logger = self.node.get_logger()
        self.session: LiveSession | None = None
        self.recording: McapSink | None = None
        self.delay: DelayLine | None = None
        self.publishers: dict[int, Any] = {}
        self.subscriptions: list[Any] = []
        self.services: list[TriggerProxy] = []
        self.parameters: dict[str, Any] = {}
        self._syncing = False
        self._warned: set[tuple[str, str]] = set()
        self._last_diagnostics = 0.0
        self.unsent = 0

    # -- time -------------------------------------------------------------------------------
    def now(self) -> int:
        """ROS time in ns (follows /clock with use_sim_time)."""
        return self.node.get_clock().now().nanoseconds

    # -- set-up ---------------------------------------------------------------------------------
    def resolve_types(self, executor: Any) -> dict[str, str]:
        """Message type per topic injector: from its injector type, `message_type`, or the graph."""
        types: dict[str, str] = {}
        waiting: dict[str, str] = {}
        for spec in self.scenario.injectors:
            if spec.is_service:
                continue
            if spec.input_topic == spec.output_topic:
                raise LiveError(f'{self.scenario.name}: injector {spec.id!r} reads and writes {spec.input_topic}; '
                                'a live proxy needs distinct input_topic and output_topic (/x_raw -> /x)')
            known = _message_type(spec)
            if known:
                types[spec.id] = known
            else:
                assert spec.input_topic is not None
                waiting[spec.id] = spec.input_topic
        if waiting:
            self.logger.info('waiting for publishers to learn the type of ' + ', '.join(sorted(waiting.values()))
                             + " (or set the injector's message_type)")
        while waiting and not self.stop.is_set():
            graph = dict(self.node.get_topic_names_and_types())
            for injector_id, topic in list(waiting.items()):
                found = graph.get(topic)
                if found:
                    if len(found) > 1:
                        raise LiveError(f'topic {topic} carries several types ({", ".join(found)}); '
                                        f'set message_type on injector {injector_id!r}')
                    types[injector_id] = found[0]
                    del waiting[injector_id]
            executor.spin_once(timeout_sec=0.1)
        return types

    def watched_topics(self, executor: Any) -> dict[str, str]:
        """Topics the oracles need besides the proxy's own: FM diagnostics and conditions, asserted topics."""
        own = {t for spec in self.scenario.injectors for t in (spec.input_topic, spec.output_topic) if t}
        wanted: dict[str, str | None] = {}
        config = self.scenario.fault_manager_config
        if config is not None:
            if config.diagnostics_topic:
                wanted[config.diagnostics_topic] = DIAGNOSTICS_TYPE
            for condition in config.conditions:
                wanted.setdefault(condition.topic, None)
        for assertion in self.scenario.assertions:
            for key in ('topic', 'input_topic'):
                name = assertion.params.get(key)
                if isinstance(name, str) and name:
                    known = assertion.params.get('message_type') if key == 'topic' else None
                    wanted[name] = wanted.get(name) or known
        wanted = {t: m for t, m in wanted.items() if t not in own and not t.startswith(OWN_PREFIXES)}
        deadline = time.monotonic() + OBSERVE_WAIT
        while any(m is None for m in wanted.values()) and time.monotonic() < deadline and not self.stop.is_set():
            graph = dict(self.node.get_topic_names_and_types())
            for name in [t for t, m in wanted.items() if m is None]:
                if graph.get(name):
                    wanted[name] = graph[name][0]
            executor.spin_once(timeout_sec=0.1)
        watched = {}
        for name, msgtype in wanted.items():
            if msgtype is None:
                self.logger.warning(f'{name}: no publisher within {OBSERVE_WAIT:g} s, type unknown; not watched')
            else:
                watched[name] = msgtype
        return watched

    def setup(self, executor: Any) -> None:
        """Types, session, recording, endpoints, parameters, services, timers."""
        types = self.resolve_types(executor)
        if self.stop.is_set():
            return
        classes = {injector_id: interface_class(msgtype) for injector_id, msgtype in types.items()}
        watched = self.watched_topics(executor)
        watched_classes = {name: interface_class(msgtype) for name, msgtype in watched.items()}
        catalog = TypeCatalog([], 'jazzy')
        if self.record_path is not None:
            self.recording = McapSink(self.record_path)
            self.recording.add_metadata('bagfault', {
                'tool': 'bagfault', 'version': __version__, 'mode': 'proxy', 'seed': str(self.seed),
                'scenario': self.scenario.name})
            self.recording.add_attachment(self.scenario.name, 'application/yaml', self.scenario.text.encode())
        self.session = LiveSession(self.scenario, catalog, types, self.now, seed=self.seed, sink=self.recording,
                                   blackbox_base=self.record_path, observed=watched)
        self.session.listeners.append(self._on_events)
        self.delay = DelayLine(self.now, self._publish)
        for topic in self.session.topics:
            profile = qos(topic.spec.qos_depth, topic.spec.options.get('reliability', 'reliable'),
                          topic.spec.options.get('durability', 'volatile'))
            cls = classes[topic.spec.id]
            self.publishers[id(topic)] = self.node.create_publisher(
                cls, topic.output_topic, profile,
                event_callbacks=PublisherEventCallbacks(
                    incompatible_qos=partial(self._incompatible, topic, 'subscriber')))
            self.subscriptions.append(self.node.create_subscription(
                cls, topic.input_topic, partial(self._on_message, topic), profile, raw=True,
                event_callbacks=SubscriptionEventCallbacks(
                    incompatible_qos=partial(self._incompatible, topic, 'publisher'))))
            self.logger.info(f'proxy {topic.input_topic} -> {topic.output_topic} ({topic.spec.type}, {topic.msgtype})')
        for name, cls in watched_classes.items():
            self.subscriptions.append(self.node.create_subscription(
                cls, name, partial(self._on_watched, name, cls), qos(100, 'best_effort'), raw=True))
            self.logger.info(f'watching {name} ({watched[name]}) for the oracles')
        for spec in self.scenario.injectors:
            if spec.is_service:
                self.services.append(TriggerProxy(self.node, spec, self.session))
                self.logger.info(f'proxy service {spec.proxy_service} -> {spec.target_service}')
        self._declare_parameters()
        self.node.add_on_set_parameters_callback(self._check_parameters)
        self.node.add_post_set_parameters_callback(self._apply_parameters)
        trigger = interface_class('std_srvs/srv/Trigger')
        self.node.create_service(trigger, '~/reload_scenario', self._reload)
        diagnostics = interface_class('diagnostic_msgs/msg/DiagnosticArray')
        self.diagnostics = self.node.create_publisher(diagnostics, '/diagnostics', 10)
        self.node.create_timer(TICK, self._tick)
        self._tick()

    # -- messages ------------------------------------------------------------------------------
    def _on_message(self, topic: LiveTopic, data: bytes) -> None:
        assert self.session is not None and self.delay is not None
        before = topic.malformed
        outputs = self.session.receive(topic, data)
        if topic.malformed != before and (topic.malformed == 1 or topic.malformed % MALFORMED_LOG_EVERY == 0):
            action = topic.spec.options.get('on_malformed', 'forward')
            self.logger.warning(f'{topic.input_topic}: malformed message #{topic.malformed} ({topic.last_error}); '
                                f'{"dropped" if action == "drop" else "forwarded untouched"}')
        now = self.now()
        for message in outputs:
            if message.log_time <= now:
                self._publish(topic, message.data)
            else:
                self.delay.put(message.log_time, topic, bytes(message.data))

    def _on_watched(self, name: str, cls: Any, data: bytes) -> None:
        assert self.session is not None
        if self.session.observed[name] == DIAGNOSTICS_TYPE:
            from rclpy.serialization import deserialize_message  # noqa: PLC0415

            try:
                statuses = deserialize_message(data, cls).status
            except Exception:  # noqa: BLE001 - malformed: let the oracle see and judge it
                statuses = []
            if statuses and all(s.name.startswith('bagfault: ') for s in statuses):
                return  # the proxy's own status, not the system under test's
        self.session.observe(name, data)

    def _publish(self, topic: LiveTopic, data: bytes | memoryview) -> None:
        assert self.session is not None
        payload = data if isinstance(data, bytes) else bytes(data)
        try:
            self.publishers[id(topic)].publish(payload)
        except Exception as exc:  # noqa: BLE001 - shutting down while the delay line publishes
            if not self.stop.is_set():
                self.logger.error(f'{topic.output_topic}: publish failed: {exc}')
            return
        self.session.sent(topic, payload)

    def _incompatible(self, topic: LiveTopic, other: str, info: Any) -> None:
        key = (topic.spec.id, other)
        if key in self._warned:
            return
        self._warned.add(key)
        name = topic.input_topic if other == 'publisher' else topic.output_topic
        policy = getattr(info.last_policy_kind, 'name', str(info.last_policy_kind))
        self.logger.warning(
            f'{name}: a {other} with incompatible QoS ({policy}) cannot connect to injector {topic.spec.id!r}; '
            "set the injector's reliability/durability to match it. Still running.")

    # -- clock ---------------------------------------------------------------------------------
    def _tick(self) -> None:
        session = self.session
        if session is None:
            return
        if not session.started:
            if self.now() <= 0:
                return  # sim time: no /clock yet
            session.start()
            self.logger.info('bagfault proxy ready')
            self._publish_diagnostics()
        session.advance()
        if time.monotonic() - self._last_diagnostics >= DIAGNOSTICS_PERIOD:
            self._publish_diagnostics()

    def _publish_diagnostics(self) -> None:
        assert self.session is not None
        self._last_diagnostics = time.monotonic()
        self.diagnostics.publish(diagnostic_array(self.session.faults(), self.session.topics,
                                                  self.node.get_clock().now().to_msg()))

    def _on_events(self, events: list[FaultEvent]) -> None:
        for event in events:
            self.logger.info(f'fault {event.fault_id}: {event.state} ({event.source}) {event.details}')
        self._sync_parameters()
        if self.session is not None and self.session.started:
            self._publish_diagnostics()

    # -- parameters ------------------------------------------------------------------------------
    def _declare_parameters(self) -> None:
        declared, notes = fault_parameters(self.scenario if self.session is None else self.session.scenario)
        for note in notes:
            self.logger.warning(note)
        wanted = {p.name: p for p in declared}
        for name in [n for n in self.parameters if n not in wanted]:
            self.node.undeclare_parameter(name)
            del self.parameters[name]
        for name, parameter in wanted.items():
            if name not in self.parameters:
                self._syncing = True
                try:
                    self.node.declare_parameter(name, parameter.value, parameter.descriptor)
                finally:
                    self._syncing = False
            self.parameters[name] = parameter

    def _sync_parameters(self) -> None:
        """Parameters show the session's state (after scheduled changes, events, reloads)."""
        if self.session is None or self._syncing:
            return
        updates = []
        for state in self.session.faults():
            name = f'{state.fault_id}.active'
            if name in self.parameters and self.node.get_parameter(name).value != state.active:
                updates.append(Parameter(name, Parameter.Type.BOOL, state.active))
            for key, value in state.config.items():
                name = f'{state.fault_id}.{key}'
                declared = self.parameters.get(name)
                if declared is None or declared.descriptor.read_only:
                    continue
                if self.node.get_parameter(name).value != value:
                    updates.append(Parameter(name, value=value))
        if updates:
            self._syncing = True
            try:
                self.node.set_parameters(updates)
            finally:
                self._syncing = False

    def _check_parameters(self, parameters: list[Parameter]) -> SetParametersResult:
        if self._syncing or self.session is None:
            return SetParametersResult(successful=True)
        for parameter in parameters:
            declared = self.parameters.get(parameter.name)
            if declared is None or declared.key is None:
                continue
            try:
                self.session.check_config(declared.fault_id, declared.key, parameter.value)
            except FieldValueError as exc:
                return SetParametersResult(successful=False, reason=f'{parameter.name}: {exc}')
        return SetParametersResult(successful=True)

    def _apply_parameters(self, parameters: list[Parameter]) -> None:
        if self._syncing or self.session is None:
            return
        self._syncing = True
        try:
            for parameter in parameters:
                declared = self.parameters.get(parameter.name)
                if declared is None:
                    continue
                if declared.key is None:
                    self.session.set_active(declared.fault_id, bool(parameter.value), 'manual')
                else:
                    for topic, message in self.session.set_config(declared.fault_id, declared.key, parameter.value):
                        self._publish(topic, message.data)
        finally:
            self._syncing = False
        self._sync_parameters()

    # -- reload --------------------------------------------------------------------------------
    def _reload(self, request: Any, response: Any) -> Any:
        assert self.session is not None
        source = self.scenario.source
        try:
            if source is None:
                raise ReloadError('reload rejected: the scenario was not loaded from a file')
            scenario = load_scenario(source)
            held = self.session.reload(scenario)
        except ScenarioError as exc:
            response.success, response.message = False, f'reload rejected: {exc}'.splitlines()[0]
        except ReloadError as exc:
            response.success, response.message = False, str(exc)
        else:
            response.success, response.message = True, f'reloaded {source.name}: {len(scenario.faults)} faults'
            for topic, message in held:
                self._publish(topic, message.data)
            self._declare_parameters()  # faults may have come or gone
            self._sync_parameters()
        if response.success:
            self.logger.info(response.message)
        else:
            self.logger.warning(response.message)
        return response

    # -- end -------------------------------------------------------------------------------------
    def close(self) -> None:
        """Stop the delay line, publish what injectors hold, finish the session and the recording."""
        if self.delay is not None:
            self.unsent = self.delay.stop()
        if self.session is not None:
            for topic, message in self.session.flush():
                self._publish(topic, message.data)
            self.session.finish()
            if self.recording is not None:
                try:
                    self.recording.finish()
                except BaseException:
                    self.session.run.close(ok=False)
                    raise
            self.session.run.close(ok=True)
        elif self.recording is not None:
            self.recording.abort()
        self.node.destroy_node()

    def abort(self) -> None:
        """A failure: stop the delay line, drop the partial recording and black boxes."""
        if self.delay is not None:
            self.delay.stop()
        if self.recording is not None:
            self.recording.abort()
        if self.session is not None:
            self.session.run.close(ok=False)
        self.node.destroy_node()
