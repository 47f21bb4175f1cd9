"""Output MCAP (profile ros2) with rosbag2's conventions, written to a temporary name and renamed when complete.

As rosbag2's MCAP storage writes it: a type without a definition gets a
schema with an empty encoding and text, every channel bagfault writes
carries `offered_qos_profiles` in the integer form with nine keys (the
default profile when the input had none) and `topic_type_hash` (an input's
channel kept for chunk copy keeps its metadata as it is, QoS or none), and a `rosbag2`
metadata record (version 8, its keys at the top level) describes the bag, so
`ros2 bag info` and `ros2 bag play` of Humble, Iron and Jazzy read it as one
of theirs. A disk that fills up, or any
other failed write, is an `OutputError`; nothing is left under the name.
"""

from __future__ import annotations

import contextlib
import os
import struct
import time
from pathlib import Path
from typing import TYPE_CHECKING

import yaml
from mcap.records import Channel as McapChannel
from mcap.records import Schema as McapSchema

from bagfault.errors import OutputError
from bagfault.io.mcap_layout import header_library
from bagfault.io.mcap_writer import LEVELS, CopiedChunk, McapWriter
from bagfault.io.outputs import PartialFile
from bagfault.io.qos import normalized

if TYPE_CHECKING:
    from typing_extensions import Self

    from bagfault.io.leading_copy import LeadingCopy

COMPRESSIONS = ('none', 'lz4', 'zstd')
LIVE_FLUSH = 1.0  # seconds: a live recording loses at most this much to a kill
METADATA_VERSION = 8  # the last version whose QoS every distro reads (9 writes names Humble and Iron cannot)


def check_level(path: Path, compression: str, level: int) -> None:
    """OutputError unless `level` is one the compression accepts."""
    if compression not in LEVELS:
        raise OutputError(f'{path}: a compression level needs a compression (lz4 or zstd), not {compression!r}')
    low, high = LEVELS[compression]
    if not low <= level <= high:
        raise OutputError(f'{path}: {compression} compression level {level} is outside {low}..{high}')


