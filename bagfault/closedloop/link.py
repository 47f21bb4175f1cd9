"""The live pass of `bagfault test`: the bag played as `play` plays it, and the system under test heard.

Before the first message the link waits until the system is ready (each
condition in turn, failing at once if the system exits), learns the types
of the topics the oracles read, and subscribes on a second node, spun in
a thread, to what the system publishes; a system that publishes a topic the
bag plays makes the run invalid (unless declared in
`system_under_test.publishes`, then bagfault does not play it). A message
from the system takes
the bag time of its arrival (wall time since the first record x rate),
never earlier than what was judged before it and never later than the
record about to be played; before each record is judged everything that
arrived is handed to the run loop, so the oracles and the recording see
one stream in time order on bag time. After the last record /clock runs
on for `tail` seconds of bag time while the system's answers come in.
"""

from __future__ import annotations

import os
import threading
import time
from collections import deque
from typing import TYPE_CHECKING, Any

from bagfault.assertions.base import AssertionResult
from bagfault.closedloop.actions import ProcessFaults
from bagfault.closedloop.clocks import GRACE, HOLD, ClockCheck
from bagfault.closedloop.isolation import NAME_POLL, NAME_WAIT, UNKNOWN, pid16, shared, shared_error
from bagfault.closedloop.links import Links
from bagfault.closedloop.process import describe_exit
from bagfault.engine.run import OutputChannel
from bagfault.engine.stop import Stopped
from bagfault.errors import ClosedLoopError
from bagfault.events import AssertionEvent
from bagfault.faults.header import has_header
from bagfault.live.graph import OWN_PREFIXES, watched_topics
from bagfault.live.recorder import Recorder
from bagfault.live.sink import MATCH_SETTLE, LiveSink
from bagfault.units import NS

if TYPE_CHECKING:
    from collections.abc import Mapping

    from bagfault.closedloop.isolation import DomainWatch
    from bagfault.closedloop.process import SystemProcess
    from bagfault.engine.oracles import Schema
    from bagfault.engine.routing import Routing
    from bagfault.engine.run import Run
    from bagfault.engine.stop import StopFlag
    from bagfault.events import AssertionState, FaultEvent
    from bagfault.io.mcap_sink import McapSink
    from bagfault.io.types import TypeCatalog
    from bagfault.spec.model import Scenario
    from bagfault.spec.system import ReadyCondition, SystemUnderTest

POLL = 0.02  # seconds between looks while waiting for readiness
DISCOVERY_PERIOD = 0.2  # seconds between looks at the graph for new topics of the system during the run
WATCH_WAIT = 2.0  # seconds to learn the type of an asserted topic the system has not advertised yet
RECORD_MATCH = 5.0  # seconds at most for the recorder's subscriptions to match the system's publishers
NOT_RECORDED = ('/clock', '/parameter_events', '/rosout')
SYSTEM_ALIVE = 'system_alive'


