"""The caret_demos `target` path as a synthetic bag, with its true end-to-end latencies (the latency tests)."""

from __future__ import annotations

from typing import Any

import numpy as np
from rosbags.typesys.store import Typestore

from bagfault.demo.synthetic import DEFAULT_START, Stream, _header, sample_times, store
from bagfault.units import NS

CARET_TOPICS = ('/topic1', '/topic2', '/topic3', '/topic4')


def tiny_image(ts: Typestore, stamp: int, frame: str = 'camera') -> Any:
    """2x2 mono8 Image carrying a header stamp (the caret_demos path's message)."""
    return ts.types['sensor_msgs/msg/Image'](
        header=_header(ts, stamp, frame), height=2, width=2, encoding='mono8', is_bigendian=0, step=2,
        data=np.arange(4, dtype=np.uint8))


def caret_target_messages(
    duration: float,
    delays_ms: tuple[float, float, float] = (10.0, 20.0, 30.0),
    jitter_ms: tuple[float, float, float] = (0.0, 0.0, 0.0),
    *,
    seed: int = 0,
    timer_hz: float | None = None,
    start: int = DEFAULT_START,
    ts: Typestore | None = None,
) -> tuple[list[tuple[Stream, int, Any]], list[tuple[int, int]]]:
    """The caret_demos `target` path as a bag, and its true end-to-end samples.

    /topic1 at 10 Hz from the sensor; filter, message_driven and timer_driven
    nodes forward after delays_ms (+ uniform jitter in [0, jitter_ms]); header.stamp
    is set once by the sensor and carried along; /drive at 10 Hz feeds
    message_driven too. With timer_hz, timer_driven republishes its latest
    input on a timer of its own, so /topic4 repeats stamps. Returns the records
    and the true (topic4 time, topic1 time) pairs.
    """
    ts = ts or store()
    rng = np.random.default_rng(seed)
    streams = {t: Stream(t, 'sensor_msgs/msg/Image', 10.0) for t in CARET_TOPICS}
    drive = Stream('/drive', 'sensor_msgs/msg/Image', 10.0)
    ms = 1_000_000
    records: list[tuple[int, int, Stream, Any]] = []
    chain: list[tuple[int, int]] = []  # (topic3 time, topic1 time)
    truth: list[tuple[int, int]] = []
    for number, t1 in enumerate(sample_times(10.0, duration, start)):
        t2 = t1 + round((delays_ms[0] + rng.uniform(0, jitter_ms[0])) * ms)
        t3 = t2 + round((delays_ms[1] + rng.uniform(0, jitter_ms[1])) * ms)
        t4 = t3 + round((delays_ms[2] + rng.uniform(0, jitter_ms[2])) * ms)
        records += [(t1, 0, streams['/topic1'], tiny_image(ts, t1)), (t2, 1, streams['/topic2'], tiny_image(ts, t1)),
                    (t3, 2, streams['/topic3'], tiny_image(ts, t1)), (t1 + 5 * ms, 4, drive, tiny_image(ts, t1))]
        chain.append((t3, t1))
        if timer_hz is None:
            records.append((t4, 3, streams['/topic4'], tiny_image(ts, t1)))
            truth.append((t4, t1))
        _ = number
    if timer_hz is not None:
        period = round(NS / timer_hz)
        tick = start + round(delays_ms[2] * ms)
        end = start + round(duration * NS) + round(sum(delays_ms) * ms)
        while tick < end:
            latest = [c for c in chain if c[0] <= tick]
            if latest:
                _, origin = latest[-1]
                records.append((tick, 3, streams['/topic4'], tiny_image(ts, origin)))
                truth.append((tick, origin))
            tick += period
    records.sort(key=lambda r: (r[0], r[1]))
    return [(stream, time, message) for time, _, stream, message in records], truth
