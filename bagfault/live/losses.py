"""Messages a subscriber knows it lost: gaps in one publisher's sequence numbers and what DDS reports lost.

A keep-last queue that overflowed while the executor was busy elsewhere
drops messages without a DDS event; only the publisher's sequence numbers,
handed over with each message by rclpy's single-threaded executor (its
events executor fails on them), show the gap. A loss is seen when a message
after it is heard: counted between the first and the last message heard.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Callable, Mapping

UNKNOWN_SEQUENCE = 2**64 - 1  # RMW_MESSAGE_INFO_SEQUENCE_NUMBER_UNSUPPORTED


class LossCount:
    """Per topic, the messages known lost: the larger of the sequence gaps and the DDS layer's count."""

    def __init__(self) -> None:
        self.gaps: dict[str, int] = {}
        self.reported: dict[str, int] = {}
        self._last: dict[str, int] = {}
        self._mixed: set[str] = set()  # topics seen with several publishers: no gap count

    def heard(self, topic: str, info: Mapping[str, int], publishers: Callable[[], int]) -> None:
        """A message arrived with its info; `publishers()` counts the topic's matched publishers (asked only when
        a gap shows: sequence numbers are a publisher's own, so with several a jump is another's, no loss)."""
        sequence = info.get('publication_sequence_number', 0)
        if not 0 < sequence < UNKNOWN_SEQUENCE or topic in self._mixed:
            return
        last = self._last.get(topic)
        if last is not None and sequence > last + 1:
            if publishers() == 1:
                self.gaps[topic] = self.gaps.get(topic, 0) + sequence - last - 1
            else:
                self._mixed.add(topic)
        self._last[topic] = sequence  # a smaller one: the publisher started again, counted from there

    def report(self, topic: str, total: int) -> None:
        """The DDS layer's running count of messages lost on a topic (a message_lost event)."""
        self.reported[topic] = int(total)

    def lost(self) -> dict[str, int]:
        """Messages known lost per topic (topics with none left out), sorted by topic."""
        topics = set(self.gaps) | set(self.reported)
        found = {topic: max(self.gaps.get(topic, 0), self.reported.get(topic, 0)) for topic in topics}
        return {topic: count for topic, count in sorted(found.items()) if count}
