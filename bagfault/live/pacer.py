"""A run-loop sink that plays records at their wall time: pacing, pause, speed, seek; no ROS needed.

The base of `LiveSink` (which adds publishers and /clock) and, on its own,
what `play --foxglove` uses where rclpy is not installed. Each record's due
wall time is (bag time - the first record's) / rate after the first was
played; `gate` sleeps until then. Pausing holds the timeline, a new rate
re-anchors it at the current bag time, and a seek ends the pass
(`Stopped('seek')`) so the player starts a new one that skips to the
requested time. Records are recorded (an MCAP sink) and shown (a view) as
they are played.
"""

from __future__ import annotations

import threading
import time
from typing import TYPE_CHECKING, Any, Protocol

from bagfault.engine.stop import Stopped
from bagfault.units import NS

if TYPE_CHECKING:
    from collections.abc import Mapping, Sequence

    from bagfault.engine.run import Run
    from bagfault.engine.stop import StopFlag
    from bagfault.events import FaultEvent
    from bagfault.io.mcap_sink import McapSink

CLOCK_PERIOD = 0.01  # ticks (and /clock) at 100 Hz while waiting for the next record
SLICE = 0.05  # longest sleep between checks of the stop flag
STALL = 0.1  # seconds between two looks of the pacing thread that are a stall of bagfault, not its pace
SEEK = 'seek'
EVENT_PREFIXES = ('/fault_injection/', '/fault_manager/', '/bagfault/')  # bagfault's own: kept by --topics
CLOCK_TOPIC = '/clock'
CLOCK_NOTE = ("the bag's own /clock was not published (recorded only): bagfault's /clock, the bag time, is the "
              'only clock')


class View(Protocol):
    """Something that shows records as they are played (the Foxglove view)."""

    def add_channel(self, topic: str, msgtype: str, schema_encoding: str, schema_text: str,
                    message_encoding: str = 'cdr') -> int:
        """A channel; its id."""
        ...

    def write(self, channel_id: int, log_time: int, data: bytes | memoryview) -> None:
        """One record."""
        ...

    def attach(self, run: Run) -> None:
        """A pass begins: its events go to the view."""
        ...

    def played(self, bag_time: int) -> None:
        """The timeline reached `bag_time`."""
        ...


