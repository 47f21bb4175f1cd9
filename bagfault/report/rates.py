"""Per-topic message times, collected while the output is written, and the rates they give.

A rate over fixed bins draws a 2 Hz topic as a comb between 0 and 10 Hz.
Here each topic gets a window matched to its nominal rate: k messages
spanning about two seconds (k = 1 for topics under 0.5 Hz), and the rate at
a message is k divided by the time the last k intervals took. Gaps (an
interval over three nominal periods) are listed so plots can mark them.
"""

from __future__ import annotations

from array import array
from dataclasses import dataclass

import numpy as np

from bagfault.units import NS

EVENT_TOPIC_PREFIXES = ('/fault_injection/', '/fault_manager/')
FEW = 10  # topics with fewer messages are drawn as events, not rates


@dataclass
class RateSeries:
    """One topic's rate at each message (s, Hz), its nominal rate and its gaps (start s, end s)."""

    times: np.ndarray
    rates: np.ndarray
    nominal_hz: float
    window: int
    gaps: list[tuple[float, float]]


class RateTracker:
    """Observer keeping every message time per topic (8 bytes a message)."""

    def __init__(self) -> None:
        self.origin = 0
        self.times: dict[str, array[int]] = {}

    def start(self, origin: int) -> None:
        """Bag time zero."""
        self.origin = origin

    def on_message(self, topic: str, time: int, data: object) -> None:
        """Note one message."""
        times = self.times.get(topic)
        if times is None:
            times = self.times[topic] = array('q')
        times.append(time)

    def on_event(self, event: object) -> None:
        """Events are not counted."""

    def finish(self, time: int) -> None:
        """Nothing to close."""

    def seconds(self, topic: str) -> np.ndarray:
        """Message times of a topic in seconds from time zero, sorted."""
        raw = np.frombuffer(self.times.get(topic, array('q')), dtype=np.int64)
        return np.sort((raw - self.origin) / NS)

    def is_event_topic(self, topic: str) -> bool:
        """bagfault's event channels, topics with a handful of messages and bursts (all messages within a
        quarter of the bag, as /rosout at start-up): markers, not rates."""
        times = self.times.get(topic, ())
        if topic.startswith(EVENT_TOPIC_PREFIXES) or len(times) < FEW:
            return True
        ends = [(min(t), max(t)) for t in self.times.values() if t]
        whole = max(e for _, e in ends) - min(s for s, _ in ends)
        return max(times) - min(times) < 0.25 * whole

    def series(self, topic: str) -> RateSeries:
        """The topic's rate at each message over a window matched to its nominal rate."""
        return rate_series(self.seconds(topic))


def rate_series(times: np.ndarray) -> RateSeries:
    """Rate at each message from the k previous intervals, k spanning about two seconds."""
    if times.size < 2:
        return RateSeries(times, np.full(times.size, np.nan), 0.0, 1, [])
    intervals = np.diff(times)
    positive = intervals[intervals > 0]
    period = float(np.median(positive)) if positive.size else 0.0
    nominal = 1.0 / period if period > 0 else 0.0
    window = max(1, min(round(2 * nominal), times.size - 1))
    rates = np.full(times.size, np.nan)
    spans = times[window:] - times[:-window]
    with np.errstate(divide='ignore'):
        rates[window:] = np.where(spans > 0, window / spans, np.nan)
    long = np.flatnonzero(intervals > 3 * period) if period > 0 else np.zeros(0, dtype=int)
    gaps = [(float(times[i]), float(times[i + 1])) for i in long]
    return RateSeries(times, rates, nominal, window, gaps)
