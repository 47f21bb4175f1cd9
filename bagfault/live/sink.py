"""A run-loop sink that publishes on live topics, paced to wall time, and records what it sent.

The sink is also the pass hooks of the run loop: before the first message
it waits for the graph (subscribers of named topics, or a settle time);
before each record is judged (`gate`) it waits until the record's wall
time (bag time x 1/rate after the first), publishing /clock meanwhile.
Then it publishes the bytes on the record's topic with the recorded QoS and
writes the same record to the recording (an MCAP sink). Types without
Python bindings here (for example bagfault's own event types) are recorded
but not published. When the stop flag is set it raises `Stopped`, which
ends the pass.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any

from bagfault.engine.stop import Stopped
from bagfault.errors import LiveError
from bagfault.live.ros import has_interface, interface_class, qos, recorded_qos

if TYPE_CHECKING:
    from collections.abc import Mapping, Sequence

    from bagfault.engine.stop import StopFlag
    from bagfault.io.mcap_sink import McapSink

CLOCK_PERIOD = 0.01  # /clock at 100 Hz while waiting for the next message (--clock HZ changes it)
MATCH_WAIT = 5.0  # seconds after the settle time to wait for subscribers the graph knows to be matched
SLICE = 0.05  # longest sleep between checks of the stop flag


class LiveSink:
    """Publishes pipeline records on live topics at their time (a sink and the pass hooks of the run loop)."""

    def __init__(self, node: Any, *, rate: float, clock: bool, stop: StopFlag,
                 recording: McapSink | None = None, settle: float = 0.0, wait_for: Sequence[str] = (),
                 wait_timeout: float = 30.0, clock_hz: float = 1 / CLOCK_PERIOD, topics: Sequence[str] = (),
                 skip: float = 0.0) -> None:
        self.node = node
        self.rate = rate
        self.stop = stop
        self.recording = recording
        self.settle = settle  # seconds between creating the publishers and the first message, for discovery
        self.wait_for = list(wait_for)  # or: topics whose publishers must first have a subscriber ('all': every one)
        self.wait_timeout = wait_timeout
        self.clock_period = 1.0 / clock_hz
        self.topics = set(topics)  # only these are published and recorded (all when empty)
        self.skip = round(skip * 1e9)  # bag ns from the first message that are not played (--start-offset)
        self._first: int | None = None
        self._events: Any = None
        self.offset = 0  # added to bag times: loops continue the timeline
        self._channels: dict[tuple[str, str], int] = {}
        self._topics: list[tuple[Any, int | None]] = []  # publisher, recording channel id
        self._names: list[str] = []  # topic of each channel id
        self._publishers: dict[str, Any] = {}
        self._clock = None
        if clock:
            clock_type = interface_class('rosgraph_msgs/msg/Clock')
            self._clock = node.create_publisher(clock_type, '/clock', qos(1))
            self._clock_message = clock_type()
        self._origin: tuple[int, float] | None = None
        self._last_clock = 0.0
        self.clock_value = -1  # the bag time /clock last said (or would have said), ns
        self.published = 0
        self.published_per_topic: dict[str, int] = {}
        self.skipped: dict[str, str] = {}

    # -- sink ---------------------------------------------------------------------------------
    def add_channel(self, topic: str, msgtype: str, schema_encoding: str, schema_text: str,
                    message_encoding: str = 'cdr', metadata: dict[str, str] | None = None) -> int:
        """A publisher (when the type is installed) and a recording channel; same id for a topic seen again."""
        key = (topic, msgtype)
        found = self._channels.get(key)
        if found is not None:
            return found
        publisher = None
        if self.topics and topic not in self.topics:
            return self._register(key, None, schema_encoding, schema_text, message_encoding, metadata, record=False)
        if has_interface(msgtype):
            profile = recorded_qos((metadata or {}).get('offered_qos_profiles', '')) or qos(10)
            publisher = self.node.create_publisher(interface_class(msgtype), topic, profile)
            self._publishers[topic] = publisher
        elif not topic.startswith(('/fault_injection/', '/fault_manager/')):
            self.skipped[topic] = msgtype
        return self._register(key, publisher, schema_encoding, schema_text, message_encoding, metadata)

    def record_only(self, topic: str, msgtype: str, schema_encoding: str, schema_text: str,
                    metadata: dict[str, str] | None = None) -> int:
        """A channel that is recorded and never published (what the system under test publishes)."""
        return self._register((topic, msgtype), None, schema_encoding, schema_text, 'cdr', metadata)

    def _register(self, key: tuple[str, str], publisher: Any, schema_encoding: str, schema_text: str,
                  message_encoding: str, metadata: dict[str, str] | None, *, record: bool = True) -> int:
        recorded = None
        if self.recording is not None and record:
            recorded = self.recording.add_channel(key[0], key[1], schema_encoding, schema_text, message_encoding,
                                                  metadata)
        self._topics.append((publisher, recorded))
        self._names.append(key[0])
        self._channels[key] = len(self._topics) - 1
        return len(self._topics) - 1

    def write(self, channel_id: int, log_time: int, publish_time: int, data: bytes | memoryview) -> None:
        """Publish one record (its time has come: `gate` waited for it) and record it."""
        if self._skipping(log_time):
            return
        publisher, recorded = self._topics[channel_id]
        if publisher is not None:
            publisher.publish(data if isinstance(data, bytes) else bytes(data))
            self.published += 1
            topic = self._names[channel_id]
            self.published_per_topic[topic] = self.published_per_topic.get(topic, 0) + 1
        if recorded is not None and self.recording is not None:
            self.recording.write(recorded, log_time + self.offset, publish_time + self.offset, data)

    # -- pass hooks -------------------------------------------------------------------------------
    def prepare(self, routing: Any) -> Mapping[str, tuple[str, str, str]]:
        """Before the first message: wait until the named topics have subscribers (or a fixed settle time)."""
        if self._origin is not None:
            return {}  # a later pass of a loop: the graph is connected
        if self.wait_for:
            self.wait_for_subscribers(sorted(self._publishers) if self.wait_for == ['all'] else self.wait_for)
            return {}
        if self.stop.wait(self.settle):
            raise Stopped(self.stop.reason)
        deadline = time.monotonic() + MATCH_WAIT
        while time.monotonic() < deadline and self._unmatched():  # subscribers the graph knows, not matched yet
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
                return
            if time.monotonic() > deadline:
                raise LiveError(f'no subscriber on {", ".join(waiting)} within {self.wait_timeout:g} s')
            if self.stop.wait(0.02):
                raise Stopped(self.stop.reason)

    def begin(self, run: Any) -> None:
        """The run's events go out on /bagfault/events as they happen (nothing comes from outside a play)."""
        if self._events is None:
            from bagfault.live.events import LiveEvents  # noqa: PLC0415

            self._events = LiveEvents(self.node, anchor_topics=False)  # anchor-typed events: published as records
        self._events.attach(run)

    def _skipping(self, bag_time: int) -> bool:
        """True for records before --start-offset (judged, neither played nor recorded)."""
        if not self.skip:
            return False
        if self._first is None:
            self._first = bag_time
        return bag_time - self._first < self.skip

    def gate(self, bag_time: int) -> None:
        """Sleep until the record's wall time, publishing /clock meanwhile."""
        if self._skipping(bag_time):
            return
        stamp = bag_time + self.offset
        if self._origin is None:
            self._origin = (stamp, time.monotonic())
        first, started = self._origin
        due = started + (stamp - first) / 1e9 / self.rate
        while True:
            if self.stop.is_set():
                raise Stopped(self.stop.reason)
            now = time.monotonic()
            if now >= due:
                break
            self._tick(first + round((now - started) * self.rate * 1e9))
            time.sleep(min(due - now, SLICE, self.clock_period if self._clock is not None else SLICE))
        self._due(stamp)
        self._publish_clock(stamp)

    def finish(self, run: Any) -> None:
        """Nothing after the last message of a plain play."""

    def _tick(self, bag_time: int) -> None:
        """While waiting: /clock every clock period, the recording's chunk when it is due (and whatever a
        subclass does meanwhile)."""
        if time.monotonic() - self._last_clock >= self.clock_period:
            self._publish_clock(bag_time)
        if self.recording is not None:
            self.recording.tick()

    def _due(self, bag_time: int) -> None:
        """The record at `bag_time` is due, /clock not yet at it (a subclass hands over what came before)."""

    def bag_time_now(self) -> int | None:
        """The bag time that corresponds to now (None before the first record)."""
        if self._origin is None:
            return None
        first, started = self._origin
        return first + round((time.monotonic() - started) * self.rate * 1e9)

    def _publish_clock(self, bag_time: int) -> None:
        if bag_time <= self.clock_value:
            return
        self.clock_value = bag_time
        self._last_clock = time.monotonic()
        if self._clock is not None:
            self._clock_message.clock.sec, self._clock_message.clock.nanosec = divmod(bag_time, 1_000_000_000)
            self._clock.publish(self._clock_message)
