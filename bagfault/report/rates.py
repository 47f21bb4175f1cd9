"""Per-topic message rate over bag time, collected while the output is written."""

from __future__ import annotations

NS = 1_000_000_000


class RateTracker:
    """Observer counting messages per topic in time bins; bins widen to stay under `max_bins`."""

    def __init__(self, bin_s: float = 0.1, max_bins: int = 2000) -> None:
        self.width = round(bin_s * NS)
        self.max_bins = max_bins
        self.origin = 0
        self.bins: dict[str, dict[int, int]] = {}
        self._high = 0

    def start(self, origin: int) -> None:
        """Bag time zero."""
        self.origin = origin

    def on_message(self, topic: str, time: int, data: object) -> None:
        """Count one message."""
        index = (time - self.origin) // self.width
        if index >= self.max_bins:
            self._coarsen(index)
            index = (time - self.origin) // self.width
        self._high = max(self._high, index)
        counts = self.bins.get(topic)
        if counts is None:
            counts = self.bins[topic] = {}
        counts[index] = counts.get(index, 0) + 1

    def _coarsen(self, index: int) -> None:
        while index >= self.max_bins:
            self.width *= 2
            index //= 2
            for topic, counts in self.bins.items():
                merged: dict[int, int] = {}
                for key, value in counts.items():
                    merged[key // 2] = merged.get(key // 2, 0) + value
                self.bins[topic] = merged
            self._high //= 2

    def on_event(self, event: object) -> None:
        """Events are not counted."""

    def finish(self, time: int) -> None:
        """Nothing to close."""

    def series(self, topic: str) -> tuple[list[float], list[float]]:
        """(bin start s, rate Hz) for every bin from zero to the last one, zeros included."""
        counts = self.bins.get(topic, {})
        seconds = self.width / NS
        indexes = range(min(counts, default=0), self._high + 1)
        return [i * seconds for i in indexes], [counts.get(i, 0) / seconds for i in indexes]
