"""An MCAP's indexes against its data section: chunks left out of the chunk index or indexed twice, a chunk
record that disagrees with its index, message indexes against the records of their chunk, unknown records
inside a chunk, a channel id defined twice. Each is an error naming the file and the place (exit 2, no
output), or with --salvage a warning; copied chunks are checked against their indexes, and with --verify
decompressed and counted too.

The files are written by the `mcap` library (its Writer, with small chunks), then damaged as the issue's
hostile round did; the expected counts are the library's (Statistics) and the reader's (`mcap`'s own
`iter_messages`, which skips what it cannot read).
"""

from __future__ import annotations

import struct
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.records import Channel as McapChannel
from mcap.records import ChunkIndex
from mcap.writer import CompressionType, Writer

from bagfault.cli import main

TOPICS = ('/a', '/b')
PER_TOPIC = 40  # 80 messages, 16 bytes each, in chunks of about 8 messages
SCENARIO = ('injector: {id: i, type: imu, input_topic: /imu, output_topic: /imu_out}\nfaults: []\n')
TOUCH_A = ('injector: {id: i, type: topic, input_topic: /a, output_topic: /a}\n'
           'faults: [{id: f, injector_id: i, start: 0.0, config: {drop_probability: 0.0}}]\n')


def write(path: Path, *, compression: CompressionType = CompressionType.NONE, drop_index: int | None = None,
          twice: int | None = None) -> Path:
    """80 messages on two channels in chunks of ~8 (the mcap library's writer, no chunk CRCs like rosbag2's);
    `drop_index` leaves that chunk out of the chunk index, `twice` indexes that chunk twice; the summary and its
    CRC are the library's own, so they are consistent."""
    with path.open('wb') as stream:
        writer = Writer(stream, chunk_size=300, compression=compression, enable_data_crcs=False)
        writer.start(profile='', library='test')
        schema = writer.register_schema('raw', 'jsonschema', b'{}')
        qos = {'offered_qos_profiles': ''}  # what lets a chunk be copied: a schema, and QoS as rosbag2 gives it
        channels = [writer.register_channel(topic, 'json', schema, qos) for topic in TOPICS]
        for k in range(PER_TOPIC):
            for number, channel in enumerate(channels):
                time = 1_000_000_000 + k * 50_000_000 + number
                writer.add_message(channel, time, b'{"k": %06d}   ' % k, time, sequence=k)
        indexes: list[ChunkIndex] = writer._Writer__chunk_indices  # type: ignore[attr-defined]
        assert len(indexes) >= 6
        if drop_index is not None:
            del indexes[drop_index]
        if twice is not None:
            indexes.insert(twice + 1, indexes[twice])
        writer.finish()
    return path


def readable(path: Path) -> int:
    """Messages the `mcap` library's reader yields."""
    with path.open('rb') as stream:
        return sum(1 for _ in make_reader(stream).iter_messages())


def run(tmp_path: Path, bag: Path, *extra: str, scenario: str = SCENARIO) -> tuple[int, str, Path]:
    path = tmp_path / 'scenario.yaml'
    path.write_text(scenario)
    out = tmp_path / 'out.mcap'
    out.unlink(missing_ok=True)
    code = main(['run', str(path), str(bag), '-o', str(out), *extra])
    return code, out


def chunk_offsets(path: Path) -> list[int]:
    with path.open('rb') as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None
    return sorted(c.chunk_start_offset for c in summary.chunk_indexes)


@pytest.mark.parametrize('copy', [True, False], ids=['chunk-copy', 'reference'])
def test_a_chunk_left_out_of_the_chunk_index(tmp_path: Path, capsys: pytest.CaptureFixture[str], copy: bool) -> None:
    bag = write(tmp_path / 'bag.mcap', drop_index=2)
    assert readable(bag) < 2 * PER_TOPIC  # what a reader that follows the index gets
    code, out = run(tmp_path, bag, *([] if copy else ['--no-chunk-copy']))
    error = capsys.readouterr().err.strip()
    assert code == 2 and error.count('\n') == 0 and 'not in the chunk index' in error and str(bag) in error
    assert not out.exists()
    code, out = run(tmp_path, bag, '--salvage')
    captured = capsys.readouterr()
    assert code == 0 and 'not in the chunk index' in captured.err
    assert readable(out) == 2 * PER_TOPIC  # salvage reads the unindexed chunk too: nothing lost


