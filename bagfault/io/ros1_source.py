"""ROS 1 bags (.bag v2.0, any chunk compression), converted to ROS 2 CDR on the way in.

rosbags reads the bag and its stored definitions; its converter module
turns each message into the ROS 2 equivalent (Header without seq,
tf/tfMessage as tf2_msgs/TFMessage), so the rest of bagfault only ever sees
ROS 2 data and the output MCAP is ROS 2.
"""

from __future__ import annotations

import heapq
import os
import struct
import zlib
from functools import partial
from typing import TYPE_CHECKING, Any

from rosbags.convert.converter import STATIC_MSGTYPE_RENAMES, is_same_wireformat, migrate_bytes
from rosbags.highlevel import AnyReader, AnyReaderError
from rosbags.rosbag1 import ReaderError
from rosbags.serde import SerdeError
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.base import TypesysError

from bagfault.errors import InputError, one_line
from bagfault.io.channel import Channel
from bagfault.io.qos import DURABILITY, HISTORY, QosProfile, dump_profiles
from bagfault.io.ros1_walk import ChunkRecord, Corrupt, Message, check_entries, decompress, split, walk

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator
    from pathlib import Path

# What rosbags' reader raises on a damaged bag: its own errors, bz2/lz4 failures, and asserts on record headers.
CONVERT_ERRORS = (SerdeError, TypesysError, struct.error, ValueError, IndexError, KeyError, UnicodeDecodeError)
READ_ERRORS = (AnyReaderError, ReaderError, TypesysError, SerdeError, AssertionError, OSError, RuntimeError,
               ValueError, KeyError, IndexError, EOFError, struct.error, zlib.error, UnicodeDecodeError, MemoryError)


