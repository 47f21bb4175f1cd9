"""rosbag2 bags: a directory (with or without metadata.yaml) or a bare storage file.

metadata.yaml (versions 1-9) tells which files belong to the bag, whether
they are zstd FILE-compressed and which distro recorded it; the storage
files themselves are the truth for topics, types and messages. A directory
without metadata.yaml is read as the set of storage files it holds.
"""

from __future__ import annotations

import heapq
import shutil
import tempfile
from pathlib import Path, PurePath
from typing import TYPE_CHECKING, Any

import yaml
import zstandard

from bagfault.io import InputError
from bagfault.io.channel import Channel
from bagfault.io.mcap_source import McapSource
from bagfault.io.sqlite_source import SqliteSource

if TYPE_CHECKING:
    from collections.abc import Iterator

STORAGE_SUFFIXES = ('.db3', '.mcap', '.db3.zstd', '.mcap.zstd')


def _is_storage(path: Path) -> bool:
    return path.is_file() and path.name.endswith(STORAGE_SUFFIXES)


class Rosbag2Source:
    """A rosbag2 bag made of one or more storage files, merged by time."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.channels: list[Channel] = []
        self.ros_distro: str | None = None
        self.metadata: dict[str, Any] = {}
        self._tmp: tempfile.TemporaryDirectory[str] | None = None
        self._parts: list[McapSource | SqliteSource] = []
        self._maps: list[list[int]] = []
        try:
            files = self._files()
            for file in files:
                self._parts.append(self._open_part(file))
        except BaseException:
            self.close()
            raise
        self._merge_channels()
        counts = [p.message_count for p in self._parts]
        self.message_count = sum(c for c in counts if c) if all(c is not None for c in counts) else None
        starts = [p.start_time for p in self._parts if p.start_time is not None]
        ends = [p.end_time for p in self._parts if p.end_time is not None]
        self.start_time = min(starts) if starts else None
        self.end_time = max(ends) if ends else None

    def _files(self) -> list[Path]:
        if self.path.is_file():
            return [self.path]
        meta = self.path / 'metadata.yaml'
        if not meta.exists():
            files = sorted(x for x in self.path.iterdir() if _is_storage(x))
            if not files:
                raise InputError(f'{self.path}: directory holds no metadata.yaml and no .db3 or .mcap files')
            return files
        try:
            info = yaml.safe_load(meta.read_text())['rosbag2_bagfile_information']
            version = int(info['version'])
            names = [PurePath(x).name for x in info['relative_file_paths']]
        except (yaml.YAMLError, KeyError, TypeError, ValueError) as exc:
            raise InputError(f'{meta}: not a rosbag2 metadata file ({exc})') from None
        except OSError as exc:
            raise InputError(f'{meta}: cannot read: {exc.strerror}') from None
        if version > 9:
            raise InputError(f'{meta}: metadata version {version} is newer than bagfault knows (1-9)')
        self.metadata = info
        self.ros_distro = info.get('ros_distro')
        fmt = (info.get('compression_format') or '').lower()
        mode = (info.get('compression_mode') or '').lower()
        if mode and mode != 'none' and fmt not in {'', 'zstd'}:
            raise InputError(f'{meta}: compression format {fmt!r} is not supported (zstd only)')
        files = [self.path / name for name in names]
        if missing := [str(x) for x in files if not x.exists()]:
            raise InputError(f'{self.path}: files listed in metadata.yaml are missing: {", ".join(missing)}')
        return files

    def _open_part(self, file: Path) -> McapSource | SqliteSource:
        if file.name.endswith('.zstd'):
            file = self._expand(file)
        if file.suffix == '.mcap':
            return McapSource(file)
        if file.suffix == '.db3':
            return SqliteSource(file)
        with file.open('rb') as stream:
            head = stream.read(16)
        if head.startswith(b'\x89MCAP'):
            return McapSource(file)
        if head.startswith(b'SQLite format 3'):
            return SqliteSource(file)
        raise InputError(f'{file}: unknown storage format (not .db3 or .mcap)')

    def _expand(self, file: Path) -> Path:
        """Decompress a FILE-compressed storage file into a private temporary directory."""
        if self._tmp is None:
            self._tmp = tempfile.TemporaryDirectory(prefix='bagfault-')
        target = Path(self._tmp.name) / file.name.removesuffix('.zstd')
        try:
            with file.open('rb') as src, target.open('wb') as dst:
                shutil.copyfileobj(zstandard.ZstdDecompressor().stream_reader(src), dst)
        except zstandard.ZstdError as exc:
            raise InputError(f'{file}: corrupt zstd file ({exc})') from None
        return target

    def _merge_channels(self) -> None:
        """One channel per (topic, type, encoding) across files, first definition wins."""
        index: dict[tuple[str, str, str], int] = {}
        declared = [
            t['topic_metadata'] for t in self.metadata.get('topics_with_message_count', [])
            if isinstance(t, dict) and isinstance(t.get('topic_metadata'), dict)
        ]
        qos = {t.get('name'): t.get('offered_qos_profiles', '') for t in declared}
        # A format declared in metadata.yaml counts even if the storage says cdr.
        formats = {t.get('name'): t.get('serialization_format') for t in declared}
        for part in self._parts:
            mapping = []
            for channel in part.channels:
                key = (channel.topic, channel.msgtype, channel.message_encoding)
                if key not in index:
                    metadata = channel.metadata
                    if not channel.qos and isinstance(qos.get(channel.topic), str) and qos[channel.topic]:
                        metadata = (('offered_qos_profiles', qos[channel.topic]),)
                    encoding = formats.get(channel.topic) or channel.message_encoding
                    if encoding != 'cdr':
                        encoding = encoding if channel.message_encoding == 'cdr' else channel.message_encoding
                    channel = Channel(channel.topic, channel.msgtype, channel.schema_encoding,
                                      channel.schema_text, encoding, metadata)
                    index[key] = len(self.channels)
                    self.channels.append(channel)
                elif channel.schema_text and not self.channels[index[key]].schema_text:
                    old = self.channels[index[key]]
                    self.channels[index[key]] = Channel(old.topic, old.msgtype, channel.schema_encoding,
                                                        channel.schema_text, old.message_encoding, old.metadata)
                mapping.append(index[key])
            self._maps.append(mapping)
            if self.ros_distro is None and part.ros_distro:
                self.ros_distro = part.ros_distro

    def messages(self) -> Iterator[tuple[int, int, int, bytes | memoryview]]:
        """All files' messages merged in time order (files in listed order on ties)."""
        if len(self._parts) == 1:
            mapping = self._maps[0]
            for channel, log_time, publish_time, data in self._parts[0].messages():
                yield mapping[channel], log_time, publish_time, data
            return
        streams = [_keyed(part, number, mapping) for number, (part, mapping) in enumerate(zip(self._parts, self._maps))]
        for log_time, _, channel, publish_time, data in heapq.merge(*streams, key=lambda x: (x[0], x[1])):
            yield channel, log_time, publish_time, data

    def close(self) -> None:
        """Close every file and remove decompressed copies."""
        for part in self._parts:
            part.close()
        self._parts = []
        if self._tmp is not None:
            self._tmp.cleanup()
            self._tmp = None


def _keyed(source: Any, number: int, mapping: list[int]) -> Iterator[tuple[int, int, int, int, Any]]:
    """Messages of one part as (log_time, part number, channel, publish_time, data) for merging."""
    for channel, log_time, publish_time, data in source.messages():
        yield log_time, number, mapping[channel], publish_time, data
