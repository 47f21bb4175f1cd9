"""Open any supported input and merge several inputs in time order."""

from __future__ import annotations

import hashlib
import heapq
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from bagfault.io import InputError
from bagfault.io.channel import Channel
from bagfault.io.mcap_source import McapSource
from bagfault.io.rosbag2_source import Rosbag2Source

if TYPE_CHECKING:
    from collections.abc import Iterator, Sequence


class Source(Protocol):
    """What every input offers."""

    channels: list[Channel]
    ros_distro: str | None
    message_count: int | None
    start_time: int | None
    end_time: int | None

    def messages(self) -> Iterator[tuple[int, int, int, bytes | memoryview]]:
        """(channel index, log_time, publish_time, data) in log-time order."""
        ...

    def close(self) -> None:
        """Release resources."""
        ...


@dataclass(frozen=True)
class InputFile:
    """One file that makes up an input, for the provenance record."""

    name: str
    size: int
    sha256: str


def open_source(path: Path) -> Source:
    """Open an MCAP file, a rosbag2 directory or storage file, or a ROS 1 bag."""
    if not path.exists():
        raise InputError(f'{path}: no such file or directory')
    if path.is_dir():
        return Rosbag2Source(path)
    try:
        with path.open('rb') as stream:
            head = stream.read(16)
    except OSError as exc:
        raise InputError(f'{path}: cannot read: {exc.strerror}') from None
    if not head:
        raise InputError(f'{path}: file is empty')
    if head.startswith(b'\x89MCAP'):
        return McapSource(path)
    if head.startswith(b'#ROSBAG V2.0'):
        from bagfault.io.ros1_source import Ros1Source  # noqa: PLC0415

        return Ros1Source(path)
    if head.startswith(b'#ROSBAG'):
        raise InputError(f'{path}: ROS 1 bag format {head[1:12].decode(errors="replace")!r} is not supported (V2.0 only)')
    if head.startswith(b'SQLite format 3') or path.name.endswith('.zstd'):
        return Rosbag2Source(path)
    raise InputError(f'{path}: not a bag (expected MCAP, rosbag2 .db3, a rosbag2 directory or a ROS 1 .bag)')


def input_files(path: Path) -> list[Path]:
    """The files that make up an input, in a stable order."""
    if path.is_dir():
        return sorted(x for x in path.iterdir() if x.is_file() and not x.name.endswith(('-shm', '-wal')))
    return [path]


def fingerprint(path: Path) -> list[InputFile]:
    """Name, size and sha256 of each file of an input."""
    out = []
    for file in input_files(path):
        digest = hashlib.sha256()
        with file.open('rb') as stream:
            while block := stream.read(1 << 20):
                digest.update(block)
        out.append(InputFile(file.name, file.stat().st_size, digest.hexdigest()))
    return out


class InputSet:
    """Several inputs seen as one bag: channels united, messages merged by time."""

    def __init__(self, paths: Sequence[Path]) -> None:
        self.paths = list(paths)
        self.sources: list[Source] = []
        self.channels: list[Channel] = []
        self._maps: list[list[int]] = []
        try:
            for path in self.paths:
                self.sources.append(open_source(path))
        except BaseException:
            self.close()
            raise
        index: dict[tuple[str, str, str], int] = {}
        for source in self.sources:
            mapping = []
            for channel in source.channels:
                key = (channel.topic, channel.msgtype, channel.message_encoding)
                if key not in index:
                    index[key] = len(self.channels)
                    self.channels.append(channel)
                mapping.append(index[key])
            self._maps.append(mapping)
        self.ros_distro = next((s.ros_distro for s in self.sources if s.ros_distro), None)
        counts = [s.message_count for s in self.sources]
        self.message_count = sum(counts) if all(c is not None for c in counts) else None  # type: ignore[arg-type]
        starts = [s.start_time for s in self.sources if s.start_time is not None]
        ends = [s.end_time for s in self.sources if s.end_time is not None]
        self.start_time = min(starts) if starts else None
        self.end_time = max(ends) if ends else None

    def messages(self) -> Iterator[tuple[int, int, int, bytes | memoryview]]:
        """(channel index, log_time, publish_time, data), merged across inputs."""
        if len(self.sources) == 1:
            mapping = self._maps[0]
            for channel, log_time, publish_time, data in self.sources[0].messages():
                yield mapping[channel], log_time, publish_time, data
            return
        streams = [_keyed(source, number, mapping) for number, (source, mapping) in enumerate(zip(self.sources, self._maps))]
        for log_time, _, channel, publish_time, data in heapq.merge(*streams, key=lambda x: (x[0], x[1])):
            yield channel, log_time, publish_time, data

    def topics(self) -> dict[str, list[Channel]]:
        """Channels by topic name."""
        out: dict[str, list[Channel]] = {}
        for channel in self.channels:
            out.setdefault(channel.topic, []).append(channel)
        return out

    def close(self) -> None:
        """Close every input."""
        for source in self.sources:
            source.close()
        self.sources = []


def _keyed(source: Any, number: int, mapping: list[int]) -> Iterator[tuple[int, int, int, int, Any]]:
    """Messages of one part as (log_time, part number, channel, publish_time, data) for merging."""
    for channel, log_time, publish_time, data in source.messages():
        yield log_time, number, mapping[channel], publish_time, data
