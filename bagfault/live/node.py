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

import contextlib
import json
import time
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy

from bagfault import __version__
from bagfault.engine.offline import finish
from bagfault.engine.provenance import record_origin
from bagfault.errors import BagfaultError, LiveError, MalformedMessageError, ReloadError, ScenarioError
from bagfault.io.mcap_sink import McapSink
from bagfault.io.types import TypeCatalog
from bagfault.live import anchor
from bagfault.live.delay import DelayLine
from bagfault.live.diagnostics import diagnostic_array
from bagfault.live.events import LiveEvents
from bagfault.live.graph import DIAGNOSTICS_TYPE, OBSERVE_WAIT, resolve_types, watched_topics
from bagfault.live.losses import LossCount
from bagfault.live.params import FaultParameters
from bagfault.live.recording import start_recording
from bagfault.live.ros import adapted_qos, interface_class, make_node, offered_metadata, qos, unacknowledged
from bagfault.live.session import LiveSession, LiveTopic
from bagfault.live.trigger import ServiceHost, TriggerProxy
from bagfault.scenario import load_scenario

if TYPE_CHECKING:
    from bagfault.engine.stop import StopFlag
    from bagfault.events import FaultEvent
    from bagfault.live.viewing import LiveView, OpenView
    from bagfault.spec.model import FaultSpec, Scenario

