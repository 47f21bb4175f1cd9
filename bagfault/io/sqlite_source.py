"""rosbag2 sqlite3 storage file (.db3), every schema version from Dashing on.

Read directly with the standard library rather than through rosbags'
reader because bagfault needs what that reader drops: the QoS text of each
topic (copied to the output channel) and tolerance of metadata.yaml files
that disagree with the database. The file is opened immutable and
read-only, so sidecar -shm/-wal files are never touched; when a -wal file
holds committed rows (a recording that was not closed), the database and
its journal are copied to a private folder and read from there, so no row
is missed and the input stays untouched.

Every row is checked: a timestamp that is not a non-negative integer, data
that is not a blob, or a topic_id the topics table does not hold is an
error naming the row, or (salvage) a listed loss.
"""

from __future__ import annotations

import shutil
import sqlite3
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Any
from urllib.parse import quote

import zstandard

from bagfault.errors import InputError, one_line
from bagfault.io.channel import Channel, normalize_msgtype

if TYPE_CHECKING:
    from collections.abc import Iterator

ZSTD_MAGIC = b'\x28\xb5\x2f\xfd'
MAX_TIME = 2**64 - 1


class SqliteSource:
    """Messages of one .db3 file in timestamp order."""

    def __init__(self, path: Path, *, display: Path | None = None, salvage: bool = False) -> None:
        self.path = path
        self.display = display or path
        self.salvage = salvage
        self.channels: list[Channel] = []
        self.ros_distro: str | None = None
        self.losses: list[str] = []
        self.warnings: list[str] = []
        self._ids: dict[int, int] = {}
        self._tmp: tempfile.TemporaryDirectory[str] | None = None
        try:
            with path.open('rb') as stream:
                if stream.read(16) != b'SQLite format 3\x00':
                    raise InputError(f'{self.display}: not an SQLite database')
            self._db = self._connect()
            self._load()
        except (sqlite3.DatabaseError, UnicodeDecodeError) as exc:
            self._cleanup()
            raise InputError(f'{self.display}: corrupt rosbag2 database ({one_line(exc)})') from None
        except OSError as exc:
            self._cleanup()
            raise InputError(f'{self.display}: cannot open: {exc.strerror}') from None
        except BaseException:
            self._cleanup()
            raise

    def _connect(self) -> sqlite3.Connection:
        wal = self.path.with_name(self.path.name + '-wal')
        if not (wal.exists() and wal.stat().st_size > 0):
            return sqlite3.connect(f'file:{quote(str(self.path.resolve()))}?immutable=1&mode=ro', uri=True)
        self._tmp = tempfile.TemporaryDirectory(prefix='bagfault-wal-')
        copy = Path(self._tmp.name) / self.path.name
        shutil.copyfile(self.path, copy)
        shutil.copyfile(wal, copy.with_name(copy.name + '-wal'))
        self.warnings.append(f'{self.display}: read with the committed rows of its -wal journal (the recording was '
                             'not closed cleanly)')
        return sqlite3.connect(f'file:{quote(str(copy))}', uri=True)

    def _load(self) -> None:
        tables = {row[0] for row in self._db.execute("SELECT name FROM sqlite_master WHERE type='table'")}
        if not {'topics', 'messages'} <= tables:
            raise InputError(f'{self.display}: SQLite file is not a rosbag2 bag (no topics/messages tables)')
        columns = {row[1] for row in self._db.execute('PRAGMA table_info(topics)')}
        if 'schema' in tables:
            row = self._db.execute('SELECT * FROM schema').fetchone()
            if row and len(row) > 1 and isinstance(row[1], str):
                self.ros_distro = row[1]
        definitions: dict[str, tuple[str, str]] = {}
        if 'message_definitions' in tables:
            for typename, encoding, text in self._db.execute(
                'SELECT topic_type, encoding, encoded_message_definition FROM message_definitions'
            ):
                if isinstance(typename, str) and isinstance(text, str) and text:
                    definitions[typename] = (encoding if isinstance(encoding, str) else '', text)
        qos = ', offered_qos_profiles' if 'offered_qos_profiles' in columns else ", ''"
        qos += ', type_description_hash' if 'type_description_hash' in columns else ", ''"
        query = f'SELECT id, name, type, serialization_format{qos} FROM topics ORDER BY id'
        for topic_id, name, typename, fmt, qos_text, type_hash in self._db.execute(query):
            if not (isinstance(name, str) and isinstance(typename, str) and isinstance(fmt, str)):
                raise InputError(f'{self.display}: topics row {topic_id} has no usable name, type or format '
                                 f'({name!r}, {typename!r}, {fmt!r})')
            encoding, text = definitions.get(typename, ('', ''))
            metadata: tuple[tuple[str, str], ...] = (
                (('offered_qos_profiles', qos_text),) if isinstance(qos_text, str) and qos_text else ())
            if isinstance(type_hash, str) and type_hash:
                metadata += (('topic_type_hash', type_hash),)
            self._ids[topic_id] = len(self.channels)
            self.channels.append(
                Channel(
                    topic=name,
                    msgtype=normalize_msgtype(typename),
                    schema_encoding=encoding if text else '',
                    schema_text=text,
                    message_encoding=fmt,
                    metadata=metadata,
                )
            )
        row = self._db.execute('SELECT MIN(timestamp), MAX(timestamp), COUNT(*) FROM messages').fetchone()
        start, end, count = row
        self.message_count: int | None = count
        self.start_time = start if isinstance(start, int) and start >= 0 else None
        self.end_time = end if isinstance(end, int) and end >= 0 else None

    def _bad(self, row_id: Any, problem: str) -> None:
        if not self.salvage:
            raise InputError(f'{self.display}: messages row {row_id}: {problem} (--salvage copies the readable rows)')
        self.losses.append(f'{self.display}: messages row {row_id}: {problem}')

    def messages(self) -> Iterator[tuple[int, int, int, bytes]]:
        """(channel index, log_time, publish_time, data); zstd-compressed blobs are expanded."""
        ids = self._ids
        decompress = zstandard.ZstdDecompressor().decompressobj
        try:
            for row_id, topic_id, timestamp, data in self._db.execute(
                'SELECT id, topic_id, timestamp, data FROM messages ORDER BY timestamp, id'
            ):
                index = ids.get(topic_id)
                if not isinstance(timestamp, int) or not 0 <= timestamp <= MAX_TIME:
                    self._bad(row_id, f'timestamp {timestamp!r} is not a time in nanoseconds')
                elif not isinstance(data, bytes):
                    self._bad(row_id, f'data is {type(data).__name__}, not a blob')
                elif index is None:
                    self._bad(row_id, f'topic_id {topic_id!r} is not in the topics table')
                else:
                    if data[:4] == ZSTD_MAGIC:
                        try:
                            data = decompress().decompress(data)
                        except zstandard.ZstdError as exc:
                            self._bad(row_id, f'corrupt zstd message ({one_line(exc)})')
                            continue
                    yield index, timestamp, timestamp, data
        except (sqlite3.DatabaseError, UnicodeDecodeError) as exc:
            raise InputError(f'{self.display}: corrupt rosbag2 database ({one_line(exc)})') from None

    def close(self) -> None:
        """Close the database (and remove a private copy)."""
        self._db.close()
        self._cleanup()

    def _cleanup(self) -> None:
        if self._tmp is not None:
            self._tmp.cleanup()
            self._tmp = None