@pytest.mark.parametrize('copy', [True, False], ids=['chunk-copy', 'reference'])
def test_a_chunk_indexed_twice(tmp_path: Path, capsys: pytest.CaptureFixture[str], copy: bool) -> None:
    bag = write(tmp_path / 'bag.mcap', twice=1)
    code, out = run(tmp_path, bag, *([] if copy else ['--no-chunk-copy']))
    error = capsys.readouterr().err.strip()
    assert code == 2 and 'indexed twice' in error and not out.exists()
    code, out = run(tmp_path, bag, '--salvage')
    assert code == 0 and readable(out) == 2 * PER_TOPIC  # read once, not 8 messages twice


def flip_message_opcode(path: Path, chunk: int) -> int:
    """Turn the first Message record of an uncompressed chunk into an unknown opcode (a one-bit flip: 0x05 ->
    0x45); the chunk's CRC is set to 0 first, as rosbag2 writes chunks. Returns the chunk's offset."""
    data = bytearray(path.read_bytes())
    offset = chunk_offsets(path)[chunk]
    body = offset + 9
    struct.pack_into('<I', data, body + 24, 0)
    name_length = struct.unpack_from('<I', data, body + 28)[0]
    records = body + 32 + name_length + 8
    position = records
    while data[position] != 0x05:
        position += 9 + struct.unpack_from('<Q', data, position + 1)[0]
    data[position] ^= 0x40
    path.write_bytes(bytes(data))
    return offset


