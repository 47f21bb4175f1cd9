"""Several sources seen as one bag: the one multi-source merge (inputs of a run, files of a rosbag2 bag)."""

from __future__ import annotations

import heapq
from dataclasses import replace
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator, Sequence

    from typing_extensions import Self

    from bagfault.io.channel import Channel, Data, InputMessage
    from bagfault.io.source import Source


class MergedSource:
    """Several sources seen as one: channels united by (topic, type, encoding), messages merged by log time.

    The first source that declares a channel gives its definition and
    metadata (after `adjust`); a later one fills in a definition the first
    lacked. Messages with equal log times keep the order of the sources.
    """

    def __init__(self, parts: Sequence[Source], *, adjust: Callable[[Channel], Channel] | None = None,
                 ros_distro: str | None = None) -> None:
        self.parts = list(parts)
        self.own_warnings: list[str] = []
        self.channels: list[Channel] = []
        self._maps: list[list[int]] = []
        index: dict[tuple[str, str, str], int] = {}
        for part in self.parts:
            mapping = []
            for channel in part.channels:
                key = (channel.topic, channel.msgtype, channel.message_encoding)
                known = index.get(key)
                if known is None:
                    index[key] = len(self.channels)
                    self.channels.append(adjust(channel) if adjust is not None else channel)
                elif channel.schema_text and not self.channels[known].schema_text:
                    self.channels[known] = replace(self.channels[known], schema_encoding=channel.schema_encoding,
                                                   schema_text=channel.schema_text)
                mapping.append(index[key])
            self._maps.append(mapping)
        self.ros_distro = ros_distro or next((p.ros_distro for p in self.parts if p.ros_distro), None)
        counts = [p.message_count for p in self.parts]
        self.message_count = sum(c for c in counts if c) if all(c is not None for c in counts) else None
        starts = [p.start_time for p in self.parts if p.start_time is not None]
        ends = [p.end_time for p in self.parts if p.end_time is not None]
        self.start_time = min(starts) if starts else None
        self.end_time = max(ends) if ends else None

    def messages(self) -> Iterator[InputMessage]:
        """(channel index, log_time, publish_time, data) of every part, merged in log-time order."""
        if len(self.parts) == 1:
            mapping = self._maps[0]
            for channel, log_time, publish_time, data in self.parts[0].messages():
                yield mapping[channel], log_time, publish_time, data
            return
        streams = [_keyed(part, number, mapping)
                   for number, (part, mapping) in enumerate(zip(self.parts, self._maps, strict=True))]
        for log_time, _, channel, publish_time, data in heapq.merge(*streams):
            yield channel, log_time, publish_time, data

    @property
    def losses(self) -> list[str]:
        """What salvage skipped in every part so far."""
        return [loss for part in self.parts for loss in part.losses]

    @property
    def warnings(self) -> list[str]:
        """What the readers noticed and worked around."""
        return [*self.own_warnings, *(warning for part in self.parts for warning in part.warnings)]

    def topics(self) -> dict[str, list[Channel]]:
        """Channels by topic name."""
        out: dict[str, list[Channel]] = {}
        for channel in self.channels:
            out.setdefault(channel.topic, []).append(channel)
        return out

    def close(self) -> None:
        """Close every part (their losses and warnings stay readable)."""
        for part in self.parts:
            part.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *_: object) -> None:
        self.close()


def _keyed(source: Source, number: int, mapping: list[int]) -> Iterator[tuple[int, int, int, int, Data]]:
    """Messages of one part as (log_time, part number, channel, publish_time, data) for merging.

    The (log_time, part number) prefix is unique among parts at any time, so the merge never compares data.
    """
    for channel, log_time, publish_time, data in source.messages():
        yield log_time, number, mapping[channel], publish_time, data