class Pacer:
    """Plays records at their time into a recording and a view (a sink and the pass hooks of the run loop)."""

    def __init__(self, *, rate: float, stop: StopFlag, recording: McapSink | None = None,
                 topics: Sequence[str] = (), skip: float = 0.0, clock_hz: float = 1 / CLOCK_PERIOD,
                 view: View | None = None, settle: float = 0.0, hold_stalls: bool = False) -> None:
        self.rate = rate
        self.hold_stalls = hold_stalls  # a stall of bagfault holds the timeline (the closed loop's sim time)
        self.held = 0.0  # seconds the timeline held for stalls of bagfault
        self._looked: float | None = None  # when the pacing thread last looked at the time
        self.stop = stop
        self.recording = recording
        self.view = view
        self.settle = settle  # seconds before the first record (discovery)
        self.topics = set(topics)  # only these are played and recorded (all when empty; events always)
        self.skip = round(skip * NS)  # bag ns from the first record that are not played (--start-offset, seek)
        self.clock_period = 1.0 / clock_hz
        self.offset = 0  # added to bag times: loops continue the timeline
        self.clock_value = -1  # the bag time the timeline last reached (what /clock said), ns
        self.published = 0
        self.published_per_topic: dict[str, int] = {}
        self._channels: dict[tuple[str, str], int] = {}
        self._entries: list[tuple[Any, int | None, int | None]] = []  # publisher, recording id, view id
        self._names: list[str] = []
        self._first: int | None = None
        self._origin: tuple[int, float] | None = None  # (bag time, monotonic) the timeline is anchored at
        self._last_tick = 0.0
        self._lock = threading.Lock()
        self.paused = False
        self._paused_at = 0.0
        self.seek_to: int | None = None  # a bag time asked for: the pass ends and the next starts there
        self.prepared = False  # the first pass waited for the graph; later passes (loops, seeks) do not

    # -- sink ---------------------------------------------------------------------------------
    def add_channel(self, topic: str, msgtype: str, schema_encoding: str, schema_text: str,
                    message_encoding: str = 'cdr', metadata: dict[str, str] | None = None) -> int:
        """A channel (same id for a topic seen again): played, recorded, shown, unless left out by `topics`."""
        key = (topic, msgtype)
        found = self._channels.get(key)
        if found is not None:
            return found
        if self.topics and topic not in self.topics and not topic.startswith(EVENT_PREFIXES):
            number = self._register(key, None, schema_encoding, schema_text, message_encoding, metadata, keep=False)
        else:
            number = self._register(key, self._publisher(topic, msgtype, metadata), schema_encoding, schema_text,
                                    message_encoding, metadata)
        self._channels[key] = number
        return number

    def _publisher(self, topic: str, msgtype: str, metadata: dict[str, str] | None) -> Any:
        """Where a topic is published (nothing here; ROS publishers in LiveSink)."""
        return None

    def record_only(self, topic: str, msgtype: str, schema_encoding: str, schema_text: str,
                    metadata: dict[str, str] | None = None) -> int:
        """A channel that is recorded and shown, never published (what a system under test publishes; a
        channel of its own beside the played one when the system publishes on a topic the bag plays)."""
        return self._register((topic, msgtype), None, schema_encoding, schema_text, 'cdr', metadata)

    def _register(self, key: tuple[str, str], publisher: Any, schema_encoding: str, schema_text: str,
                  message_encoding: str, metadata: dict[str, str] | None, *, keep: bool = True) -> int:
        recorded = shown = None
        if keep and self.recording is not None:
            recorded = self.recording.add_channel(key[0], key[1], schema_encoding, schema_text, message_encoding,
                                                  metadata)
        if keep and self.view is not None:
            shown = self.view.add_channel(key[0], key[1], schema_encoding, schema_text, message_encoding)
        self._entries.append((publisher, recorded, shown))
        self._names.append(key[0])
        return len(self._entries) - 1

    def write(self, channel_id: int, log_time: int, publish_time: int, data: bytes | memoryview) -> None:
        """Play one record (its time has come: `gate` waited for it): publish, record, show."""
        if self._skipping(log_time):
            return
        publisher, recorded, shown = self._entries[channel_id]
        if publisher is not None:
            publisher.publish(data if isinstance(data, bytes) else bytes(data))
            self.published += 1
            topic = self._names[channel_id]
            self.published_per_topic[topic] = self.published_per_topic.get(topic, 0) + 1
        if recorded is not None and self.recording is not None:
            self.recording.write(recorded, log_time + self.offset, publish_time + self.offset, data)
        if shown is not None and self.view is not None:
            self.view.write(shown, log_time + self.offset, data)

    # -- pass hooks -------------------------------------------------------------------------------
    def prepare(self, routing: Any) -> Mapping[str, tuple[str, str, str]]:
        """Before the first record of the first pass: the settle time."""
        if not self.prepared:
            self.prepared = True
            if self.stop.wait(self.settle):
                raise Stopped(self.stop.reason)
        return {}

    def begin(self, run: Run) -> None:
        """A pass begins: its events go to the view."""
        if self.view is not None:
            self.view.attach(run)

    def _skipping(self, bag_time: int) -> bool:
        """True for records before the skip point (judged, neither played nor recorded)."""
        if not self.skip:
            return False
        if self._first is None:
            self._first = bag_time
        return bag_time - self._first < self.skip

    def gate(self, bag_time: int) -> None:
        """Wait until the record's wall time, ticking meanwhile; hold while paused; end the pass on a seek."""
        if self._skipping(bag_time):
            return
        stamp = bag_time + self.offset
        if self._origin is None:
            self._origin = (stamp, time.monotonic())
        while True:
            if self.stop.is_set():
                raise Stopped(self.stop.reason)
            if self.seek_to is not None:
                raise Stopped(SEEK)
            now = time.monotonic()
            with self._lock:
                self._look(now)
                first, started = self._origin
                due = started + (stamp - first) / NS / self.rate
                paused = self.paused
            if not paused and now >= due:
                break
            if not paused:
                self._tick(first + round((now - started) * self.rate * NS))
            elif now - self._last_tick >= self.clock_period:
                self._last_tick = now
                if self.recording is not None:
                    self.recording.tick()
            time.sleep(min(max(due - now, 0.0) if not paused else SLICE, SLICE, self.clock_period))
        self._due(stamp)
        self._reached(stamp)

    def finish(self, run: Run) -> None:
        """Nothing after the last record of a plain play."""

    def act(self, event: FaultEvent) -> str:
        """Nothing to carry out without a clock or a system (LiveSink and the closed loop's link do)."""
        return ''

    def delivered(self, timeout: float) -> list[str]:
        """The topics whose subscribers have not acknowledged every message within `timeout` (none here)."""
        return []

    def _look(self, now: float) -> None:
        """With `hold_stalls`: when the pacing thread looks more than STALL after its last look, bagfault stalled
        (a busy machine, a long pause of the collector, swapping); the timeline's anchor moves by the stall, so
        the clock holds where it was instead of jumping ahead and the records due meanwhile do not come in a burst
        (sim time: the system under test sees bag time go on as recorded; `rate` stays true between stalls).
        The caller holds the lock."""
        if self.hold_stalls and self._looked is not None and self._origin is not None and not self.paused:
            stalled = now - self._looked
            if stalled > STALL:
                first, started = self._origin
                self._origin = (first, started + stalled)
                self.held += stalled
        self._looked = now

    def _tick(self, bag_time: int) -> None:
        """While waiting: every clock period the timeline's time goes out; the recording's chunk when due."""
        if time.monotonic() - self._last_tick >= self.clock_period:
            self._last_tick = time.monotonic()
            self._reached(bag_time)
        if self.recording is not None:
            self.recording.tick()

    def _due(self, bag_time: int) -> None:
        """The record at `bag_time` is due, the timeline not yet at it (a subclass hands over what came before)."""

    def _reached(self, bag_time: int) -> None:
        """The timeline reached `bag_time` (/clock in LiveSink, the time in the view)."""
        if bag_time <= self.clock_value:
            return
        self.clock_value = bag_time
        if self.view is not None:
            self.view.played(bag_time)

    def bag_time_now(self) -> int | None:
        """The bag time that corresponds to now (None before the first record)."""
        with self._lock:
            if self._origin is None:
                return None
            first, started = self._origin
            if self.paused:
                return self.clock_value
            return first + round((time.monotonic() - started) * self.rate * NS)

    def looked_now(self) -> int | None:
        """The pacing thread's bag time now, after a look (a stall since the last one held the timeline)."""
        with self._lock:
            self._look(time.monotonic())
        return self.bag_time_now()

    # -- playback controls (any thread) ---------------------------------------------------------------
    def pause(self) -> None:
        """Hold the timeline where it is."""
        with self._lock:
            if not self.paused:
                self.paused = True
                self._paused_at = time.monotonic()
                self._looked = None  # a pause is no stall (resume moves the anchor by it)

    def resume(self) -> None:
        """Go on from where it was held."""
        with self._lock:
            if self.paused and self._origin is not None:
                first, started = self._origin
                self._origin = (first, started + time.monotonic() - self._paused_at)
            self.paused = False

    def set_rate(self, rate: float) -> None:
        """A new speed from the current bag time on."""
        if not rate > 0:
            return
        current = self.bag_time_now()
        with self._lock:
            if self._origin is not None and current is not None:
                self._origin = (current, self._paused_at if self.paused else time.monotonic())
                self._looked = None
            self.rate = rate

    def seek(self, bag_time: int) -> None:
        """Ask for the timeline to continue from `bag_time` (the current pass ends at its next record)."""
        self.seek_to = bag_time

    def seeking(self) -> bool:
        """True when a seek was asked for and the next pass must start there."""
        return self.seek_to is not None

    def restart(self, first: int) -> None:
        """The next pass skips to the time asked for (the bag's first record is at `first`)."""
        target = self.seek_to if self.seek_to is not None else first
        self.seek_to = None
        self.skip = max(0, target - first)
        self._first = None
        self._origin = None
        self._looked = None
        self.clock_value = -1
