"""rosbag2 bags: a directory (with or without metadata.yaml) or a bare storage file.

metadata.yaml (versions 1-9) tells which files belong to the bag, whether
they are zstd FILE-compressed and which distro recorded it; the storage
files themselves are the truth for topics, types and messages. A directory
without metadata.yaml is read as the set of storage files it holds.
"""

from __future__ import annotations

import shutil
import tempfile
from dataclasses import replace
from pathlib import Path, PurePath
from typing import TYPE_CHECKING, Any

import yaml
import zstandard

from bagfault.errors import InputError, one_line
from bagfault.io.mcap_layout import MAGIC
from bagfault.io.mcap_source import McapSource
from bagfault.io.merged import MergedSource
from bagfault.io.qos import normalized
from bagfault.io.regular import read_text
from bagfault.io.source import Source
from bagfault.io.sqlite_source import SqliteSource

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator

    from bagfault.io.channel import Channel, InputMessage

STORAGE_SUFFIXES = ('.db3', '.mcap', '.db3.zstd', '.mcap.zstd')


def _is_storage(path: Path) -> bool:
    return path.is_file() and path.name.endswith(STORAGE_SUFFIXES)


class Rosbag2Source(MergedSource):
    """A rosbag2 bag made of one or more storage files, merged by time (files in listed order on ties)."""

    def __init__(self, path: Path, *, salvage: bool = False) -> None:
        self.path = path
        self.salvage = salvage
        self.metadata: dict[str, Any] = {}
        notes: list[str] = []
        self._notes = notes
        self._tmp: tempfile.TemporaryDirectory[str] | None = None
        parts: list[Source] = []
        distro: str | None = None
        try:
            files = self._files()
            distro = self.metadata.get('ros_distro') if isinstance(self.metadata.get('ros_distro'), str) else None
            for file in files:
                parts.append(self._open_part(file))
        except BaseException:
            for part in parts:
                part.close()
            self._cleanup()
            raise
        super().__init__(parts, adjust=self._declared(), ros_distro=distro)
        self.own_warnings += notes
        claimed = self.metadata.get('message_count')
        if isinstance(claimed, int) and not isinstance(claimed, bool):
            self.message_count = claimed  # what metadata.yaml declares: checked against what is read

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
            info = yaml.safe_load(read_text(meta))['rosbag2_bagfile_information']
            version = info['version']
            listed = info['relative_file_paths']
            if not isinstance(version, int) or isinstance(version, bool):
                raise ValueError(f'version {version!r} is not an integer')
            if not isinstance(listed, list) or not all(isinstance(x, str) for x in listed):
                raise ValueError(f'relative_file_paths {listed!r} is not a list of file names')
            names = [PurePath(x).name for x in listed]
        except (yaml.YAMLError, KeyError, TypeError, ValueError) as exc:
            raise InputError(f'{meta}: not a rosbag2 metadata file ({one_line(exc)})') from None
        except OSError as exc:
            raise InputError(f'{meta}: cannot read: {exc.strerror}') from None
        if version > 9:
            raise InputError(f'{meta}: metadata version {version} is newer than bagfault knows (1-9)')
        if len(set(names)) < len(names):
            repeated = sorted({n for n in names if names.count(n) > 1})
            self._notes.append(f'{meta}: {", ".join(repeated)} listed more than once; each file is read once')
            names = list(dict.fromkeys(names))
        self.metadata = info
        fmt = _text(info.get('compression_format')).lower()
        mode = _text(info.get('compression_mode')).lower()
        if mode and mode != 'none' and fmt not in {'', 'zstd'}:
            raise InputError(f'{meta}: compression format {fmt!r} is not supported (zstd only)')
        files = [self.path / name for name in names]
        if missing := [str(x) for x in files if not x.exists()]:
            raise InputError(f'{self.path}: files listed in metadata.yaml are missing: {", ".join(missing)}')
        if unlisted := sorted(x.name for x in self.path.iterdir() if _is_storage(x) and x.name not in names):
            # a warning, not an error: rosbag2's own test bags carry such files (Dashing's cdr_test holds a
            # test.db3 beside cdr_test.db3) and `ros2 bag` plays them, reading the listed files only
            self._notes.append(f'{meta}: {", ".join(unlisted)} in the folder but not listed in metadata.yaml: not '
                               'read, as rosbag2 reads only the listed files')
        return files

    def _open_part(self, file: Path) -> McapSource | SqliteSource:
        if file.exists() and not file.is_file():  # listed in metadata.yaml: a FIFO there would block for ever
            raise InputError(f'{file}: not a regular file (a FIFO, device or socket is not a bag file)')
        if file.name.endswith('.zstd'):
            file = self._expand(file)
        with file.open('rb') as stream:
            head = stream.read(16)
        if head.startswith(MAGIC[:5]) or (file.suffix == '.mcap' and not head.startswith(b'SQLite format 3')):
            return McapSource(file, salvage=self.salvage)
        if head.startswith(b'SQLite format 3') or file.suffix == '.db3':
            return SqliteSource(file, salvage=self.salvage)
        raise InputError(f'{file}: unknown storage format (not .db3 or .mcap)')

    def _expand(self, file: Path) -> Path:
        """Decompress a FILE-compressed storage file into a private temporary directory."""
        try:
            if self._tmp is None:
                self._tmp = tempfile.TemporaryDirectory(prefix='bagfault-')
            target = Path(self._tmp.name) / file.name.removesuffix('.zstd')
            with file.open('rb') as src, target.open('wb') as dst:
                shutil.copyfileobj(zstandard.ZstdDecompressor().stream_reader(src), dst)
        except zstandard.ZstdError as exc:
            raise InputError(f'{file}: corrupt zstd file ({one_line(exc)})') from None
        except OSError as exc:
            where = self._tmp.name if self._tmp is not None else tempfile.gettempdir()
            raise InputError(f'{file}: cannot decompress it into {where}: {exc.strerror or exc} '
                             '(TMPDIR names where; it needs room for the decompressed file)') from None
        return target

    def _declared(self) -> Callable[[Channel], Channel]:
        """What metadata.yaml declares of a topic: its QoS (when the storage has none) and its format."""
        listed = self.metadata.get('topics_with_message_count')
        declared = [
            t['topic_metadata'] for t in (listed if isinstance(listed, list) else [])
            if isinstance(t, dict) and isinstance(t.get('topic_metadata'), dict)
        ]
        qos = {t.get('name'): t.get('offered_qos_profiles', '') for t in declared}
        hashes = {t.get('name'): t.get('type_description_hash') for t in declared}
        formats = {t.get('name'): t.get('serialization_format') for t in declared}

        def adjust(channel: Channel) -> Channel:
            metadata = dict(channel.metadata)
            declared_qos = qos.get(channel.topic)
            if not channel.qos and isinstance(declared_qos, list) and declared_qos:  # version 9: a sequence
                declared_qos = normalized(declared_qos)
            if not channel.qos and isinstance(declared_qos, str) and declared_qos:
                metadata['offered_qos_profiles'] = declared_qos
            declared_hash = hashes.get(channel.topic)
            if not metadata.get('topic_type_hash') and isinstance(declared_hash, str) and declared_hash:
                metadata['topic_type_hash'] = declared_hash
            # A format declared in metadata.yaml counts even if the storage says cdr.
            declared_format = formats.get(channel.topic)
            encoding = channel.message_encoding
            if isinstance(declared_format, str) and declared_format:
                encoding = declared_format
            if encoding != 'cdr' and channel.message_encoding != 'cdr':
                encoding = channel.message_encoding
            return replace(channel, message_encoding=encoding, metadata=tuple(metadata.items()))

        return adjust

    def messages(self) -> Iterator[InputMessage]:
        """Every file's messages merged by time; at the end, each topic's count against metadata.yaml."""
        counts = [0] * len(self.channels)
        for item in super().messages():
            counts[item[0]] += 1
            yield item
        read: dict[str, int] = {}
        for channel, count in zip(self.channels, counts, strict=True):
            read[channel.topic] = read.get(channel.topic, 0) + count
        self._check_topic_counts(read)

    def _check_topic_counts(self, read: dict[str, int]) -> None:
        """metadata.yaml's messages per topic against those read: fewer read means part of a file was not read
        (an error, or with salvage a warning); more read, or a count that is not one, a warning."""
        listed = self.metadata.get('topics_with_message_count')
        declared: dict[str, int] = {}
        for entry in listed if isinstance(listed, list) else []:
            topic = entry.get('topic_metadata', {}).get('name') if isinstance(entry, dict) else None
            count = entry.get('message_count') if isinstance(entry, dict) else None
            if not isinstance(topic, str):
                continue
            if not isinstance(count, int) or isinstance(count, bool) or count < 0:
                self._late(f'metadata.yaml: {topic}: message_count {count!r} is not a count; ignored')
                continue
            declared[topic] = declared.get(topic, 0) + count
        if not declared:
            return
        fewer = [f'{t}: {n} declared, {read.get(t, 0)} read' for t, n in declared.items() if read.get(t, 0) < n]
        more = [f'{t}: {declared.get(t, 0)} declared, {n} read' for t, n in read.items() if n > declared.get(t, 0)]
        if fewer and not self.salvage:
            raise InputError(f'{self.path}: metadata.yaml declares more messages than its files hold '
                             f'({"; ".join(fewer[:3])}): part of them was not read (--salvage writes what can be '
                             'read and says what is missing)')
        if fewer:
            self._late(f'metadata.yaml declares more messages than were read ({"; ".join(fewer[:3])}; --salvage)')
        if more:
            self._late(f'metadata.yaml declares fewer messages than its files hold ({"; ".join(more[:3])}): its '
                       'counts are older than its files; every message read is in the output')

    def _late(self, text: str) -> None:
        self.own_warnings.append(f'{self.path}: {text}')

    def close(self) -> None:
        """Close every file and remove decompressed copies."""
        super().close()
        self._cleanup()

    def _cleanup(self) -> None:
        if self._tmp is not None:
            self._tmp.cleanup()
            self._tmp = None


def _text(value: object) -> str:
    """A metadata value expected to be text; anything else counts as absent."""
    return value if isinstance(value, str) else ''
