"""Output MCAP (profile ros2), written to a temporary name and renamed when complete."""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path

from bagfault.errors import OutputError
from bagfault.io.mcap_writer import McapWriter
from bagfault.io.outputs import current_umask

COMPRESSIONS = ('none', 'lz4', 'zstd')


class McapSink:
    """Writes schemas, channels, messages, metadata and attachments.

    Nothing appears under the requested name until `finish` succeeds; `abort`
    removes the partial file.
    """

    def __init__(self, path: Path, *, compression: str = 'zstd', chunk_size: int = 1 << 20) -> None:
        self.path = path
        if compression not in COMPRESSIONS:
            raise OutputError(f'{path}: unknown compression {compression!r} (none, lz4, zstd)')
        directory = path.parent if str(path.parent) else Path('.')
        if path.is_dir():
            raise OutputError(f'{path}: is a directory; give a file name such as out.mcap')
        if not directory.is_dir():
            raise OutputError(f'{path}: directory {directory} does not exist')
        try:
            handle, tmp = tempfile.mkstemp(prefix=f'.{path.name}.', suffix='.partial', dir=directory)
        except OSError as exc:
            raise OutputError(f'{path}: cannot write in {directory}: {exc.strerror}') from None
        self._tmp = Path(tmp)
        os.chmod(handle, 0o666 & ~current_umask())  # mkstemp makes 0600; outputs get the usual permissions
        self._stream = os.fdopen(handle, 'wb', buffering=1 << 20)
        self._writer = McapWriter(self._stream, chunk_size=chunk_size, compression=compression,
                                  library=f'bagfault {_version()}')
        self._schemas: dict[tuple[str, str, str], int] = {}

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
        key = (msgtype, schema_encoding or 'ros2msg', schema_text)
        schema_id = self._schemas.get(key)
        if schema_id is None:
            schema_id = self._writer.register_schema(msgtype, key[1], schema_text.encode())
            self._schemas[key] = schema_id
        return self._writer.register_channel(topic, message_encoding, schema_id, dict(metadata or {}))

    def write(self, channel_id: int, log_time: int, publish_time: int, data: bytes | memoryview) -> None:
        """Append one message."""
        self._writer.add_message(channel_id, log_time, data, publish_time)

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        """Append a metadata record."""
        self._writer.add_metadata(name, data)

    def add_attachment(self, name: str, media_type: str, data: bytes, log_time: int = 0) -> None:
        """Append an attachment (create_time 0 keeps output reproducible)."""
        self._writer.add_attachment(create_time=0, log_time=log_time, name=name, media_type=media_type, data=data)

    def finish(self) -> None:
        """Write the summary and move the file to its final name."""
        self.close_unpublished()
        self.publish()

    def close_unpublished(self) -> None:
        """Complete the file under its temporary name (published later, or aborted)."""
        try:
            self._writer.finish()
            self._stream.close()
        except OSError as exc:
            self.abort()
            raise OutputError(f'{self.path}: cannot write: {exc.strerror}') from None

    def publish(self) -> None:
        """Move the completed file to its final name."""
        try:
            os.replace(self._tmp, self.path)
        except OSError as exc:
            self.abort()
            raise OutputError(f'{self.path}: cannot write: {exc.strerror}') from None

    def abort(self) -> None:
        """Drop the partial output."""
        self._writer.abandon()
        with contextlib.suppress(OSError):
            self._stream.close()
        self._tmp.unlink(missing_ok=True)


def _version() -> str:
    from bagfault import __version__  # noqa: PLC0415

    return __version__



