"""The lean MCAP writer produces files that the `mcap` library and rosbags read through every path."""

from __future__ import annotations

import io
import struct
import zlib
from pathlib import Path

import pytest
import zstandard
from mcap.reader import make_reader
from mcap.records import Chunk, Message, MessageIndex
from mcap.stream_reader import StreamReader

from bagfault.io.mcap_sink import McapSink
from bagfault.io.mcap_writer import McapWriter

TEXT = 'float64 data\n'
TIMES = [1_000 + k * 10 + (0 if k % 5 else 25) for k in range(50)]  # every fifth message is late


def write(stream: io.BytesIO | None = None, *, compression: str = 'zstd', chunk_size: int = 200) -> bytes:
    """Two channels, log times interleaved and not sorted inside chunks, several small chunks."""
    stream = stream or io.BytesIO()
    writer = McapWriter(stream, compression=compression, chunk_size=chunk_size, library='test')
    schema = writer.register_schema('std_msgs/msg/Float64', 'ros2msg', TEXT.encode())
    first = writer.register_channel('/a', 'cdr', schema, {'offered_qos_profiles': ''})
    second = writer.register_channel('/b', 'cdr', schema, {})
    writer.add_metadata('info', {'k': 'v'})
    for k in range(50):
        channel = first if k % 3 else second
        time = TIMES[k]
        writer.add_message(channel, time, b'\x00\x01\x00\x00' + struct.pack('<d', k), time + 1, sequence=k)
    writer.add_attachment(5, 6, 'scenario.yaml', 'application/yaml', b'faults: []\n')
    writer.finish()
    return stream.getvalue()


@pytest.mark.parametrize('compression', ['zstd', 'lz4', 'none'])
def test_indexed_reader_sees_every_message_in_time_order(compression: str) -> None:
    data = write(compression=compression)
    reader = make_reader(io.BytesIO(data))
    summary = reader.get_summary()
    assert summary is not None
    assert summary.statistics.message_count == 50
    assert summary.statistics.channel_message_counts == {1: 33, 2: 17}
    assert summary.statistics.chunk_count == len(summary.chunk_indexes) > 3
    assert summary.statistics.message_start_time == min(TIMES) == 1_010
    assert summary.statistics.message_end_time == max(TIMES) == 1_490
    times = [m.log_time for _, _, m in reader.iter_messages(log_time_order=True)]
    assert times == sorted(times) and len(times) == 50
    only_b = [struct.unpack('<d', m.data[4:])[0] for _, _, m in reader.iter_messages(topics=['/b'])]
    assert only_b == [k for k in range(50) if k % 3 == 0]
    window = [m.log_time for _, _, m in reader.iter_messages(starting_at=1_100, ending_before=1_200)]
    assert sorted(window) == [t for t in sorted(TIMES) if 1_100 <= t < 1_200]
    assert [m.name for m in reader.iter_metadata()] == ['info']
    assert [a.data for a in reader.iter_attachments()] == [b'faults: []\n']


def test_crcs_validate_and_message_indexes_point_at_their_messages() -> None:
    data = write()
    decoded = list(StreamReader(io.BytesIO(data), skip_magic=False, validate_crcs=True).records)
    assert sum(isinstance(r, Message) for r in decoded) == 50
    records = list(StreamReader(io.BytesIO(data), skip_magic=False, emit_chunks=True).records)
    seen = set()
    body = b''
    for record in records:
        if isinstance(record, Chunk):
            assert record.compression == 'zstd'
            body = zstandard.ZstdDecompressor().decompress(record.data, max_output_size=record.uncompressed_size)
            assert zlib.crc32(body) == record.uncompressed_crc
        elif isinstance(record, MessageIndex):
            for log_time, offset in record.records:
                opcode, _, channel_id, _, stamp = struct.unpack_from('<BQHIQ', body, offset)
                assert (opcode, channel_id, stamp) == (0x05, record.channel_id, log_time)
                seen.add(stamp)
    assert seen == set(TIMES)


def test_output_is_identical_run_to_run_and_readable_by_rosbags(tmp_path: Path) -> None:
    from rosbags.highlevel import AnyReader

    assert write() == write()
    path = tmp_path / 'out.mcap'
    path.write_bytes(write())
    with AnyReader([path]) as reader:
        values = [reader.deserialize(raw, c.msgtype).data for c, _, raw in reader.messages()]
    assert sorted(values) == [float(k) for k in range(50)]


def test_failed_sink_leaves_nothing_under_the_requested_name(tmp_path: Path) -> None:
    target = tmp_path / 'out.mcap'
    sink = McapSink(target)
    channel = sink.add_channel('/a', 'std_msgs/msg/Float64', 'ros2msg', TEXT)
    sink.write(channel, 1, 1, b'\x00\x01\x00\x00' + bytes(8))
    sink.abort()
    assert list(tmp_path.iterdir()) == []


def test_sink_output_has_the_usual_file_permissions(tmp_path: Path) -> None:
    import os
    import stat

    mask = os.umask(0o022)
    try:
        sink = McapSink(tmp_path / 'out.mcap')
        sink.finish()
    finally:
        os.umask(mask)
    assert stat.S_IMODE((tmp_path / 'out.mcap').stat().st_mode) == 0o644


