"""Receive times and header stamps of path topics, from a bag or from a run's output records."""

from __future__ import annotations

import struct
from collections import defaultdict
from typing import TYPE_CHECKING

import numpy as np

from bagfault.faults.header import has_header
from bagfault.io.sources import InputSet
from bagfault.io.types import TypeCatalog
from bagfault.latency.compute import TopicSeries
from bagfault.units import NS

if TYPE_CHECKING:
    from collections.abc import Sequence
    from pathlib import Path

    from bagfault.events import FaultEvent
    from bagfault.io.types import Codec



def stamp_of(data: bytes | memoryview) -> int:
    """header.stamp in ns, read from the CDR bytes (the header is the first field)."""
    sec, nanosec = struct.unpack_from('<iI' if data[1] else '>iI', data, 4)
    return int(sec) * NS + int(nanosec)


class SeriesCollector:
    """Accumulates (log_time, stamp) per topic; stamps only for types that start with a header."""

    def __init__(self, topics: dict[str, bool]) -> None:
        self.stamped = topics
        self.times: dict[str, list[int]] = defaultdict(list)
        self.stamps: dict[str, list[int]] = defaultdict(list)

    def add(self, topic: str, time: int, data: bytes | memoryview) -> None:
        """One message of a path topic."""
        if topic not in self.stamped:
            return
        self.times[topic].append(time)
        if self.stamped[topic]:
            self.stamps[topic].append(stamp_of(data))

    def series(self) -> dict[str, TopicSeries]:
        """Sorted series per topic."""
        out = {}
        for topic, stamped in self.stamped.items():
            times = np.asarray(self.times.get(topic, []), dtype=np.int64)
            order = np.argsort(times, kind='stable')
            stamps = np.asarray(self.stamps.get(topic, []), dtype=np.int64)[order] if stamped else None
            out[topic] = TopicSeries(times[order], stamps)
        return out


def read_series(paths: Sequence[Path], topics: Sequence[str]) -> tuple[dict[str, TopicSeries], list[FaultEvent]]:
    """Series of the given topics and the recorded fault events of one or more bags."""
    from bagfault.events import FaultEvent  # noqa: PLC0415

    with InputSet(list(paths)) as inputs:
        catalog = TypeCatalog(inputs.channels, inputs.ros_distro)
        stamped = _stamped(inputs, catalog, topics)
        collector = SeriesCollector(stamped)
        wanted = {i: c.topic for i, c in enumerate(inputs.channels) if c.topic in stamped}
        events_channel, event_codec = _event_channels(inputs, catalog)
        events: list[FaultEvent] = []
        for index, time, _, data in inputs.messages():
            topic = wanted.get(index)
            if topic is not None:
                collector.add(topic, time, data)
            elif index in events_channel and event_codec is not None:
                events.append(FaultEvent.from_message(time, event_codec.decode(data)))
        series = collector.series()
        for topic in topics:
            series.setdefault(topic, TopicSeries.empty())
        return series, events


def _event_channels(inputs: InputSet, catalog: TypeCatalog) -> tuple[set[int], Codec | None]:
    """The channels of recorded fault events, and their codec (None without such channels)."""
    from bagfault.events import FAULT_EVENT_TOPIC, FaultEvent  # noqa: PLC0415

    channels = {i for i, c in enumerate(inputs.channels) if c.topic == FAULT_EVENT_TOPIC}
    return channels, catalog.codec(FaultEvent.msgtype) if channels else None


def _stamped(inputs: InputSet, catalog: TypeCatalog, topics: Sequence[str]) -> dict[str, bool]:
    """Each of the topics the bags have: whether its type has a header stamp (a type not decodable has none)."""
    stamped = {}
    for channel in inputs.channels:
        if channel.topic in topics:
            codec = catalog.codec(channel.msgtype)
            stamped[channel.topic] = codec is not None and has_header(channel.msgtype, codec.store)
    return stamped


def fault_windows(events: Sequence[FaultEvent]) -> dict[str, list[tuple[int, int | None]]]:
    """Active intervals (ns) per fault from its events."""
    windows: dict[str, list[tuple[int, int | None]]] = {}
    open_: dict[str, int] = {}
    for event in events:
        if event.state == 'active' and event.fault_id not in open_:
            open_[event.fault_id] = event.time
        elif event.state == 'inactive' and event.fault_id in open_:
            windows.setdefault(event.fault_id, []).append((open_.pop(event.fault_id), event.time))
    for fault_id, start in open_.items():
        windows.setdefault(fault_id, []).append((start, None))
    return {k: sorted(v, key=lambda w: w[0]) for k, v in windows.items()}