class Ros1Source:
    """Messages of a ROS 1 bag as ROS 2 CDR, in time order.

    A chunk that cannot be decompressed or a record that cannot be parsed is
    an error naming the file; a message that cannot be converted is an
    error too, or (salvage) a listed loss.
    """

    def __init__(self, path: Path, *, salvage: bool = False) -> None:
        self.path = path
        self.salvage = salvage
        self.ros_distro: str | None = None  # ROS 1 names no ROS 2 distro; its types convert to Humble's
        self.channels: list[Channel] = []
        self.losses: list[str] = []
        self.warnings: list[str] = []
        self._converters: list[Callable[[Any], Any]] = []
        self._ids: dict[int, int] = {}
        try:
            self._reader = AnyReader([path])
            self._reader.open()
        except READ_ERRORS as exc:
            raise InputError(f'{path}: cannot read ROS 1 bag ({one_line(exc)})') from None
        try:
            self._setup()
        except READ_ERRORS as exc:
            self._reader.close()
            raise InputError(f'{path}: cannot convert ROS 1 types to ROS 2 ({one_line(exc)})') from None
        # what the chunk infos declare (each chunk's messages per connection), not the index data's entries the
        # reader counts: an index data record whose connection id is damaged drops its entries from both
        self._infos = {info.pos: info for info in getattr(self._reader.readers[0], 'chunk_infos', None) or []}
        self._connections = {c.id: c for c in self._reader.readers[0].connections}
        try:
            self._layout = walk(path)
        except Corrupt as exc:
            self._reader.close()
            raise InputError(f'{path}: corrupt ROS 1 bag: {exc}') from None
        except OSError as exc:
            self._reader.close()
            raise InputError(f'{path}: cannot read ROS 1 bag ({one_line(exc)})') from None
        declared = sum(sum(info.connection_counts.values()) for info in self._infos.values())
        self.message_count: int | None = declared + len(self._layout.loose)
        try:
            self._check_layout()
        except InputError:
            self._reader.close()
            raise
        self.start_time = self._reader.start_time if self.message_count else None
        self.end_time = self._reader.end_time - 1 if self.message_count else None

    def _lost(self, text: str, hint: str = '--salvage copies what can be read') -> None:
        """A part that cannot be read as the index declares it: an error, or (salvage) a listed loss."""
        if not self.salvage:
            raise InputError(f'{self.path}: {text} ({hint})')
        self.losses.append(f'{self.path}: {text}')

    def _check_layout(self) -> None:
        """The index (the header's chunk_count of chunk infos, which the reader trusts, and its conn_count of
        connection records) against the records the file holds: a bag holding more chunks than it indexes
        would be read in part, its own counts agreeing with that part."""
        layout, infos = self._layout, self._infos
        walked = {chunk.position for chunk in layout.chunks}
        unlisted = walked - set(infos)
        if unlisted:
            self._lost(f'the bag holds {len(walked)} chunks and its index lists {len(set(infos) & walked)} (its '
                       f'header says chunk_count={len(infos)}): the chunk at {min(unlisted)} would not be read',
                       '--salvage reads the indexed ones and says so')
        astray = set(infos) - walked
        if astray:
            self._lost(f'its index lists a chunk at {min(astray)}, where the file holds none')
        if layout.index_connections > len(self._connections):
            self._lost(f'its index holds {layout.index_connections} connection records and its header says '
                       f'conn_count={len(self._connections)}: the messages of the others would not be read',
                       '--salvage reads the indexed ones and says so')

    def _setup(self) -> None:
        source = self._reader.typestore
        header = get_typestore(Stores.ROS2_HUMBLE).fielddefs['std_msgs/msg/Header']
        target = get_typestore(Stores.EMPTY)
        target.register({**source.fielddefs, 'std_msgs/msg/Header': header})
        cache: dict[str, object] = {}
        by_type: dict[str, tuple[int, str]] = {}
        for connection in self._reader.connections:
            msgtype = STATIC_MSGTYPE_RENAMES.get(connection.msgtype, connection.msgtype)
            if connection.msgtype not in by_type:
                if msgtype not in target.fielddefs:
                    types = get_types_from_msg(source.generate_msgdef(connection.msgtype, ros_version=2)[0], msgtype)
                    types.pop('std_msgs/msg/Header', None)
                    target.register(types)
                if is_same_wireformat(source, target, connection.msgtype, msgtype):
                    convert: Callable[[Any], Any] = partial(target.ros1_to_cdr, typename=msgtype)
                else:
                    convert = partial(migrate_bytes, source, target, connection.msgtype, msgtype, cache,
                                      src_is2=False, dst_is2=True)
                self._converters.append(convert)
                by_type[connection.msgtype] = (len(self._converters) - 1, msgtype)
            key = (connection.topic, by_type[connection.msgtype][1])
            index = next((i for i, c in enumerate(self.channels) if (c.topic, c.msgtype) == key), None)
            if index is None:
                text, _ = target.generate_msgdef(key[1], ros_version=2)
                latching = getattr(connection.ext, 'latching', 0)
                metadata = (('offered_qos_profiles', LATCHED_QOS),) if latching else ()
                self.channels.append(Channel(connection.topic, key[1], 'ros2msg', text, 'cdr', metadata))
                index = len(self.channels) - 1
            self._ids[id(connection)] = index
        self._by_connection = {id(c): by_type[c.msgtype][0] for c in self._reader.connections}

    def messages(self) -> Iterator[tuple[int, int, int, bytes | memoryview]]:
        """(channel index, log_time, publish_time, CDR data) in time order: every chunk the index lists read
        once, in the order of its start time, its records checked against its index data and chunk info, and
        merged with the messages outside any chunk."""
        ids, converters, by_connection, connections = self._ids, self._converters, self._by_connection, \
            self._connections
        for message in self._ordered():
            connection = connections.get(message.conn)
            if connection is None:
                self._lost(f'a message at {message.time} ns of connection {message.conn}, which its index does '
                           'not define')
                continue
            key = id(connection)
            try:
                converted = converters[by_connection[key]](message.data)
            except CONVERT_ERRORS as exc:
                self._lost(f'{connection.topic} at {message.time} ns: cannot convert the message ({one_line(exc)})')
                continue
            yield ids[key], message.time, message.time, converted

    def _ordered(self) -> Iterator[Message]:
        """Messages in time order (ties: file order): chunks by their chunk info's start time, each message
        held back until no later chunk can hold an earlier one."""
        infos = self._infos
        chunks = sorted((c for c in self._layout.chunks if c.position in infos),
                        key=lambda c: (infos[c.position].start_time, c.position))
        pending = [(m.time, -1, m.offset, m) for m in sorted(self._layout.loose, key=lambda m: (m.time, m.offset))]
        fd = self._reader.readers[0].bio.fileno()  # type: ignore[union-attr]
        for number, chunk in enumerate(chunks):
            found = self._read(fd, chunk)
            horizon = infos[chunks[number + 1].position].start_time if number + 1 < len(chunks) else None
            in_order = all(found[i].time <= found[i + 1].time for i in range(len(found) - 1))
            if not pending and in_order and (horizon is None or not found or found[-1].time <= horizon):
                yield from found
                continue
            for message in found:
                heapq.heappush(pending, (message.time, number, message.offset, message))
            while pending and (horizon is None or pending[0][0] < horizon):
                yield heapq.heappop(pending)[3]

    def _read(self, fd: int, chunk: ChunkRecord) -> list[Message]:
        """One chunk's messages, checked against what its index data and chunk info declare."""
        where = f'corrupt ROS 1 bag: chunk at {chunk.position}'
        try:
            raw = os.pread(fd, chunk.data_size, chunk.data_position)
            messages, _ = split(chunk, decompress(chunk, raw))
        except Corrupt as exc:
            self._lost(f'{where}: {exc}')
            return []
        except OSError as exc:
            self._lost(f'{where}: cannot read it ({one_line(exc)})')
            return []
        differ = check_entries(chunk, messages)
        if differ:
            self._lost(f'{where}: its messages and its index data disagree ({differ})')
        info = self._infos[chunk.position]
        counts: dict[int, int] = {}
        for message in messages:
            counts[message.conn] = counts.get(message.conn, 0) + 1
        if counts != {conn: n for conn, n in info.connection_counts.items() if n}:
            self._lost(f'{where}: its chunk info declares {sum(info.connection_counts.values())} messages '
                       f'{dict(info.connection_counts)}, the chunk holds {len(messages)} {counts}')
        if messages and (min(m.time for m in messages) < info.start_time or
                         max(m.time for m in messages) >= info.end_time):
            self._lost(f'{where}: messages outside the time range its chunk info gives')
        return messages

    def close(self) -> None:
        """Close the bag."""
        self._reader.close()


# a latched ROS 1 topic as rosbag2 records a transient-local publisher
LATCHED_QOS = dump_profiles([QosProfile(history=HISTORY['unknown'], depth=0, durability=DURABILITY['transient_local'])])