class SystemLink(LiveSink):
    """Plays the bag into the system under test and hands what the system publishes to the run loop."""

    def __init__(self, node: Any, listener: Any, executor: Any, *, system: SystemUnderTest,
                 process: SystemProcess, scenario: Scenario, catalog: TypeCatalog, rate: float, stop: StopFlag,
                 recording: McapSink | None, watch: DomainWatch | None = None, seed: int = 0,
                 clock_check: bool = True) -> None:
        super().__init__(node, rate=rate, clock=True, stop=stop, recording=recording, hold_stalls=True)
        self.watch = watch
        self.clock_check = clock_check  # at a rate other than 1: hold the clock before the first record (HOLD)
        self.clocks = ClockCheck(rate)
        self._hold = (0.0, 0.0)  # monotonic window in which the sim clock stands still (rate != 1)
        self._stamped: set[str] = set()  # the system's topics whose type starts with a std_msgs/Header
        self.listener = listener
        self.executor = executor
        self.system = system
        self.process = process
        self.scenario = scenario
        self.catalog = catalog
        self.played: list[str] = []
        self._graph: dict[str, Any] = {}  # played topics by their name in the graph
        self.unwatched: list[str] = []
        self.ready_seconds = 0.0
        self.died_at: int | None = None  # bag time the system was found dead, if it died during the run
        self.alive_result: AssertionResult | None = None
        self.heard: dict[str, int] = {}  # messages of the system per topic, as handed to the run
        self.clock_errors: list[float] = []
        self._queue: deque[tuple[str, float, bytes]] = deque()
        self._lock = threading.Lock()
        self._outputs: dict[str, OutputChannel] = {}
        self._recorder: Recorder | None = None
        self._thread: threading.Thread | None = None
        self._settled_at = 0.0  # monotonic time from which the system's side of every match has settled
        self._run: Run | None = None
        self._floor = 0  # nothing is handed over earlier than what was judged before
        self._last_look = 0.0
        self._unnamed_since: float | None = None  # when the system was first seen on a played topic, unnamed
        self.faults = ProcessFaults(scenario, process, listener)
        self.links = Links(scenario, seed)
        self.notes: list[str] = []  # what was done to the system before the bag played (links remapped)

    # -- before the first record --------------------------------------------------------------
    def prepare(self, routing: Routing) -> Mapping[str, Schema]:
        """Wait until the system is ready, subscribe to its topics; the schemas of those the oracles read."""
        self._graph = {p.topic_name: p for p in self._publishers.values()}  # as the graph names them
        self.played = sorted(self._graph)  # (a bag's `odom` is played as /odom, a remapped topic by its new name)
        started = time.monotonic()
        if self.watch is not None:
            self.watch.first_look()  # while the system starts: a domain other processes use is left for another
        for condition in self.system.conditions():
            self._await(condition)
        self.ready_seconds = time.monotonic() - started
        if self.links:
            self.notes += self.links.remap(self.process, self.listener, self.node, self.system.stop_timeout)
            for condition in self.system.conditions():  # the restarted subscriber is ready as the system was
                self._await(condition)
        self._check_shared(wait=True)
        own = {*self.played, *NOT_RECORDED}
        watched, self.unwatched = watched_topics(self.listener, self.scenario, self.stop, own=own, wait=WATCH_WAIT)
        record = self.system.record
        every = record == 'all'
        self._recorder = Recorder(self.listener, [] if record == 'all' else record, every,
                                  on_topic=self._on_topic, on_message=self._on_message,
                                  exclude={*NOT_RECORDED, *self.played},
                                  every_excludes=(*NOT_RECORDED, *OWN_PREFIXES), count_lost=True)
        self._recorder.discover()
        types = dict(self.listener.get_topic_names_and_types())
        for topic, link in self.links.links.items():
            if topic not in self._recorder.subscriptions:
                self._recorder.subscribe(topic, types[topic][0])  # heard to be passed on, so recorded too
            self._on_topic(link.remapped, types[topic][0], {})
        for topic, msgtype in watched.items():
            if topic not in self._recorder.subscriptions:
                self._recorder.subscribe(topic, msgtype)  # advertised later (a monitor's first report)
        # the recorder hears the system from the first played message on: its subscriptions, made just now,
        # have matched the system's publishers (a short bag leaves only its tail to hear the system in)
        deadline = time.monotonic() + RECORD_MATCH
        while self._recorder.unmatched() and time.monotonic() < deadline:
            time.sleep(POLL)
        # a publisher sees its subscriber first; the system's side of its subscriptions matches a moment later:
        # the first message waits that long (`_settled`), the run's setup meanwhile
        self._settled_at = time.monotonic() + MATCH_SETTLE
        if self.rate != 1 and self.clock_check:
            self._settled()
            self._hold_clock()
        return {topic: (msgtype, *self.catalog.schema(msgtype)) for topic, msgtype in watched.items()}

    def _settled(self) -> None:
        """Wait until the matches have settled (MATCH_SETTLE after the last was seen), then hear the system."""
        if self._thread is not None:
            return
        time.sleep(max(0.0, self._settled_at - time.monotonic()))
        self._thread = threading.Thread(target=self._spin, name='bagfault-test-listener', daemon=True)
        self._thread.start()

    def _hold_clock(self) -> None:
        """HOLD seconds before the first /clock: what the system publishes now, it publishes on wall time."""
        began = time.monotonic()
        self._hold = (began + GRACE, began + HOLD)
        while time.monotonic() < began + HOLD:
            if self.stop.is_set():
                raise Stopped(self.stop.reason)
            time.sleep(POLL)

    def _await(self, condition: ReadyCondition) -> None:
        """One ready condition, or ClosedLoopError when the system exits or the timeout passes."""
        deadline = time.monotonic() + (condition.seconds if condition.kind == 'delay' else condition.timeout)
        seen: set[str] = set()
        probe = None
        while True:
            if self.stop.is_set():
                raise Stopped(self.stop.reason)
            if not self.process.alive():
                raise ClosedLoopError(f'the system under test exited with {describe_exit(self.process.returncode)} '
                                      f'before it was ready (waiting for {condition.describe()})',
                                      tail=self.process.tail())
            self.process.watch()
            if self.watch is not None:
                self.watch.look()
            if condition.kind == 'delay':
                if time.monotonic() >= deadline:
                    return
            elif condition.kind == 'message':
                if probe is None and self.listener.count_publishers(condition.name):
                    probe = self._probe(condition.name, seen)
                if seen:
                    self.listener.destroy_subscription(probe)
                    return
            elif self._met(condition):
                return
            if time.monotonic() >= deadline:
                raise ClosedLoopError(f'the system under test was not ready after {condition.timeout:g} s: still '
                                      f'waiting for {condition.describe()}', tail=self.process.tail())
            if condition.kind == 'message':
                self.executor.spin_once(timeout_sec=POLL)
            else:
                time.sleep(POLL)

    def _probe(self, topic: str, seen: set[str]) -> Any:
        from bagfault.live.ros import interface_class  # noqa: PLC0415

        types = dict(self.listener.get_topic_names_and_types()).get(topic) or []
        if not types:
            return None
        return self.listener.create_subscription(interface_class(types[0]), topic, lambda _d: seen.add(topic),
                                                 10, raw=True)

    def _met(self, condition: ReadyCondition) -> bool:
        if condition.kind == 'publisher':
            return bool(self.listener.count_publishers(condition.name))
        if condition.kind == 'service':
            return any(name == condition.name for name, _ in self.listener.get_service_names_and_types())
        if condition.kind == 'subscribes':
            topics = self.played if condition.topics == 'played' else list(condition.topics)
            named = {**self._publishers, **self._graph}
            missing = [t for t in topics if t not in named]
            if missing:
                raise ClosedLoopError(f'ready: {", ".join(missing)} is not a topic this bag plays '
                                      f'(it plays {", ".join(self.played) or "nothing"})')
            return all(named[t].get_subscription_count() > 0 for t in topics)
        # default: the system subscribes to at least one played topic, and every such subscription is matched
        subscribed = [t for t in self.played if self.listener.count_subscribers(t) > 0]
        return bool(subscribed) and all(
            self._graph[t].get_subscription_count() >= self.listener.count_subscribers(t) for t in subscribed)

    def _spin(self) -> None:
        while not self.stop.is_set() and self._thread is not None:
            try:
                self.executor.spin_once(timeout_sec=0.05)
            except Exception:  # noqa: BLE001 - shutting down: the context is gone
                return

    # -- the system's messages ---------------------------------------------------------------
    def _on_topic(self, topic: str, msgtype: str, metadata: dict[str, str]) -> None:
        channel = self.record_only(topic, msgtype, *self.catalog.schema(msgtype),
                                   metadata=metadata)
        codec = self.catalog.codec(msgtype)
        if codec is not None and has_header(msgtype, codec.store):
            self._stamped.add(topic)
        self._outputs[topic] = OutputChannel(channel, topic, msgtype)

    def _on_message(self, topic: str, data: bytes) -> None:
        now = time.monotonic()
        passed = self.links.heard(topic, self.bag_time_now(), data) if topic in self.links.links else []
        with self._lock:
            self._queue.append((topic, now, data))
            self._queue.extend((remapped, now, payload) for remapped, payload in passed)
            if self._hold[0] <= now <= self._hold[1]:
                self.clocks.during_hold(topic)

    def begin(self, run: Run) -> None:
        """Messages of the system go into this run; its events go out live; the first message waits for the
        matches to settle."""
        super().begin(run)
        self._run = run
        self._settled()

    def _due(self, bag_time: int) -> None:
        self._hand_over(bag_time)
        self._floor = bag_time

    def _tick(self, bag_time: int) -> None:
        super()._tick(bag_time)
        released = self.links.due(bag_time) if self.links else []
        if released:
            now = time.monotonic()
            with self._lock:
                self._queue.extend((remapped, now, payload) for remapped, payload in released)
        now = time.monotonic()
        if now - self._last_look >= DISCOVERY_PERIOD:
            self._last_look = now
            if self._recorder is not None:
                self._recorder.discover()
            if self.watch is not None:
                self.watch.look()
            self._check_shared()
            self._check_alive(bag_time)
        self._hand_over(bag_time)

    def _check_shared(self, *, wait: bool = False) -> None:
        """ClosedLoopError when the system publishes a topic bagfault plays (undeclared: a declared one is not
        played); its messages would be judged as the bag's. The node is named once the graph says its name
        (NAME_WAIT at most: `wait` polls for it, else a later look says it)."""
        deadline = time.monotonic() + NAME_WAIT
        while True:
            found = shared(self.listener, self._graph, {pid16(pid) for pid in self.process.pids()}, os.getpid())
            if found is None:
                return
            if UNKNOWN not in found[1]:
                raise shared_error(*found)
            self._unnamed_since = self._unnamed_since or time.monotonic()
            if time.monotonic() - self._unnamed_since >= NAME_WAIT:
                raise shared_error(*found)
            if not wait or time.monotonic() >= deadline:
                return
            time.sleep(NAME_POLL)

    def _hand_over(self, upto: int) -> None:
        """Everything that arrived, into the run loop, stamped with its bag time of arrival (clamped)."""
        run = self._run
        if run is None or not self._queue:
            return
        with self._lock:
            items = list(self._queue)
            self._queue.clear()
        origin = self._origin
        wall, now = time.time_ns(), time.monotonic()
        for topic, arrived, data in items:
            stamp = upto if origin is None else origin[0] + round((arrived - origin[1]) * self.rate * NS)
            stamp = min(max(stamp, self._floor), upto)
            self._floor = stamp
            self.heard[topic] = self.heard.get(topic, 0) + 1
            if topic in self._stamped and origin is not None:
                self.clocks.stamp(topic, data, stamp, wall - round((now - arrived) * NS))
            run.message(self._outputs[topic], stamp, stamp, data)

    def act(self, event: FaultEvent) -> str:
        """A process fault's change is carried out on the system; a clock fault's on /clock."""
        return self.faults.act(event) or self.links.act(event) or super().act(event)

    def _check_alive(self, bag_time: int) -> None:
        if self.died_at is not None or self.process.alive():
            if self.died_at is None:
                self.process.watch()
            return
        if self.faults.died_by_us(self.process.pid, self.process.returncode):
            return  # a process fault's kill: not a crash (restarted when the fault ends, if it says so)
        self.died_at = bag_time
        code = self.process.returncode
        self._verdict('failed', bag_time, f'the system under test exited with {describe_exit(code)} during the run')

    def _verdict(self, state: AssertionState, time_ns: int, message: str) -> None:
        origin = self._run.stats.origin if self._run is not None else None
        seconds = (time_ns - (origin if origin is not None else time_ns)) / NS
        text = f'{message} (found at {seconds:.3f} s)' if state == 'failed' else message
        self.alive_result = AssertionResult(SYSTEM_ALIVE, SYSTEM_ALIVE, state, time_ns, text)
        if self._run is not None:
            self._run.write_event(AssertionEvent(time_ns, SYSTEM_ALIVE, SYSTEM_ALIVE, state, text))

    # -- after the last record ----------------------------------------------------------------------
    def finish(self, run: Run) -> None:
        """/clock on for `tail` seconds of bag time, the system's last answers handed over, the alive verdict."""
        if self._origin is None:
            self._hand_over(run.stats.origin or 0)
            return
        end = max(self.clock_value, 0) + round(self.system.tail * NS)
        while True:
            if self.stop.is_set():
                raise Stopped(self.stop.reason)
            now = self.looked_now()
            assert now is not None
            if now >= end:
                break
            self._tick(now)
            time.sleep(min(0.01, (end - now) / NS / self.rate))
        self._reached(end)
        if self.watch is not None:
            self.watch.look(now=True)  # before any verdict: a stranger that joined late spoils them too
        self._check_shared(wait=True)
        self._hand_over(end)
        self._check_alive(end)
        if self.died_at is None and not self.process.alive():  # a process fault's kill without restart
            self._verdict('passed', end, 'the system under test ran until a process fault killed it (not a crash)')
        elif self.died_at is None:
            self._verdict('passed', end, 'the system under test ran until the end of the bag and its tail')

    def lost(self) -> dict[str, int]:
        """Messages of the system known lost before they were heard, per topic (see Recorder.lost)."""
        return self._recorder.lost() if self._recorder is not None else {}

    def close(self) -> None:
        """Paused or throttled processes go on; stop the listener thread."""
        self.faults.close()
        thread, self._thread = self._thread, None
        if thread is not None:
            thread.join(timeout=2.0)
