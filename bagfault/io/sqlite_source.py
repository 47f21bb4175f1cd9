"""rosbag2 sqlite3 storage file (.db3), every schema version from Dashing on.

Read directly with the standard library rather than through rosbags'
reader because bagfault needs what that reader drops: the QoS text of each
topic (copied to the output channel) and tolerance of metadata.yaml files
that disagree with the database. The file is opened immutable and
read-only, so sidecar -shm/-wal files are never touched.
"""

from __future__ import annotations

import sqlite3
from pathlib import Path
from typing import TYPE_CHECKING
from urllib.parse import quote

import zstandard

from bagfault.errors import InputError
from bagfault.io.channel import Channel, normalize_msgtype

if TYPE_CHECKING:
    from collections.abc import Iterator

ZSTD_MAGIC = b'\x28\xb5\x2f\xfd'


class SqliteSource:
    """Messages of one .db3 file in timestamp order."""

    def __init__(self, path: Path, *, display: Path | None = None) -> None:
        self.path = path
        self.display = display or path
        self.channels: list[Channel] = []
        self.ros_distro: str | None = None
        self._ids: dict[int, int] = {}
        try:
            with path.open('rb') as stream:
                if stream.read(16) != b'SQLite format 3\x00':
                    raise InputError(f'{self.display}: not an SQLite database')
            self._db = sqlite3.connect(f'file:{quote(str(path.resolve()))}?immutable=1&mode=ro', uri=True)
            self._load()
        except sqlite3.DatabaseError as exc:
            raise InputError(f'{self.display}: corrupt rosbag2 database ({exc})') from None
        except OSError as exc:
            raise InputError(f'{self.display}: cannot open: {exc.strerror}') from None

    def _load(self) -> None:
        tables = {row[0] for row in self._db.execute("SELECT name FROM sqlite_master WHERE type='table'")}
        if not {'topics', 'messages'} <= tables:
            raise InputError(f'{self.display}: SQLite file is not a rosbag2 bag (no topics/messages tables)')
        columns = {row[1] for row in self._db.execute('PRAGMA table_info(topics)')}
        if 'schema' in tables:
            row = self._db.execute('SELECT * FROM schema').fetchone()
            if row and len(row) > 1:
                self.ros_distro = row[1]
        definitions: dict[str, tuple[str, str]] = {}
        if 'message_definitions' in tables:
            for typename, encoding, text in self._db.execute(
                'SELECT topic_type, encoding, encoded_message_definition FROM message_definitions'
            ):
                if text:
                    definitions[typename] = (encoding, text)
        qos = ', offered_qos_profiles' if 'offered_qos_profiles' in columns else ", ''"
        query = f'SELECT id, name, type, serialization_format{qos} FROM topics ORDER BY id'
        for topic_id, name, typename, fmt, qos_text in self._db.execute(query):
            encoding, text = definitions.get(typename, ('', ''))
            metadata = (('offered_qos_profiles', qos_text),) if qos_text else ()
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
        self.start_time, self.end_time, self.message_count = row

    def messages(self) -> Iterator[tuple[int, int, int, bytes]]:
        """(channel index, log_time, publish_time, data); zstd-compressed blobs are expanded."""
        ids = self._ids
        decompress = zstandard.ZstdDecompressor().decompressobj
        try:
            for topic_id, timestamp, data in self._db.execute(
                'SELECT topic_id, timestamp, data FROM messages ORDER BY timestamp, id'
            ):
                if data[:4] == ZSTD_MAGIC:
                    data = decompress().decompress(data)
                index = ids.get(topic_id)
                if index is not None:
                    yield index, timestamp, timestamp, data
        except sqlite3.DatabaseError as exc:
            raise InputError(f'{self.display}: corrupt rosbag2 database ({exc})') from None
        except zstandard.ZstdError as exc:
            raise InputError(f'{self.display}: corrupt zstd message ({exc})') from None

    def close(self) -> None:
        """Close the database."""
        self._db.close()