def test_a_waiting_writer_compresses_queued_chunks_itself(monkeypatch: pytest.MonkeyPatch) -> None:
    """When the compressor falls behind, the writing thread compresses chunks the worker has not started
    instead of waiting: the same bytes, part of the chunks compressed on each thread."""
    import threading
    import time

    from bagfault.io import mcap_writer

    expected = write(chunk_size=60)  # about 25 chunks
    original, where = mcap_writer._compress, []

    def slow(compression: str, level: int, data: bytes) -> tuple[bytes, int]:
        worker = threading.current_thread().name.startswith('mcap-compress')
        where.append('worker' if worker else 'writer')
        if worker:
            time.sleep(0.02)
        return original(compression, level, data)

    monkeypatch.setattr(mcap_writer, '_compress', slow)
    monkeypatch.setattr(mcap_writer, 'PENDING_CHUNKS', 2)
    assert write(chunk_size=60) == expected
    assert 'worker' in where and 'writer' in where
    assert len(where) == make_reader(io.BytesIO(expected)).get_summary().statistics.chunk_count


@pytest.mark.parametrize(('compression', 'level', 'expected'), [
    ('zstd', None, lambda data: zstandard.ZstdCompressor(level=1).compress(data)),  # the MCAP C++ writer's default
    ('zstd', 19, lambda data: zstandard.ZstdCompressor(level=19).compress(data)),
    ('lz4', None, lambda data: __import__('lz4.frame').frame.compress(data, compression_level=0)),
    ('lz4', 9, lambda data: __import__('lz4.frame').frame.compress(data, compression_level=9)),
])
def test_chunks_are_compressed_at_the_level_asked(compression: str, level: int | None, expected) -> None:
    """Each chunk's bytes are what the compression library makes of its records at that level: the default is
    the MCAP C++ writer's (CompressionLevel::Default: zstd 1; lz4 its fast mode)."""
    stream = io.BytesIO()
    writer = McapWriter(stream, compression=compression, chunk_size=200, library='test', level=level)
    schema = writer.register_schema('std_msgs/msg/Float64', 'ros2msg', TEXT.encode())
    channel = writer.register_channel('/a', 'cdr', schema, {})
    for k in range(50):
        writer.add_message(channel, 1_000 + k, b'\x00\x01\x00\x00' + struct.pack('<d', k % 7), 1_000 + k)
    writer.finish()
    chunks = [r for r in StreamReader(io.BytesIO(stream.getvalue()), skip_magic=False, emit_chunks=True).records
              if isinstance(r, Chunk)]
    assert len(chunks) > 3
    for chunk in chunks:
        plain = zstandard.ZstdDecompressor().decompress(chunk.data, max_output_size=chunk.uncompressed_size) \
            if compression == 'zstd' else __import__('lz4.frame').frame.decompress(chunk.data)
        assert chunk.compression == compression
        assert chunk.data == expected(plain)


def test_a_level_the_compression_does_not_take_is_refused_before_anything_is_written(tmp_path: Path) -> None:
    from bagfault.errors import OutputError

    for compression, level, problem in (('zstd', 23, r'zstd compression level 23 is outside -7\.\.22'),
                                        ('lz4', -1, r'lz4 compression level -1 is outside 0\.\.16'),
                                        ('none', 3, r'a compression level needs a compression')):
        with pytest.raises(OutputError, match=problem):
            McapSink(tmp_path / 'out.mcap', compression=compression, level=level)
    assert list(tmp_path.iterdir()) == []


def test_numbered_schemas_and_channels_wait_for_the_writer_s_own_next_record() -> None:
    """An input's channels (given ids) go first, where copied chunks can follow them; new ones (numbered) just
    before the first chunk, metadata or attachment the writer writes itself, a channel without messages too."""
    stream = io.BytesIO()
    writer = McapWriter(stream, library='test')
    writer.reserve(7, 9)
    new_schema = writer.register_schema('std_msgs/msg/Float64', 'ros2msg', TEXT.encode())
    new = writer.register_channel('/new', 'cdr', new_schema, {})
    writer.register_schema('std_msgs/msg/Float64', 'ros2msg', TEXT.encode(), schema_id=7)
    writer.register_channel('/input', 'cdr', 7, {}, channel_id=9)
    writer.register_channel('/quiet', 'cdr', new_schema, {})
    writer.add_message(new, 10, b'\x00\x01\x00\x00' + struct.pack('<d', 1.5), 10)
    writer.add_message(9, 11, b'\x00\x01\x00\x00' + struct.pack('<d', 2.5), 11)
    writer.add_metadata('info', {'k': 'v'})
    writer.finish()
    data = stream.getvalue()
    order = []
    for record in StreamReader(io.BytesIO(data), skip_magic=False, emit_chunks=True).records:
        name = type(record).__name__
        if name in ('Schema', 'Channel'):
            order.append(f'{name} {record.id}')
        elif name in ('Header', 'Chunk', 'Metadata', 'DataEnd'):
            order.append(name)
    assert order[:order.index('DataEnd') + 1] == ['Header', 'Schema 7', 'Channel 9', 'Schema 8', 'Channel 10',
                                                  'Channel 11', 'Chunk', 'Metadata', 'DataEnd']
    reader = make_reader(io.BytesIO(data))
    assert {c.topic: c.id for c in reader.get_summary().channels.values()} == {'/new': 10, '/input': 9, '/quiet': 11}
    assert [(c.topic, m.log_time) for _, c, m in reader.iter_messages()] == [('/new', 10), ('/input', 11)]