def test_a_flipped_message_opcode_in_a_chunk_without_crc(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The reference path and a faulted chunk find it (the chunk's message indexes count one more message than
    it holds); a copied chunk is passed through byte for byte unless --verify reads it."""
    bag = write(tmp_path / 'bag.mcap')
    offset = flip_message_opcode(bag, 3)
    assert readable(bag) == 2 * PER_TOPIC - 1  # the library's reader skips the unknown record
    code, out = run(tmp_path, bag, '--no-chunk-copy')
    error = capsys.readouterr().err.strip()
    assert code == 2 and error.count('\n') == 0 and f'chunk at offset {offset}' in error and 'type 0x45' in error
    code, out = run(tmp_path, bag, scenario=TOUCH_A)  # a fault on /a all along: every chunk is decompressed
    assert code == 2 and 'type 0x45' in capsys.readouterr().err and not out.exists()
    code, out = run(tmp_path, bag)  # nothing faulted: copied as it is, unverified, and the summary says so
    captured = capsys.readouterr()
    assert code == 0 and 'unverified (--verify reads them)' in captured.out
    assert out.read_bytes().count(bag.read_bytes()[offset:offset + 200]) == 1  # the same bytes, same damage
    code, out = run(tmp_path, bag, '--verify')
    error = capsys.readouterr().err.strip()
    assert code == 2 and error.count('\n') == 0 and f'chunk at offset {offset} (copied, then verified)' in error
    assert not out.exists()


def test_verify_of_a_sound_file_says_every_copied_chunk_was_verified(tmp_path: Path,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    bag = write(tmp_path / 'bag.mcap', compression=CompressionType.ZSTD)
    chunks = len(chunk_offsets(bag))
    code, out = run(tmp_path, bag, '--verify')
    assert code == 0 and f'{chunks} of {chunks} chunks copied as they are and verified' in capsys.readouterr().out
    assert readable(out) == 2 * PER_TOPIC


def test_a_chunk_record_that_disagrees_with_its_index(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The chunk record's uncompressed size changed (the index still says the old one): found without
    decompressing, on the copy path too."""
    bag = write(tmp_path / 'bag.mcap')
    data = bytearray(bag.read_bytes())
    offset = chunk_offsets(bag)[1]
    size = struct.unpack_from('<Q', data, offset + 9 + 16)[0]
    struct.pack_into('<Q', data, offset + 9 + 16, size + 1)
    bag.write_bytes(bytes(data))
    code, out = run(tmp_path, bag)
    error = capsys.readouterr().err.strip()
    assert code == 2 and f'uncompressed size {size + 1} in the record, {size} in the index' in error
    assert not out.exists()


def test_a_message_index_entry_outside_its_chunk(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A message index whose offset points past the chunk's records: the copy would carry an index no reader
    can follow."""
    bag = write(tmp_path / 'bag.mcap')
    data = bytearray(bag.read_bytes())
    with bag.open('rb') as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None
    index = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)[2]
    record = min(index.message_index_offsets.values())
    struct.pack_into('<Q', data, record + 15 + 8, index.uncompressed_size + 100)  # first entry's offset
    bag.write_bytes(bytes(data))
    code, out = run(tmp_path, bag)
    error = capsys.readouterr().err.strip()
    assert code == 2 and 'point outside the chunk' in error and not out.exists()


def test_a_channel_id_defined_again_with_another_topic(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Channel 1 defined as /a, then (in a later chunk) as /z: the paths would disagree on its topic."""
    bag = tmp_path / 'bag.mcap'
    with bag.open('wb') as stream:
        writer = Writer(stream, chunk_size=200, compression=CompressionType.NONE)
        writer.start(profile='', library='test')
        schema = writer.register_schema('raw', 'jsonschema', b'{}')
        first = writer.register_channel('/a', 'json', schema)
        for k in range(20):
            writer.add_message(first, 1_000_000_000 + k * 1000, b'{}', 0)
        again = McapChannel(id=first, topic='/z', message_encoding='json', schema_id=schema, metadata={})
        writer._Writer__chunk_builder.add_channel(again)  # type: ignore[attr-defined]
        for k in range(20, 40):
            writer.add_message(first, 1_000_000_000 + k * 1000, b'{}', 0)
        writer.finish()
    code, out = run(tmp_path, bag, '--no-chunk-copy')
    error = capsys.readouterr().err.strip()
    assert code == 2 and 'channel 1' in error and "'/a'" in error and "'/z'" in error and not out.exists()


def test_statistics_that_move_messages_between_channels(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The total is right, the per-channel counts are not (3 of /b's counted as /a's): found against the
    message indexes, whose counts are themselves checked against the chunks."""
    bag = tmp_path / 'bag.mcap'
    with bag.open('wb') as stream:
        writer = Writer(stream, chunk_size=300, compression=CompressionType.ZSTD)
        writer.start(profile='', library='test')
        schema = writer.register_schema('raw', 'jsonschema', b'{}')
        channels = [writer.register_channel(t, 'json', schema, {'offered_qos_profiles': ''}) for t in TOPICS]
        for k in range(PER_TOPIC):
            for number, channel in enumerate(channels):
                writer.add_message(channel, 10**9 + k * 10**7 + number, b'{}', 0)
        statistics = writer._Writer__statistics  # type: ignore[attr-defined]
        statistics.channel_message_counts[channels[0]] += 3
        statistics.channel_message_counts[channels[1]] -= 3
        writer.finish()
    code, out = run(tmp_path, bag)
    error = capsys.readouterr().err.strip()
    assert code == 2 and error.count('\n') == 0 and 'messages per channel and the message indexes disagree' in error
    assert f'channel {channels[0]}: {PER_TOPIC + 3} declared, {PER_TOPIC} indexed' in error and not out.exists()


def test_the_layout_walk_reads_what_plain_reads_read(tmp_path: Path) -> None:
    """The walk's reads through a map (no read-ahead) give the bytes os.pread gives, short at the end of the
    file; a file that cannot be mapped (an empty one) is read plainly."""
    import os

    from bagfault.io.mcap_index_check import ScatteredReads

    path = tmp_path / 'data.bin'
    path.write_bytes(bytes(range(256)) * 64)
    empty = tmp_path / 'empty.bin'
    empty.write_bytes(b'')
    with path.open('rb') as stream, empty.open('rb') as nothing:
        reads, plain = ScatteredReads(stream.fileno()), ScatteredReads(nothing.fileno())
        for length, offset in ((25, 8), (100, 16_300), (4096, 4000), (10, 16_384), (10, 99_999)):
            assert reads.read(length, offset) == os.pread(stream.fileno(), length, offset)
        assert plain.read(10, 0) == b''
        reads.close()
        plain.close()


def crafted(path: Path, between: str) -> Path:
    """Two chunks of 10 /imu messages each (an index for both, Statistics counting those 20), and between them a
    top-level Message record or a DataEnd record, as a hand-made file holds them; the mcap writer's own records."""
    from mcap.records import DataEnd, Message

    from bagfault.demo import synthetic

    ts = synthetic.store()
    with path.open('wb') as stream:
        writer = Writer(stream, compression=CompressionType.NONE, chunk_size=1 << 20)
        writer.start(profile='ros2', library='test')
        text, _ = ts.generate_msgdef('sensor_msgs/msg/Imu', ros_version=2)
        channel = writer.register_channel('/imu', 'cdr', writer.register_schema('sensor_msgs/msg/Imu', 'ros2msg',
                                                                                 text.encode()), {})
        times = synthetic.sample_times(100.0, 0.2)
        data = [bytes(ts.serialize_cdr(synthetic.imu(ts, t, 0.0), 'sensor_msgs/msg/Imu')) for t in times]
        for t, payload in zip(times[:10], data[:10], strict=True):
            writer.add_message(channel, t, payload, t)
        writer._Writer__finalize_chunk()
        builder = writer._Writer__record_builder
        if between == 'message':
            Message(channel_id=channel, log_time=times[9] + 1, data=data[0], publish_time=times[9] + 1,
                    sequence=0).write(builder)
        else:
            DataEnd(0).write(builder)
        for t, payload in zip(times[10:], data[10:], strict=True):
            writer.add_message(channel, t, payload, t)
        writer.finish()
    return path


def streamed_messages(path: Path) -> int:
    """Every message record the file holds, wherever it sits: the mcap library's streamed reader."""
    from mcap.records import Chunk, Message
    from mcap.stream_reader import StreamReader, breakup_chunk

    count = 0
    with path.open('rb') as stream:
        for record in StreamReader(stream).records:
            parts = breakup_chunk(record) if isinstance(record, Chunk) else [record]
            count += sum(isinstance(part, Message) for part in parts)
    return count


@pytest.mark.parametrize('options', [[], ['--no-chunk-copy'], ['--verify']], ids=['default', 'no-chunk-copy', 'verify'])
def test_a_message_outside_any_chunk_is_read_and_the_statistics_checked(tmp_path, capsys, options):
    """The specification allows a Message record at top level between chunks; readers that follow the index
    skip it (every run path once dropped it at exit 0). bagfault reads it; this file's Statistics count only the
    20 chunked messages, so the run refuses in one line naming that record, and --salvage writes all 21 and
    lists the disagreement. (A file whose Statistics count it is written whole: tests/test_differential.py.)"""
    bag = crafted(tmp_path / 'loose.mcap', 'message')
    assert streamed_messages(bag) == 21 and make_reader(bag.open('rb')).get_summary().statistics.message_count == 20
    scenario = tmp_path / 's.yaml'
    scenario.write_text('injectors: []\n')
    out = tmp_path / 'out.mcap'
    assert main(['run', str(scenario), str(bag), '-o', str(out), *options]) == 2
    err = capsys.readouterr().err
    assert 'the Statistics record' in err and '20 declared, 21 indexed' in err and len(err.strip().splitlines()) == 1
    assert not out.exists()
    assert main(['run', str(scenario), str(bag), '-o', str(out), '--salvage', *options]) == 0
    captured = capsys.readouterr()
    assert 'the Statistics record' in captured.out + captured.err
    assert streamed_messages(out) == 21


def test_chunks_after_an_early_data_end_are_read(tmp_path, capsys):
    """A DataEnd record before the last chunk: the walk goes on to the summary, the chunk after it is read (its
    messages were lost at exit 0 on two paths) and a warning says where the data section should have ended."""
    bag = crafted(tmp_path / 'early_end.mcap', 'data_end')
    scenario = tmp_path / 's.yaml'
    scenario.write_text('injectors: []\n')
    for options in ([], ['--no-chunk-copy'], ['--salvage']):
        out = tmp_path / 'out.mcap'
        out.unlink(missing_ok=True)
        assert main(['run', str(scenario), str(bag), '-o', str(out), *options]) == 0
        assert 'chunks follow the DataEnd record at offset' in capsys.readouterr().err
        assert streamed_messages(out) - streamed_messages(bag) >= 0
        counts = {}
        with out.open('rb') as stream:
            for _, channel, _ in make_reader(stream).iter_messages():
                counts[channel.topic] = counts.get(channel.topic, 0) + 1
        assert counts['/imu'] == 20, options
