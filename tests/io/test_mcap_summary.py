"""The hand-written summary parser gives the `mcap` library's records, on files of many writers."""

from __future__ import annotations

import io
import struct
import zlib
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer
from support.helpers import EXTERNAL, FIXTURES, third_party

from bagfault.errors import InputError
from bagfault.io.mcap_source import McapSource
from bagfault.io.mcap_summary import FOOTER_LENGTH, SummaryError, parse_summary, read_footer, read_metadata


def ours(path: Path) -> tuple[object, list[object]]:
    """(summary, metadata records) as bagfault parses them."""
    with path.open('rb') as stream:
        size = path.stat().st_size
        start, _ = read_footer(stream, size)
        if not start:
            return None, []
        stream.seek(start)
        summary = parse_summary(stream.read(size - 8 - FOOTER_LENGTH - start))
        return summary, [read_metadata(stream, index) for index in summary.metadata_indexes]


def library(path: Path) -> tuple[object, list[object]]:
    """(summary, metadata records) as the mcap library reads them."""
    with path.open('rb') as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        return summary, (list(reader.iter_metadata()) if summary is not None else [])


def same(a: object, b: object) -> None:
    """Field by field (the library's Summary has no __eq__ over its lists of records)."""
    if a is None or b is None:
        assert a is b
        return
    assert a.schemas == b.schemas
    assert a.channels == b.channels
    assert a.statistics == b.statistics
    assert a.chunk_indexes == b.chunk_indexes
    assert a.metadata_indexes == b.metadata_indexes


def written_by_library(path: Path) -> Path:
    """A file the mcap library writes: small chunks, channel metadata, metadata records, an attachment."""
    with path.open('wb') as stream:
        writer = Writer(stream, compression=CompressionType.LZ4, chunk_size=200)
        writer.start(profile='ros2', library='test')
        schema = writer.register_schema('std_msgs/msg/String', 'ros2msg', b'string data')
        first = writer.register_channel('/a', 'cdr', schema, {'offered_qos_profiles': '- depth: 10', 'x': 'é'})
        second = writer.register_channel('/b', 'cdr', schema)
        for n in range(50):
            writer.add_message(first if n % 3 else second, log_time=n * 1000, data=bytes(n), publish_time=n)
        writer.add_metadata('rosbag2', {'serialized_metadata': 'a: 1', 'ROS_DISTRO': 'jazzy'})
        writer.add_metadata('empty', {})
        writer.add_attachment(1, 2, 'scenario.yaml', 'application/yaml', b'faults: []')
        writer.finish()
    return path


def test_same_records_as_the_library_on_a_library_file(tmp_path):
    path = written_by_library(tmp_path / 'lib.mcap')
    summary, metadata = ours(path)
    expected_summary, expected_metadata = library(path)
    same(summary, expected_summary)
    assert metadata == expected_metadata
    assert len(summary.chunk_indexes) > 10  # the 200-byte chunks made many indexes
    assert [m.name for m in metadata] == ['rosbag2', 'empty']
    assert summary.channels[1].metadata['x'] == 'é'


def test_same_records_as_the_library_on_bagfaults_own_fixture():
    path = FIXTURES / 'rover_20s.mcap'
    summary, metadata = ours(path)
    expected_summary, expected_metadata = library(path)
    same(summary, expected_summary)
    assert metadata == expected_metadata


@pytest.mark.parametrize('root', third_party([EXTERNAL]))
def test_same_records_as_the_library_on_every_external_mcap(root):
    compared = 0
    for path in sorted(root.rglob('*.mcap')):
        try:
            expected = library(path)
        except Exception:  # files the library itself refuses (the conformance set has invalid ones)
            continue
        summary, metadata = ours(path)
        same(summary, expected[0])
        assert metadata == expected[1], path
        compared += 1
    assert compared > 100


def test_a_record_running_past_the_summary_is_refused(tmp_path):
    """A chunk index whose length field overstates it: an InputError naming the file, not a crash."""
    path = written_by_library(tmp_path / 'lib.mcap')
    data = bytearray(path.read_bytes())
    size = len(data)
    start, _ = struct.unpack_from('<QQ', data, size - 8 - FOOTER_LENGTH + 9)
    opcode, length = struct.unpack_from('<BQ', data, start)
    while opcode != 0x08:  # the first chunk index
        start += 9 + length
        opcode, length = struct.unpack_from('<BQ', data, start)
    struct.pack_into('<Q', data, start + 1, size)
    struct.pack_into('<I', data, size - 8 - 4, 0)  # no summary CRC: the parser itself must notice
    path.write_bytes(bytes(data))
    with pytest.raises(InputError, match=r'lib\.mcap: corrupt MCAP file: .*runs past the summary'):
        McapSource(path)


def test_a_map_longer_than_its_record_is_refused():
    body = struct.pack('<H', 1) + struct.pack('<H', 0) + b'\x01\x00\x00\x00/' + b'\x03\x00\x00\x00cdr'
    body += struct.pack('<I', 100)  # metadata map claims 100 bytes
    record = struct.pack('<BQ', 0x04, len(body)) + body
    with pytest.raises(SummaryError, match='map of 100 bytes runs past its record'):
        parse_summary(record)


def test_summary_crc_is_checked(tmp_path):
    path = written_by_library(tmp_path / 'lib.mcap')
    data = bytearray(path.read_bytes())
    start, _ = struct.unpack_from('<QQ', data, len(data) - 8 - FOOTER_LENGTH + 9)
    data[start + 20] ^= 0xFF
    path.write_bytes(bytes(data))
    stored = struct.unpack_from('<I', data, len(data) - 12)[0]
    computed = zlib.crc32(bytes(data[start : len(data) - 12]))
    with pytest.raises(InputError, match=f'summary CRC mismatch \\(stored {stored:#010x}, computed {computed:#010x}\\)'):
        McapSource(path)


def test_no_summary_reads_metadata_through_the_file(tmp_path):
    """A file whose footer has no summary (a stream writer's): metadata found by reading it through."""
    stream = io.BytesIO()
    writer = Writer(stream, compression=CompressionType.NONE, use_summary_offsets=False, use_chunking=False,
                    use_statistics=False, repeat_schemas=False, repeat_channels=False)
    writer.start()
    writer.add_metadata('rosbag2', {'ROS_DISTRO': 'humble'})
    writer.finish()
    data = bytearray(stream.getvalue())
    struct.pack_into('<QQI', data, len(data) - 8 - FOOTER_LENGTH + 9, 0, 0, 0)  # footer: no summary
    path = tmp_path / 'stream.mcap'
    path.write_bytes(bytes(data))
    assert ours(path) == (None, [])
    assert McapSource(path).ros_distro == 'humble'
