"""ROS 1 bags (.bag v2.0, any chunk compression), converted to ROS 2 CDR on the way in.

rosbags reads the bag and its stored definitions; its converter module
turns each message into the ROS 2 equivalent (Header without seq,
tf/tfMessage as tf2_msgs/TFMessage), so the rest of bagfault only ever sees
ROS 2 data and the output MCAP is ROS 2.
"""

from __future__ import annotations

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

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator
    from pathlib import Path

# What rosbags' reader raises on a damaged bag: its own errors, bz2/lz4 failures, and asserts on record headers.
CONVERT_ERRORS = (SerdeError, TypesysError, struct.error, ValueError, IndexError, KeyError, UnicodeDecodeError)
READ_ERRORS = (AnyReaderError, ReaderError, TypesysError, SerdeError, AssertionError, OSError, RuntimeError,
               ValueError, KeyError, IndexError, EOFError, struct.error, zlib.error, UnicodeDecodeError, MemoryError)


def count_chunk_records(path: Path) -> tuple[int, int] | None:
    """(chunk records between the bag header and the index, connection records in the index section), each
    record's header read and its data skipped; None when the walk does not find the layout (the reader
    reports that file on its own). Bytes after the index section that make no whole record (trailing garbage)
    end the walk there; no read is ever larger than what the file has left."""
    try:
        with path.open('rb') as stream:
            left = os.fstat(stream.fileno()).st_size
            if stream.read(13) != b'#ROSBAG V2.0\n':
                return None
            index_pos: int | None = None
            chunks = connections = 0
            first = True
            while True:
                raw = stream.read(4)
                length = struct.unpack('<I', raw)[0] if len(raw) == 4 else None
                if length is None or stream.tell() + length + 4 > left:  # no whole record header here
                    past_index = index_pos is not None and stream.tell() - len(raw) >= index_pos
                    return (chunks, connections) if past_index else None
                header = stream.read(length)
                fields = _fields(header)
                size = struct.unpack('<I', stream.read(4))[0]
                if stream.tell() + size > left:  # a record's data past the end: not a record
                    return (chunks, connections) if index_pos is not None and stream.tell() > index_pos else None
                op = fields.get(b'op', b'')
                if first:
                    first = False
                    if op != b'\x03' or b'index_pos' not in fields:
                        return None
                    index_pos = struct.unpack('<Q', fields[b'index_pos'])[0]
                elif op == b'\x05' and index_pos is not None and stream.tell() <= index_pos:
                    chunks += 1
                elif op == b'\x07' and index_pos is not None and stream.tell() > index_pos:
                    connections += 1
                stream.seek(size, 1)
    except (OSError, struct.error):
        return None


def _fields(header: bytes) -> dict[bytes, bytes]:
    """The name=value fields of a record header."""
    fields = {}
    position = 0
    while position + 4 <= len(header):
        length = struct.unpack_from('<I', header, position)[0]
        name, _, value = header[position + 4:position + 4 + length].partition(b'=')
        fields[name] = value
        position += 4 + length
    return fields


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
        infos = getattr(self._reader.readers[0], 'chunk_infos', None) or []
        declared = sum(sum(info.connection_counts.values()) for info in infos)
        self.message_count: int | None = declared if infos else sum(c.msgcount for c in self._reader.connections)
        self._check_chunks()
        self.start_time = self._reader.start_time if self.message_count else None
        self.end_time = self._reader.end_time - 1 if self.message_count else None

    def _check_chunks(self) -> None:
        """The chunks the index lists (the header's chunk_count of chunk infos, which the reader trusts) against
        the chunk records in the file, walked record by record up to the index: a bag holding more chunks than
        it indexes would be read in part, its own counts agreeing with that part. An error (or with salvage a
        listed loss: the indexed chunks are read)."""
        indexed = len(getattr(self._reader.readers[0], 'chunk_infos', ()) or ())
        walked = count_chunk_records(self.path)
        if walked is None:
            return
        found, connections = walked
        known = len(getattr(self._reader.readers[0], 'connections', ()) or ())
        problems = []
        if found > indexed:
            problems.append(f'the bag holds {found} chunks and its index lists {indexed} (its header says '
                            f'chunk_count={indexed}): the other chunks would not be read')
        if connections > known:
            problems.append(f'its index holds {connections} connection records and its header says '
                            f'conn_count={known}: the messages of the others would not be read')
        for text in problems:
            if not self.salvage:
                self._reader.close()
                raise InputError(f'{self.path}: {text} (--salvage reads the indexed ones and says so)')
            self.losses.append(f'{self.path}: {text}')

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
        """(channel index, log_time, publish_time, CDR data) in time order."""
        ids, converters, by_connection = self._ids, self._converters, self._by_connection
        try:
            for connection, timestamp, raw in self._reader.messages():
                key = id(connection)
                try:
                    converted = converters[by_connection[key]](raw)
                except CONVERT_ERRORS as exc:
                    problem = f'{connection.topic} at {timestamp} ns: cannot convert the message ({one_line(exc)})'
                    if not self.salvage:
                        raise InputError(f'{self.path}: {problem} (--salvage copies what can be read)') from None
                    self.losses.append(f'{self.path}: {problem}')
                    continue
                yield ids[key], timestamp, timestamp, converted
        except READ_ERRORS as exc:
            raise InputError(f'{self.path}: corrupt ROS 1 bag ({one_line(exc)})') from None

    def close(self) -> None:
        """Close the bag."""
        self._reader.close()


# a latched ROS 1 topic as rosbag2 records a transient-local publisher
LATCHED_QOS = dump_profiles([QosProfile(history=HISTORY['unknown'], depth=0, durability=DURABILITY['transient_local'])])