NODE_NAME = 'bagfault'
TICK = 0.01  # scheduler resolution in live mode, seconds
DIAGNOSTICS_PERIOD = 1.0
MALFORMED_LOG_EVERY = 100
DRAIN = 2.0  # seconds a clean stop waits for delayed messages and service calls to fall due


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
        ros_args: list[str] | None = None,
        view: OpenView | None = None,
    ) -> None:
        self.scenario = scenario
        self.open_view = view
        self.view: LiveView | None = None
        self.anchor: Any = None
        self.stop = stop
        self.seed = seed
        self.record_path = record
        overrides = [Parameter('use_sim_time', Parameter.Type.BOOL, True)] if use_sim_time else []
        self.node = make_node(NODE_NAME, context, ros_args, parameter_overrides=overrides,
                              allow_undeclared_parameters=True)  # unknown names get our message, not rclpy's
        self.node.add_on_set_parameters_callback(self._check_sim_time)
        self.logger = self.node.get_logger()
        self.session: LiveSession | None = None
        self.recording: McapSink | None = None
        self.delay: DelayLine | None = None
        self.publishers: dict[int, Any] = {}
        self.unacknowledged: list[str] = []  # output topics whose subscribers missed acknowledging the last messages
        self.subscriptions: list[Any] = []
        self.services: list[TriggerProxy] = []
        self.service_host: ServiceHost | None = None
        self.context = context
        self.ros_args = ros_args
        self.parameters: FaultParameters | None = None
        self._warned: set[tuple[str, str]] = set()
        self._inputs: dict[int, tuple[Any, Any, Any]] = {}  # id(topic) -> its subscription, class and QoS
        self._incompatible_inputs: set[LiveTopic] = set()  # inputs whose subscription asks more than a publisher
        self._last_diagnostics = 0.0
        self.early = 0  # delayed messages published before their time at the stop
        self.failure: BagfaultError | None = None  # raised once the proxy has stopped cleanly
        # a recording says what the proxy's inputs lost (the executor then hands message info over)
        self.losses = LossCount() if record is not None else None

    # -- time -------------------------------------------------------------------------------
    def now(self) -> int:
        """ROS time in ns (follows /clock with use_sim_time)."""
        return int(self.node.get_clock().now().nanoseconds)

    # -- set-up ---------------------------------------------------------------------------------
    def setup(self, executor: Any) -> None:
        """Types, session, recording, endpoints, parameters, services, timers."""
        types = resolve_types(self.node, self.scenario, executor, self.stop)
        if self.stop.is_set():
            return
        classes = {injector_id: interface_class(msgtype) for injector_id, msgtype in types.items()}
        own = {t for spec in self.scenario.injectors for t in (spec.input_topic, spec.output_topic) if t}
        watched, unknown = watched_topics(self.node, self.scenario, self.stop, own=own, executor=executor)
        for name in unknown:
            self.node.get_logger().warning(f'{name}: no publisher within {OBSERVE_WAIT:g} s, type unknown; '
                                           'not watched')
        watched_classes = {name: interface_class(msgtype) for name, msgtype in watched.items()}
        catalog = TypeCatalog([], 'jazzy')
        if self.record_path is not None:
            self.recording = start_recording(self.record_path, {
                'tool': 'bagfault', 'version': __version__, 'mode': 'proxy', 'seed': str(self.seed),
                'scenario': self.scenario.name}, self.scenario, self.now())
        sink: Any = self.recording
        if self.open_view is not None:
            from bagfault.engine.run import NullSink  # noqa: PLC0415

            self.view = self.open_view(self.scenario, reload=self.reload_scenario, editable=True)
            sink = self.view.sink(self.recording if self.recording is not None else NullSink())
            self.logger.info(f'Foxglove view on {self.view.url}')
        self.session = LiveSession(self.scenario, catalog, types, self.now, seed=self.seed, sink=sink,
                                   blackbox_base=self.record_path, observed=watched, offers=self._offers)
        if self.view is not None:
            self.view.controls = self
            self.view.attach(self.session.run)
        self.session.listeners.append(self._on_events)
        self.events = LiveEvents(self.node, anchor_topics=True)
        self.events.attach(self.session.run)
        self.delay = DelayLine(self.now, self._publish)
        for topic in self.session.topics:
            profile = self._profile(topic)
            cls = classes[topic.spec.id]
            offered = profile if 'reliability' in topic.spec.options else qos(
                profile.depth, 'reliable', 'transient_local' if profile.durability == DurabilityPolicy.TRANSIENT_LOCAL
                else 'volatile')  # reliable reaches best-effort and reliable subscribers alike
            self.publishers[id(topic)] = self.node.create_publisher(
                cls, topic.output_topic, offered,
                event_callbacks=PublisherEventCallbacks(
                    incompatible_qos=partial(self._incompatible, topic, 'subscriber')))
            self._subscribe(topic, cls, profile)
            self.logger.info(f'proxy {topic.input_topic} -> {topic.output_topic} ({topic.spec.type}, {topic.msgtype})')
        for name, cls in watched_classes.items():
            self.subscriptions.append(self.node.create_subscription(
                cls, name, partial(self._on_watched, name, cls), qos(100, 'best_effort'), raw=True))
            self.logger.info(f'watching {name} ({watched[name]}) for the oracles')
        for spec in self.scenario.injectors:
            if spec.is_service:
                if self.service_host is None:
                    self.service_host = ServiceHost(self.node.get_name(), self.context, self.ros_args)
                self.services.append(TriggerProxy(self.service_host.node, spec, self.session))
                self.logger.info(f'proxy service {spec.proxy_service} -> {spec.target_service}')
        self.parameters = FaultParameters(self.node, self.session, self._publish)
        trigger = interface_class('std_srvs/srv/Trigger')
        self.node.create_service(trigger, '~/reload_scenario', self._reload)
        if anchor.available():
            self.anchor = anchor.AnchorServices(self.node, self)
            self.logger.info('serving the anchor interface (fault_injection/*)')
        diagnostics = interface_class('diagnostic_msgs/msg/DiagnosticArray')
        self.diagnostics = self.node.create_publisher(diagnostics, '/diagnostics', 10)
        self.node.create_timer(TICK, self._tick)
        self._tick()

    # -- messages ------------------------------------------------------------------------------
    def _on_message(self, topic: LiveTopic, data: bytes) -> None:
        assert self.session is not None and self.delay is not None
        before = topic.malformed
        try:
            outputs = self.session.receive(topic, data)
        except MalformedMessageError as exc:
            self.logger.error(str(exc))
            self.failure = exc
            self.stop.set('a malformed message (on_malformed: error)')
            return
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

    def _offers(self, topic: str) -> dict[str, str]:
        """What the publishers of a topic offer now (the proxy's own, for an output topic), as recorded."""
        return offered_metadata(self.node.get_publishers_info_by_topic(topic))

    def _profile(self, topic: LiveTopic) -> Any:
        """The injector's QoS when it sets reliability or durability; else one every current publisher of its
        input connects to (a best-effort sensor driver gets a best-effort proxy), as rosbag2's recorder adapts."""
        options = topic.spec.options
        if 'reliability' in options or 'durability' in options:
            return qos(topic.spec.qos_depth, options.get('reliability', 'reliable'),
                       options.get('durability', 'volatile'))
        return adapted_qos(topic.spec.qos_depth, self.node.get_publishers_info_by_topic(topic.input_topic))

    def _subscribe(self, topic: LiveTopic, cls: Any, profile: Any) -> None:
        events = SubscriptionEventCallbacks(incompatible_qos=partial(self._incompatible, topic, 'publisher'))
        callback: Any = partial(self._on_message, topic)
        if self.losses is not None:
            events.message_lost = partial(self._on_lost, topic)
            callback = partial(self._on_message_with_info, topic)
        self._inputs[id(topic)] = (self.node.create_subscription(
            cls, topic.input_topic, callback, profile, raw=True, event_callbacks=events), cls, profile)

    def _on_message_with_info(self, topic: LiveTopic, data: bytes, info: dict[str, int]) -> None:
        assert self.losses is not None
        self.losses.heard(topic.input_topic, info, self._inputs[id(topic)][0].get_publisher_count)
        self._on_message(topic, data)

    def _on_lost(self, topic: LiveTopic, status: Any) -> None:
        assert self.losses is not None
        self.losses.report(topic.input_topic, status.total_count)

    def lost(self) -> dict[str, int]:
        """Messages of the inputs known lost before the proxy heard them, per input topic (with a recording)."""
        return self.losses.lost() if self.losses is not None else {}

    def _readapt(self) -> None:
        """A publisher that appeared later offers less than the input subscription asks: ask for less (in the
        timer's callback, not the event's)."""
        while self._incompatible_inputs:
            topic = self._incompatible_inputs.pop()
            subscription, cls, profile = self._inputs[id(topic)]
            wanted = self._profile(topic)
            if (wanted.reliability, wanted.durability) == (profile.reliability, profile.durability):
                continue
            self.node.destroy_subscription(subscription)
            self._subscribe(topic, cls, wanted)
            self.logger.info(f'{topic.input_topic}: subscription now {wanted.reliability.name.lower()}, '
                             f'{wanted.durability.name.lower()} to match its publishers')

    def _incompatible(self, topic: LiveTopic, other: str, info: Any) -> None:
        options = topic.spec.options
        if other == 'publisher' and 'reliability' not in options and 'durability' not in options:
            self._incompatible_inputs.add(topic)
            return
        key = (topic.spec.id, other)
        if key in self._warned:
            return
        self._warned.add(key)
        name = topic.input_topic if other == 'publisher' else topic.output_topic
        policy = getattr(info.last_policy_kind, 'name', str(info.last_policy_kind))
        self.logger.warning(
            f'{name}: a {other} with incompatible QoS ({policy}) cannot connect to injector {topic.spec.id!r}; '
            "set the injector's reliability/durability to match it. Still running.")

    def _check_sim_time(self, parameters: list[Parameter]) -> Any:
        """Sim time switched on with nothing on /clock would stop the scheduler and the delay line: refused."""
        from rcl_interfaces.msg import SetParametersResult  # noqa: PLC0415

        for parameter in parameters:
            if parameter.name == 'use_sim_time' and parameter.value is True \
                    and not self.node.get_parameter('use_sim_time').value \
                    and self.node.count_publishers('/clock') == 0:
                return SetParametersResult(successful=False, reason=(
                    'use_sim_time: nothing publishes /clock; sim time would stop the fault schedule and every '
                    'delayed message. Start the clock source (bagfault play --clock, a simulator) first'))
        return SetParametersResult(successful=True)

    # -- clock ---------------------------------------------------------------------------------
    def _tick(self) -> None:
        session = self.session
        if session is None:
            return
        if not session.started:
            if self.now() <= 0:
                return  # sim time: no /clock yet
            session.start()
            if self.parameters is not None:
                try:
                    self.parameters.apply_overrides()
                except LiveError as exc:
                    self.logger.error(str(exc))
                    self.failure = exc
                    self.stop.set('a refused parameter value')
                    return
            self.logger.info('bagfault proxy ready')
            self._publish_diagnostics()
        self._readapt()
        session.advance()
        if self.recording is not None:
            with session.lock:
                self.recording.tick()
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
        if self.parameters is not None:
            self.parameters.sync()
        if self.session is not None and self.session.started:
            self._publish_diagnostics()

    # -- reload --------------------------------------------------------------------------------
    def _reload(self, request: Any, response: Any) -> Any:
        response.success, response.message = self.reload_scenario()
        return response

    def reload_scenario(self) -> tuple[bool, str]:
        """Re-read the scenario file (the reload service, the Foxglove view): (success, message)."""
        assert self.session is not None
        source = self.scenario.source
        try:
            if source is None:
                raise ReloadError('reload rejected: the scenario was not loaded from a file')
            scenario = load_scenario(source)
            held, kept = self.session.reload(scenario)
        except ScenarioError as exc:
            success, message = False, f'reload rejected: {exc}'.splitlines()[0]
        except ReloadError as exc:
            success, message = False, str(exc)
        else:
            success, message = True, f'reloaded {source.name}: {len(scenario.faults)} faults' + (
                f'; kept what was set at run time: {", ".join(kept)}' if kept else '')
            for topic, held_message in held:
                self._publish(topic, held_message.data)
            assert self.parameters is not None
            self.parameters.declare()  # faults may have come or gone
            self.parameters.sync()
            if self.view is not None:
                self.view.scenario = scenario
        if success:
            self.logger.info(message)
        else:
            self.logger.warning(message)
        return success, message

    def fault(self, fault_id: str) -> FaultSpec | None:
        """A fault with its current config (the session's fault state), for the Foxglove view."""
        return self.session.state.fault(fault_id) if self.session is not None else self.scenario.fault(fault_id)

    def ask(self, fault_id: str, key: str | None, value: object) -> Any:
        """A change from the Foxglove view: checked by the schema, applied now (parameters follow)."""
        assert self.session is not None
        if key is None:
            checked = self.session.state.check(fault_id, None, value)
            self.session.set_active(fault_id, bool(checked), 'manual')
            return checked
        checked = self.session.check_config(fault_id, key, value)
        for topic, message in self.session.set_config(fault_id, key, checked):
            self._publish(topic, message.data)
        return checked

    # -- end -------------------------------------------------------------------------------------
    def drain(self) -> None:
        """A clean stop, while the service thread still runs: delayed service calls are answered now."""
        for service in self.services:
            service.release()
        deadline = time.monotonic() + DRAIN
        while any(s.in_flight for s in self.services) and time.monotonic() < deadline:
            time.sleep(0.02)
        if self.service_host is not None:
            self.service_host.close()
            self.service_host = None

    def close(self) -> None:
        """Publish what the delay line and the injectors hold, finish the session and the recording."""
        if self.delay is not None:
            self.early = self.delay.stop(drain=DRAIN)
        if self.session is not None:
            for topic, message in self.session.flush():
                self._publish(topic, message.data)
            self.unacknowledged = unacknowledged(self.publishers.values(), DRAIN)
            self.session.register_channels()
            self.session.finish()
            with self.session.run:  # black boxes dropped unless the recording is complete
                if self.recording is not None:
                    record_origin(self.recording, self.session.run.stats.origin)
                    received = {t.input_topic: t.received for t in self.session.topics}
                    self.recording.add_metadata('bagfault.recording', {
                        'received': json.dumps(received, sort_keys=True),
                        'lost': json.dumps(self.lost(), sort_keys=True)})
                    finish(self.recording, self.session.run)
                else:
                    self.session.run.close(ok=True)
        elif self.recording is not None:
            self.recording.abort()
        self.node.destroy_node()

    def close_view(self) -> None:
        """Stop the Foxglove server."""
        if self.view is not None:
            self.view.close()
            self.view = None

    def __enter__(self) -> ProxyNode:
        return self

    def __exit__(self, kind: type[BaseException] | None, *_: object) -> None:
        """A failure inside the `with` aborts (a normal end closes explicitly, to report what it drained)."""
        if kind is not None:
            self.abort()

    def abort(self) -> None:
        """A failure: stop the delay line, drop the partial recording and black boxes."""
        self.close_view()
        if self.service_host is not None:
            self.service_host.close()
        if self.delay is not None:
            self.delay.stop()
        if self.recording is not None:
            self.recording.abort()
        if self.session is not None:
            self.session.run.close(ok=False)
        with contextlib.suppress(Exception):  # close may have destroyed it before it failed
            self.node.destroy_node()
