"""A run-loop sink that publishes on live topics, paced to wall time, and records what it sent.

A `Pacer` (pacing, pause, speed, seek, recording, view) with ROS: each
topic gets a publisher with the recorded QoS (types without Python bindings
here, such as bagfault's own event types where the anchor's packages are
absent, are recorded but not published), /clock carries the timeline, and
before the first message the sink waits for the graph (subscribers of named
topics, or a settle time and then every subscriber the graph knows).
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any

from rclpy.exceptions import InvalidTopicNameException

from bagfault.engine.stop import Stopped
from bagfault.errors import LiveError
from bagfault.live.clockwarp import CLOCK_TRACE, CLOCK_TYPE, ClockWarps, clock_cdr, stall_seconds
from bagfault.live.pacer import CLOCK_PERIOD, CLOCK_TOPIC, Pacer
from bagfault.live.ros import has_interface, interface_class, qos, recorded_qos, unacknowledged
from bagfault.units import NS

if TYPE_CHECKING:
    from collections.abc import Mapping, Sequence

    from bagfault.engine.run import Run
    from bagfault.engine.stop import StopFlag
    from bagfault.events import FaultEvent
    from bagfault.io.mcap_sink import McapSink
    from bagfault.live.pacer import View
    from bagfault.spec.model import Scenario

MATCH_WAIT = 5.0  # seconds after the settle time to wait for subscribers the graph knows to be matched
MATCH_SETTLE = 0.25  # seconds after a publisher sees its subscriber until the subscriber has matched it too


class LiveSink(Pacer):
    """Publishes pipeline records on live topics at their time (a sink and the pass hooks of the run loop)."""

    def __init__(self, node: Any, *, rate: float, clock: bool, stop: StopFlag,
                 recording: McapSink | None = None, settle: float = 0.0, wait_for: Sequence[str] = (),
                 wait_timeout: float = 30.0, clock_hz: float = 1 / CLOCK_PERIOD, topics: Sequence[str] = (),
                 skip: float = 0.0, view: View | None = None, hold_stalls: bool = False) -> None:
        super().__init__(rate=rate, stop=stop, recording=recording, topics=topics, skip=skip, clock_hz=clock_hz,
                         view=view, settle=settle, hold_stalls=hold_stalls)
        self.node = node
        self.wait_for = list(wait_for)  # topics whose publishers must first have a subscriber ('all': every one)
        self.wait_timeout = wait_timeout
        self._events: Any = None
        self._publishers: dict[str, Any] = {}
        self._clock = None
        if clock:
            clock_type = interface_class(CLOCK_TYPE)
            self._clock = node.create_publisher(clock_type, CLOCK_TOPIC, qos(1))
            self._clock_message = clock_type()
        self.skipped: dict[str, str] = {}  # topic -> why it is recorded but not published
        self.warps = ClockWarps()
        self._scenario: Scenario | None = None
        self._clock_injectors: set[str] = set()
        self._trace: int | None = None  # the recording's channel of the /clock bagfault published
        self.clock_left_out = False  # the bag's own /clock was recorded, not published (bagfault's is the clock)

    def _publisher(self, topic: str, msgtype: str, metadata: dict[str, str] | None) -> Any:
        """A publisher with the recorded QoS when the type is installed; none for the bag's own /clock while
        bagfault publishes the bag time there (a simulator's recording holds its /clock: two clocks would
        make every node's time jump between them)."""
        if self._clock is not None and topic == CLOCK_TOPIC:
            self.clock_left_out = True
            return None
        if has_interface(msgtype):
            profile = recorded_qos((metadata or {}).get('offered_qos_profiles', '')) or qos(10)
            try:
                publisher = self.node.create_publisher(interface_class(msgtype), topic, profile)
            except InvalidTopicNameException:  # a ROS 1 name such as 'ORB-SLAM' has no ROS 2 form
                self.skipped[topic] = 'not a valid ROS 2 topic name'
                return None
            self._publishers[topic] = publisher
            return publisher
        if not topic.startswith(('/fault_injection/', '/fault_manager/')):
            self.skipped[topic] = f'{msgtype} has no Python bindings here'
        return None

    # -- pass hooks -------------------------------------------------------------------------------
    def prepare(self, routing: Any) -> Mapping[str, tuple[str, str, str]]:
        """Before the first message: wait until the named topics have subscribers, or the settle time and
        then until every subscriber the graph knows is matched (MATCH_WAIT at most)."""
        if self.prepared:
            return {}  # a later pass (a loop, a seek): the graph is connected
        if self.wait_for:
            self.prepared = True
            self.wait_for_subscribers(sorted(self._publishers) if self.wait_for == ['all'] else self.wait_for)
            return {}
        super().prepare(routing)
        deadline = time.monotonic() + MATCH_WAIT
        while time.monotonic() < deadline and self._unmatched():
            if self.stop.wait(0.02):
                raise Stopped(self.stop.reason)
        return {}

    def _unmatched(self) -> list[str]:
        return [t for t, p in self._publishers.items()
                if p.get_subscription_count() < self.node.count_subscribers(p.topic_name)]

    def wait_for_subscribers(self, topics: Sequence[str]) -> None:
        """Until every topic's publisher is matched by a subscriber; LiveError after `wait_timeout`. A topic is
        named as in the bag or as published (after remapping)."""
        publishers = {**self._publishers, **{p.topic_name: p for p in self._publishers.values()}}
        unknown = [t for t in topics if t not in publishers]
        if unknown:
            names = sorted({p.topic_name for p in self._publishers.values()})
            raise LiveError(f'--wait-for {", ".join(unknown)}: not a topic this bag publishes '
                            f'(it publishes {", ".join(names) or "nothing"})')
        deadline = time.monotonic() + self.wait_timeout
        while True:
            waiting = [t for t in topics if publishers[t].get_subscription_count() == 0]
            if not waiting:
                if self.stop.wait(MATCH_SETTLE):  # the subscriber's side of the match completes a moment later
                    raise Stopped(self.stop.reason)
                return
            if time.monotonic() > deadline:
                raise LiveError(f'no subscriber on {", ".join(waiting)} within {self.wait_timeout:g} s')
            if self.stop.wait(0.02):
                raise Stopped(self.stop.reason)

    def delivered(self, timeout: float) -> list[str]:
        """After the last message: the topics whose subscribers have not acknowledged it within `timeout`."""
        return unacknowledged(self._publishers.values(), timeout)

    def begin(self, run: Run) -> None:
        """The run's events go out on /bagfault/events as they happen (and to the view)."""
        super().begin(run)
        self._scenario = run.scenario
        self._clock_injectors = {i.id for i in run.scenario.injectors if i.type == 'clock'}
        if self._clock is not None and self._clock_injectors and self._trace is None:
            self._trace = self.record_only(CLOCK_TRACE, CLOCK_TYPE, *run.catalog.schema(CLOCK_TYPE))
        if self._events is None:
            from bagfault.live.events import LiveEvents  # noqa: PLC0415

            self._events = LiveEvents(self.node, anchor_topics=False)  # anchor-typed events: published as records
        self._events.attach(run)

    def _reached(self, bag_time: int) -> None:
        """/clock says the timeline's time (as the clock faults warp it; their trace recorded on CLOCK_TRACE)."""
        if bag_time <= self.clock_value:
            return
        super()._reached(bag_time)
        self._publish_clock(bag_time)

    def _publish_clock(self, bag_time: int) -> None:
        if self._clock is not None:
            clock = self.warps.clock_of(bag_time)
            self._clock_message.clock.sec, self._clock_message.clock.nanosec = divmod(clock, NS)
            self._clock.publish(self._clock_message)
            if self._trace is not None:
                self.write(self._trace, bag_time, bag_time, clock_cdr(clock))

    def act(self, event: FaultEvent) -> str:
        """A clock fault's change: the warp of /clock starts or ends; a stall holds the timeline here."""
        if self._clock is None or event.injector_id not in self._clock_injectors:
            return ''
        if event.state == 'inactive':
            said = self.warps.end(event.fault_id)
            self._publish_clock(event.time)  # at the event's time, not at the next tick
            return said
        if event.state != 'active':
            return ''
        fault = self._scenario.fault(event.fault_id) if self._scenario is not None else None
        assert fault is not None
        if not fault.config.get('stall'):
            said = self.warps.start(event.fault_id, event.time, fault.config)
            self._publish_clock(event.time)
            return said
        seconds = stall_seconds(fault) / self.rate
        self.pause()
        try:
            self._stall(time.monotonic() + seconds)
        finally:
            self.resume()
        return f'/clock stood still at {self.warps.clock_of(event.time) / NS:.3f} s for {seconds:g} s of wall time'

    def _stall(self, until: float) -> None:
        """Wait, nothing played and /clock still, until `until` (monotonic); the recording's chunks go on."""
        while time.monotonic() < until:
            if self.stop.wait(min(0.01, max(until - time.monotonic(), 0.0))):
                raise Stopped(self.stop.reason)
            if self.recording is not None:
                self.recording.tick()