class McapSink:
    """Writes schemas, channels, messages, metadata and attachments.

    Nothing appears under the requested name until `finish` succeeds; `abort`
    removes the partial file. `output` is the file when the caller holds it
    (`bagfault run`, whose leading copy `lead` fills it ahead of the run: see
    `bagfault.io.leading_copy`); without it the sink makes and holds its own.
    """

    def __init__(self, path: Path, *, compression: str = 'zstd', chunk_size: int = 1 << 20,
                 ros_distro: str = '', flush_every: float | None = None, level: int | None = None,
                 output: PartialFile | None = None, lead: LeadingCopy | None = None) -> None:
        self.path = path
        self.ros_distro = ros_distro  # the input's or the recording rclpy's; '' when unknown, never guessed
        self.flush_every = flush_every  # live recordings: complete a chunk at least this often (seconds)
        self._flushed = time.monotonic()
        if compression not in COMPRESSIONS:
            raise OutputError(f'{path}: unknown compression {compression!r} (none, lz4, zstd)')
        if level is not None:
            check_level(path, compression, level)
        self._file = output if output is not None else PartialFile(path)
        self._ended = False  # published or aborted: leaving a `with` then does nothing
        self.partial = self._file.partial  # where the file grows until `finish` (`bagfault recover` reads it)
        self._stream = os.fdopen(self._file.fd, 'wb', buffering=1 << 20, closefd=False)
        self._writer = McapWriter(self._stream, chunk_size=chunk_size, compression=compression,
                                  library=header_library(), level=level, lead=lead)
        self._schemas: dict[tuple[str, str, str], int] = {}
        self._topics: dict[int, tuple[str, str, str, str, str]] = {}  # id -> topic, type, encoding, QoS, hash
        self._kept_schemas: set[int] = set()
        if flush_every is not None:  # a live recording says what it is at its start, as rosbag2's recorder does
            self.add_metadata('rosbag2', self._rosbag2_metadata())

    def add_channel(
        self,
        topic: str,
        msgtype: str,
        schema_encoding: str,
        schema_text: str,
        message_encoding: str = 'cdr',
        metadata: dict[str, str] | None = None,
    ) -> int:
        """Register a channel (and its schema once); return its id."""
        key = (msgtype, schema_encoding if schema_text else '', schema_text)
        given = dict(metadata or {})
        channel_metadata = {'offered_qos_profiles': normalized(given.pop('offered_qos_profiles', None)),
                            'topic_type_hash': given.pop('topic_type_hash', ''), **given}
        try:
            schema_id = self._schemas.get(key)
            if schema_id is None:
                schema_id = self._writer.register_schema(msgtype, key[1], schema_text.encode())
                self._schemas[key] = schema_id
            channel_id = self._writer.register_channel(topic, message_encoding, schema_id, channel_metadata)
        except OSError as exc:
            raise self._failed(exc) from None
        self._topics[channel_id] = (topic, msgtype, message_encoding, channel_metadata['offered_qos_profiles'],
                                    channel_metadata['topic_type_hash'])
        return channel_id

    # -- chunk copy: an input's channels kept as they are, its chunks copied -------------------------
    def reserve(self, schema_ids: int, channel_ids: int) -> None:
        """Schema and channel ids up to these belong to the input; new ones are numbered above."""
        self._writer.reserve(schema_ids, channel_ids)

    def keep_channel(self, schema: McapSchema | None, channel: McapChannel, msgtype: str) -> int:
        """Register an input's channel (and its schema) with its ids and bytes, so its chunks can be copied."""
        try:
            if schema is not None and schema.id not in self._kept_schemas:
                self._writer.register_schema(schema.name, schema.encoding, schema.data, schema_id=schema.id)
                self._kept_schemas.add(schema.id)
            self._writer.register_channel(channel.topic, channel.message_encoding, channel.schema_id,
                                          dict(channel.metadata), channel_id=channel.id)
        except OSError as exc:
            raise self._failed(exc) from None
        qos = channel.metadata.get('offered_qos_profiles', '')  # none given: none said (ros2 bag's defaults)
        self._topics[channel.id] = (channel.topic, msgtype, channel.message_encoding, qos,
                                    channel.metadata.get('topic_type_hash', ''))
        return channel.id

    def copy_chunk(self, chunk: CopiedChunk) -> None:
        """Write an input chunk as it is."""
        try:
            self._writer.copy_chunk(chunk)
        except OSError as exc:
            raise self._failed(exc) from None

    def write(self, channel_id: int, log_time: int, publish_time: int, data: bytes | memoryview) -> None:
        """Append one message."""
        try:
            self._writer.add_message(channel_id, log_time, data, publish_time)
        except struct.error:
            raise OutputError(f'{self.path}: time {log_time} ns cannot be written (MCAP times are 0 to 2^64 - 1 '
                              'ns)') from None
        except OSError as exc:
            raise self._failed(exc) from None
        if self.flush_every is not None:
            self.tick()

    def written(self) -> dict[str, int]:
        """Messages written so far per topic."""
        out: dict[str, int] = {}
        for number, count in self._writer.counts.items():
            topic = self._topics[number][0]
            out[topic] = out.get(topic, 0) + count
        return out

    def flush(self) -> None:
        """Write every completed chunk, copied ones included (a run does it while the input's hash completes)."""
        try:
            self._writer.flush()
        except OSError as exc:
            raise self._failed(exc) from None

    def tick(self) -> None:
        """Live recordings: when `flush_every` has passed, complete the open chunk and hand it to the kernel, so
        a kill (SIGKILL, the OOM killer) loses at most that much; `bagfault recover` reads the rest."""
        if self.flush_every is None or time.monotonic() - self._flushed < self.flush_every:
            return
        self._flushed = time.monotonic()
        try:
            self._writer.flush()
            self._stream.flush()
        except OSError as exc:
            raise self._failed(exc) from None

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        """Append a metadata record."""
        try:
            self._writer.add_metadata(name, data)
        except OSError as exc:
            raise self._failed(exc) from None

    def add_attachment(self, name: str, media_type: str, data: bytes, log_time: int = 0) -> None:
        """Append an attachment (create_time 0 keeps output reproducible)."""
        try:
            self._writer.add_attachment(create_time=0, log_time=log_time, name=name, media_type=media_type,
                                        data=data)
        except OSError as exc:
            raise self._failed(exc) from None

    def finish(self) -> None:
        """Write the rosbag2 metadata, the summary, and move the file to its final name."""
        self.close_unpublished()
        self.publish()

    def close_unpublished(self) -> None:
        """Complete the file under its temporary name (published later, or aborted)."""
        try:
            self._writer.flush()
            self._writer.add_metadata('rosbag2', self._rosbag2_metadata())
            self._writer.add_mark()  # proof that bagfault wrote it (io/marks.py)
            self._writer.finish()
            self._stream.close()
        except OSError as exc:
            raise self._failed(exc) from None

    def publish(self) -> None:
        """Move the completed file to its final name."""
        self._ended = True
        self._file.publish()

    def abort(self) -> None:
        """Drop the partial output."""
        self._ended = True
        self._writer.abandon()
        with contextlib.suppress(OSError):
            self._stream.close()
        self._file.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        """All or nothing: an output not finished (published) by the end of the `with` is dropped."""
        if not self._ended:
            self.abort()

    def _failed(self, exc: OSError) -> OutputError:
        """A write failed (a full disk, a lost mount): drop the partial file and say why."""
        self.abort()
        return OutputError(f'{self.path}: cannot write: {exc.strerror or exc}')

    def _rosbag2_metadata(self) -> dict[str, str]:
        """The `rosbag2` metadata record as rosbag2's MCAP storage writes it: `serialized_metadata` holds the
        BagMetadata YAML with its keys at the top level (metadata.yaml nests them; this record does not)."""
        counts, (start, end) = self._writer.counts, self._writer.time_range
        total = sum(counts.values())
        span = {'nanoseconds': end - start if total else 0}
        first = {'nanoseconds_since_epoch': start if total else 0}
        topics = [{
            'topic_metadata': {'name': topic, 'type': msgtype, 'serialization_format': encoding,
                               'offered_qos_profiles': qos, 'type_description_hash': type_hash},
            'message_count': counts.get(number, 0),
        } for number, (topic, msgtype, encoding, qos, type_hash) in sorted(self._topics.items())]
        info = {
            'version': METADATA_VERSION, 'storage_identifier': 'mcap', 'duration': span, 'starting_time': first,
            'message_count': total, 'topics_with_message_count': topics, 'compression_format': '',
            'compression_mode': '', 'relative_file_paths': [], 'files': [],  # rosbag2's reader fills these in
            'custom_data': {}, 'ros_distro': self.ros_distro,  # (and a name here would differ between copies)
        }
        return {'serialized_metadata': yaml.dump(info, Dumper=_PlainDumper, sort_keys=False)}


class _PlainDumper(yaml.SafeDumper):
    """Writes repeated values out in full (no &anchors), as rosbag2 does."""

    def ignore_aliases(self, data: object) -> bool:
        return True
