"""A run-loop sink that publishes on live topics, paced to wall time, and records what it sent.

The offline pipeline hands records over in bag-time order; this sink holds
each one until its time has come (bag time x 1/rate after the first),
publishes /clock when asked, publishes the bytes on the record's topic with
the recorded QoS, and writes the same record to the recording (an MCAP
sink). Types without Python bindings here (for example bagfault's own
event types) are recorded but not published. When the stop flag is set it
raises `Stopped`, which ends the pass.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any

from bagfault.engine.stop import Stopped
from bagfault.live.ros import has_interface, interface_class, qos, recorded_qos

if TYPE_CHECKING:
    from bagfault.engine.stop import StopFlag
    from bagfault.io.mcap_sink import McapSink

CLOCK_PERIOD = 0.01  # /clock at 100 Hz while waiting for the next message
SLICE = 0.05  # longest sleep between checks of the stop flag


class LiveSink:
    """Publishes pipeline records on live topics at their time; see module docstring."""

    def __init__(self, node: Any, *, rate: float, clock: bool, stop: StopFlag,
                 recording: McapSink | None = None, settle: float = 0.0) -> None:
        self.node = node
        self.rate = rate
        self.stop = stop
        self.settle = settle  # seconds between creating the publishers and the first message, for discovery
        self.recording = recording
        self.offset = 0  # added to bag times: loops continue the timeline
        self._channels: dict[tuple[str, str], int] = {}
        self._topics: list[tuple[Any, int | None]] = []  # publisher, recording channel id
        self._clock = None
        if clock:
            clock_type = interface_class('rosgraph_msgs/msg/Clock')
            self._clock = node.create_publisher(clock_type, '/clock', qos(1))
            self._clock_message = clock_type()
        self._origin: tuple[int, float] | None = None
        self._last_clock = 0.0
        self._last_clock_value = -1
        self.published = 0
        self.skipped: dict[str, str] = {}

    def add_channel(self, topic: str, msgtype: str, schema_encoding: str, schema_text: str,
                    message_encoding: str = 'cdr', metadata: dict[str, str] | None = None) -> int:
        """A publisher (when the type is installed) and a recording channel; same id for a topic seen again."""
        key = (topic, msgtype)
        found = self._channels.get(key)
        if found is not None:
            return found
        publisher = None
        if has_interface(msgtype):
            profile = recorded_qos((metadata or {}).get('offered_qos_profiles', '')) or qos(10)
            publisher = self.node.create_publisher(interface_class(msgtype), topic, profile)
        elif not topic.startswith(('/fault_injection/', '/fault_manager/')):
            self.skipped[topic] = msgtype
        recorded = None
        if self.recording is not None:
            recorded = self.recording.add_channel(topic, msgtype, schema_encoding, schema_text, message_encoding,
                                                  metadata)
        self._topics.append((publisher, recorded))
        self._channels[key] = len(self._topics) - 1
        return len(self._topics) - 1

    def _publish_clock(self, bag_time: int) -> None:
        assert self._clock is not None
        if bag_time <= self._last_clock_value:
            return
        self._last_clock_value = bag_time
        self._clock_message.clock.sec, self._clock_message.clock.nanosec = divmod(bag_time, 1_000_000_000)
        self._clock.publish(self._clock_message)
        self._last_clock = time.monotonic()

    def _wait(self, bag_time: int) -> None:
        """Sleep until the record's wall time, publishing /clock meanwhile."""
        if self._origin is None:
            if self.stop.wait(self.settle):
                raise Stopped(self.stop.reason)
            self._origin = (bag_time, time.monotonic())
        first, started = self._origin
        due = started + (bag_time - first) / 1e9 / self.rate
        while True:
            if self.stop.is_set():
                raise Stopped(self.stop.reason)
            now = time.monotonic()
            if now >= due:
                break
            if self._clock is not None and now - self._last_clock >= CLOCK_PERIOD:
                self._publish_clock(first + round((now - started) * self.rate * 1e9))
            time.sleep(min(due - now, SLICE, CLOCK_PERIOD if self._clock is not None else SLICE))
        if self._clock is not None:
            self._publish_clock(bag_time)

    def write(self, channel_id: int, log_time: int, publish_time: int, data: bytes | memoryview) -> None:
        """Publish one record when its time has come, and record it."""
        publisher, recorded = self._topics[channel_id]
        stamp = log_time + self.offset
        self._wait(stamp)
        if publisher is not None:
            publisher.publish(data if isinstance(data, bytes) else bytes(data))
            self.published += 1
        if recorded is not None and self.recording is not None:
            self.recording.write(recorded, stamp, publish_time + self.offset, data)
