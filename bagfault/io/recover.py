"""`bagfault recover`: a recording cut short (SIGKILL, the OOM killer, a power cut) made a valid MCAP again.

A live recording grows under a temporary name (`.NAME.XXXX.partial` beside
the requested one) and completes a chunk at least once a second, so after a
kill the file holds every chunk but the last. Its records are read in order
with the `mcap` library, CRCs checked, up to the first that is cut or
damaged; schemas, channels, the messages of every complete chunk, metadata
and attachments are written to a new file with a summary, all or nothing.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path

from mcap.exceptions import McapError
from mcap.records import Attachment, Channel, DataEnd, Footer, Message, Metadata, Schema
from mcap.stream_reader import StreamReader

from bagfault.errors import InputError
from bagfault.io.mcap_layout import MAGIC
from bagfault.io.mcap_sink import McapSink
from bagfault.io.rosbag2_record import distro_of

READ_ERRORS = (McapError, EOFError, ValueError, KeyError, OSError, struct.error)


@dataclass
class Recovered:
    """What a recovery kept, and why it stopped where it did."""

    source: Path
    output: Path
    messages: int = 0
    channels: int = 0
    complete: bool = False  # the source was a finished file (nothing was lost)
    stopped: str = ''  # what ended the readable part


def partial_of(path: Path) -> Path:
    """The file to recover: `path` itself, or the newest `.NAME.*.partial` beside it (the requested name)."""
    if path.is_file():
        return path
    found = sorted(path.parent.glob(f'.{path.name}.*.partial'), key=lambda p: p.stat().st_mtime)
    if not found:
        raise InputError(f'{path}: no such file, and no partial recording (.{path.name}.*.partial) beside it')
    return found[-1]


def requested_name(partial: Path) -> Path:
    """`out.mcap` for `.out.mcap.k2j4x.partial`; `NAME.recovered.mcap` for anything else."""
    name = partial.name
    if name.startswith('.') and name.endswith('.partial') and name.count('.') >= 3:
        return partial.with_name(name[1:].rsplit('.', 2)[0])
    return partial.with_name(f'{partial.stem}.recovered.mcap')


def recover(source: Path, output: Path) -> Recovered:
    """Copy the readable part of `source` into a complete MCAP at `output`."""
    result = Recovered(source, output)
    with source.open('rb') as stream:
        if stream.read(len(MAGIC)) != MAGIC:
            raise InputError(f'{source}: not an MCAP recording (no MCAP magic at its start); nothing to recover')
    channels: dict[int, int] = {}
    schemas: dict[int, Schema] = {}
    with McapSink(output, ros_distro=_distro(source)) as sink:  # dropped unless finished
        with source.open('rb') as stream:
            reader = StreamReader(stream, validate_crcs=True)
            try:
                for record in reader.records:
                    if isinstance(record, Schema):
                        schemas[record.id] = record
                    elif isinstance(record, Channel):
                        if record.id in channels:
                            continue
                        schema = schemas.get(record.schema_id)
                        channels[record.id] = sink.add_channel(
                            record.topic, schema.name if schema else '', schema.encoding if schema else '',
                            schema.data.decode(errors='replace') if schema else '', record.message_encoding,
                            dict(record.metadata))
                    elif isinstance(record, Message):
                        if record.channel_id in channels:
                            sink.write(channels[record.channel_id], record.log_time, record.publish_time, record.data)
                            result.messages += 1
                    elif isinstance(record, Metadata) and record.name != 'rosbag2':
                        sink.add_metadata(record.name, dict(record.metadata))
                    elif isinstance(record, Attachment):
                        sink.add_attachment(record.name, record.media_type, record.data, record.log_time)
                    elif isinstance(record, (DataEnd, Footer)):
                        result.complete = True
                        break
            except READ_ERRORS as exc:
                result.stopped = ' '.join(str(exc).split()) or type(exc).__name__
        if not result.complete and not result.stopped:
            result.stopped = 'the file ends'
        result.channels = len(channels)
        sink.finish()
    return result


def _distro(source: Path) -> str:
    """The distro of the recording's opening `rosbag2` record (live recordings write one at their start, as
    rosbag2 does), '' when it has none."""
    with source.open('rb') as stream:
        try:
            for record in StreamReader(stream, validate_crcs=True).records:
                if isinstance(record, Metadata) and record.name == 'rosbag2':
                    return distro_of(record.metadata) or ''
                if isinstance(record, (Message, DataEnd)):
                    break
        except READ_ERRORS:
            pass
    return ''
