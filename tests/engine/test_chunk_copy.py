"""Chunk copy: untouched chunks of a single MCAP input go out as they are, and nothing else changes.

Every case runs twice, with chunk copy and with the reference path
(`--no-chunk-copy`, which decompresses and rewrites every chunk), and the
two outputs must hold the same message stream per topic (log time, publish
time, bytes), read with the `mcap` library (CRCs checked, log-time order)
and with rosbags. Which chunks can be copied is worked out here from the
input's chunk index, independently of the code under test.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, Message
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer
from rosbags.highlevel import AnyReader
from support.foxglove import foxglove_reads
from support.helpers import chunk_indexes, rosbags_counts
from support.mutations import mcap_records
from support.toolchain import converted

from bagfault import api
from bagfault.cli import main
from bagfault.demo.workloads import scenario, write_bag
from bagfault.io.qos import DEFAULT_QOS
from bagfault.scenario import parse_scenario

QOS = {'offered_qos_profiles': DEFAULT_QOS}


@pytest.fixture(scope='module')
def bags(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp('copy')
    paths = {'sensor-heavy': folder / 'sensor.mcap', 'message-heavy': folder / 'message.mcap'}
    write_bag(paths['sensor-heavy'], 'sensor-heavy', 3.0)
    write_bag(paths['message-heavy'], 'message-heavy', 3.0)
    return paths


def streams(path: Path) -> dict[str, list[tuple[int, int, bytes]]]:
    """Per topic (log time, publish time, bytes), read in log-time order with CRCs checked."""
    out: dict[str, list[tuple[int, int, bytes]]] = {}
    last = -1
    with path.open('rb') as stream:
        for _, channel, message in make_reader(stream, validate_crcs=True).iter_messages(log_time_order=True):
            assert message.log_time >= last
            last = message.log_time
            out.setdefault(channel.topic, []).append((message.log_time, message.publish_time, bytes(message.data)))
    return out


def rosbags_count(path: Path) -> int:
    """Messages rosbags reads, checking its log-time order too."""
    count, last = 0, -1
    with AnyReader([path]) as reader:
        for _, time, _ in reader.messages():
            assert time >= last
            last, count = time, count + 1
    return count


def chunk_records(path: Path) -> list[Chunk]:
    with path.open('rb') as stream:
        return [r for r in StreamReader(stream, skip_magic=False, emit_chunks=True).records
                if isinstance(r, Chunk)]


def both(bag: Path, text: str, tmp_path: Path, **options: Any) -> tuple[Any, Any]:
    loaded = parse_scenario(text)
    fast = api.run(loaded, [bag], tmp_path / 'copy.mcap', seed=4, **options)
    reference = api.run(loaded, [bag], tmp_path / 'reference.mcap', seed=4, chunk_copy=False, **options)
    assert streams(tmp_path / 'copy.mcap') == streams(tmp_path / 'reference.mcap')
    assert rosbags_count(tmp_path / 'copy.mcap') == reference.stats.output_messages
    assert fast.stats.output_messages == reference.stats.output_messages
    assert fast.stats.per_topic_out == reference.stats.per_topic_out
    assert [(a.id, a.state, a.time) for a in fast.assertions] == [(a.id, a.state, a.time)
                                                                  for a in reference.assertions]
    return fast, reference


IMU_WINDOW = """
injectors:
  - {id: imu, type: imu, input_topic: /imu, output_topic: /imu}
faults:
  - {id: bias, injector_id: imu, start: 1.0, duration: 0.5, config: {angular_velocity_z_bias: 0.05,
     angular_velocity_z_noise_stddev: 0.02}}
"""


@pytest.mark.parametrize(('kind', 'case'), [('sensor-heavy', c) for c in 'abcd'] + [('message-heavy', c)
                                                                                   for c in 'abd'])
def test_every_benchmark_kind_writes_the_same_stream(bags: dict[str, Path], tmp_path: Path, kind: str,
                                                     case: str) -> None:
    fast, _ = both(bags[kind], scenario(kind, case), tmp_path)
    # the topics with a fault active all along (a: none; b: the IMUs; c: the point cloud; d: every topic)
    with bags[kind].open('rb') as stream:
        summary = make_reader(stream).get_summary()
    faulted = {'a': set(), 'b': {c.id for c in summary.channels.values() if 'imu' in c.topic},
               'c': {c.id for c in summary.channels.values() if c.topic == '/points'},
               'd': set(summary.channels)}[case]
    untouched = [c for c in summary.chunk_indexes if not faulted & set(c.message_index_offsets)]
    assert fast.stats.chunks_copied == len(untouched)
    assert fast.stats.chunks == len(summary.chunk_indexes) == len(chunk_records(bags[kind]))


def test_a_fault_window_copies_the_chunks_outside_it_byte_for_byte(bags: dict[str, Path], tmp_path: Path) -> None:
    bag = bags['sensor-heavy']
    fast, _ = both(bag, IMU_WINDOW, tmp_path)
    with bag.open('rb') as stream:
        summary = make_reader(stream).get_summary()
        first = summary.statistics.message_start_time
        imu = next(c.id for c in summary.channels.values() if c.topic == '/imu')
        window = (first + 1_000_000_000, first + 1_500_000_000)
        # a chunk with /imu messages whose range meets the window (the fault starts and ends on whole ms)
        touched = [c for c in summary.chunk_indexes
                   if imu in c.message_index_offsets and c.message_start_time <= window[1]
                   and c.message_end_time >= window[0]]
    assert touched and fast.stats.chunks_copied == len(summary.chunk_indexes) - len(touched)
    copied = {(c.message_start_time, c.message_end_time, c.data) for c in chunk_records(tmp_path / 'copy.mcap')}
    originals = chunk_records(bag)
    kept = [c for c in originals if (c.message_start_time, c.message_end_time, c.data) in copied]
    assert len(kept) == fast.stats.chunks_copied  # compressed bytes unchanged
    # the same inputs, scenario and seed give the same bytes
    again = api.run(parse_scenario(IMU_WINDOW), [bag], tmp_path / 'again.mcap', seed=4)
    assert again.stats.chunks_copied == fast.stats.chunks_copied
    assert (tmp_path / 'again.mcap').read_bytes() == (tmp_path / 'copy.mcap').read_bytes()


@pytest.mark.parametrize('faults', [
    # a delay that carries messages past the chunk where the window ends
    '[{id: late, injector_id: imu, start: 1.0, duration: 0.3, config: {delay_ms: 400}}]',
    # intermittent, from seeded draws
    '[{id: flaky, injector_id: imu, start: 0.5, duration: 2.0, probability_per_second: 2.0, hold: 0.1, '
    'config: {drop_probability: 1.0}}]',
    # a follower: its window comes from its leader's
    '[{id: lead, injector_id: imu, start: 0.8, duration: 0.2, config: {angular_velocity_z_bias: 0.1}}, '
    '{id: follow, injector_id: imu, after: {fault: lead, delay: 1.0}, duration: 0.2, '
    'config: {drop_probability: 0.5}}]',
])
def test_windows_of_every_schedule_kind(bags: dict[str, Path], tmp_path: Path, faults: str) -> None:
    text = f'injectors:\n  - {{id: imu, type: imu, input_topic: /imu, output_topic: /imu}}\nfaults: {faults}\n'
    fast, _ = both(bags['sensor-heavy'], text, tmp_path)
    assert 0 < fast.stats.chunks_copied < fast.stats.chunks


def test_what_an_oracle_reads_or_an_injector_republishes_is_not_copied(bags: dict[str, Path],
                                                                      tmp_path: Path) -> None:
    bag = bags['sensor-heavy']
    watched = IMU_WINDOW + """
assertions:
  - {id: imu_rate, type: topic_hz, topic: /imu, message_type: sensor_msgs/msg/Imu, min_hz: 100.0, window: 1.0}
  - {id: scan_count, type: message_count, topic: /scan, min: 1}
"""
    fast, _ = both(bag, watched, tmp_path)
    assert fast.stats.chunks_copied == 0  # every chunk holds /imu or /scan messages
    out_of_place = """
injectors:
  - {id: imu, type: imu, input_topic: /imu, output_topic: /imu_biased}
faults:
  - {id: bias, injector_id: imu, start: 1.0, duration: 0.5, config: {angular_velocity_z_bias: 0.05}}
"""
    fast, _ = both(bag, out_of_place, tmp_path)
    assert fast.stats.chunks_copied == 0  # /imu_biased repeats every /imu message
    assert fast.stats.per_topic_out['/imu_biased'] == fast.stats.per_topic_out['/imu']


def test_chunks_that_define_their_own_channels(tmp_path: Path) -> None:
    """The mcap library's writer puts a channel registered mid-recording inside the chunk being written."""
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    text, _ = store.generate_msgdef('std_msgs/msg/String', ros_version=2)
    bag = tmp_path / 'late.mcap'
    with bag.open('wb') as stream:
        writer = Writer(stream, chunk_size=2048, compression=CompressionType.LZ4)
        writer.start(profile='ros2', library='tests')
        schema = writer.register_schema('std_msgs/msg/String', 'ros2msg', text.encode())
        first = writer.register_channel('/a', 'cdr', schema, QOS)
        late = None
        for k in range(400):
            time = 1_000_000_000 + k * 10_000_000
            if k == 200:
                late = writer.register_channel('/b', 'cdr', schema, QOS)
            data = bytes(store.serialize_cdr(store.types['std_msgs/msg/String'](data=f'message {k}'),
                                             'std_msgs/msg/String'))
            writer.add_message(first, time, data, time)
            if late is not None:
                writer.add_message(late, time, data, time)
        writer.finish()
    inside = 0
    with bag.open('rb') as stream:
        from mcap.records import Channel
        from mcap.stream_reader import breakup_chunk
        for record in StreamReader(stream, skip_magic=False, emit_chunks=True).records:
            if isinstance(record, Chunk):
                inside += sum(isinstance(r, Channel) for r in breakup_chunk(record))
    assert inside  # the case this test is about
    text = """
injectors:
  - {id: b, type: topic, input_topic: /b, output_topic: /b}
faults:
  - {id: gap, injector_id: b, start: 2.5, duration: 0.5, config: {drop_probability: 1.0}}
"""
    fast, _ = both(bag, text, tmp_path)
    assert 0 < fast.stats.chunks_copied < fast.stats.chunks


def test_inputs_outside_the_fast_path_take_the_reference_path(bags: dict[str, Path], tmp_path: Path,
                                                              capsys: pytest.CaptureFixture[str]) -> None:
    bag = bags['sensor-heavy']
    scenario_file = tmp_path / 's.yaml'
    scenario_file.write_text(scenario('sensor-heavy', 'a'))
    assert main(['run', str(scenario_file), str(bag), '-o', str(tmp_path / 'one.mcap')]) == 0
    chunks = len(chunk_records(bag))
    assert f'; {chunks} of {chunks} chunks copied as they are' in capsys.readouterr().out
    # two inputs: the reference path (the summary says nothing about chunks)
    assert main(['run', str(scenario_file), str(bag), str(bags['message-heavy']), '-o',
                 str(tmp_path / 'two.mcap')]) == 0
    assert 'chunks copied' not in capsys.readouterr().out
    # --no-chunk-copy
    assert main(['run', str(scenario_file), str(bag), '-o', str(tmp_path / 'ref.mcap'), '--no-chunk-copy']) == 0
    assert 'chunks copied' not in capsys.readouterr().out
    assert streams(tmp_path / 'one.mcap') == streams(tmp_path / 'ref.mcap')


def test_copied_chunks_handed_over_in_any_span_give_the_same_file(bags: dict[str, Path], tmp_path: Path,
                                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    """Consecutive copied chunks go to the copy thread as one span (at most SPAN_LIMIT bytes): one chunk per
    span and the whole file in one span write the same bytes, around the window's rewritten chunks too; also
    where no span is aligned and where every span is (ALIGN_FROM 1 byte: after a padding record, so placed
    where it would be as one span)."""
    from bagfault.io import mcap_layout, mcap_writer

    loaded = parse_scenario(IMU_WINDOW)
    outputs = []
    for align_from in (1 << 62, 1):
        monkeypatch.setattr(mcap_layout, 'ALIGN_FROM', align_from)
        for limit in (1, 1 << 40):
            monkeypatch.setattr(mcap_writer, 'SPAN_LIMIT', limit)
            out = tmp_path / f'span-{limit}-{align_from}.mcap'
            result = api.run(loaded, [bags['sensor-heavy']], out, seed=4)
            assert 0 < result.stats.chunks_copied < result.stats.chunks
            outputs.append(out.read_bytes())
    assert outputs[0] == outputs[1]
    assert outputs[2] == outputs[3]
    assert outputs[2] != outputs[0]  # the spans moved
    api.run(loaded, [bags['sensor-heavy']], tmp_path / 'reference.mcap', seed=4, chunk_copy=False)
    for name in ('span-1-1.mcap', f'span-1-{1 << 62}.mcap'):
        assert streams(tmp_path / name) == streams(tmp_path / 'reference.mcap')


def test_chunk_index_records_are_packed_as_the_library_packs_them() -> None:
    from mcap.data_stream import RecordBuilder
    from mcap.records import ChunkIndex

    from bagfault.io.mcap_writer import chunk_index_record

    for offsets, compression in (({}, ''), ({1: 4242, 7: 2**40 + 3}, 'zstd'), ({65535: 2**64 - 1}, 'lz4')):
        values = {'message_start_time': 2**63 + 5, 'message_end_time': 2**64 - 1, 'chunk_start_offset': 77,
                  'chunk_length': 123456, 'message_index_offsets': offsets,
                  'message_index_length': len(offsets) * 31, 'compression': compression, 'compressed_size': 999,
                  'uncompressed_size': 2**33}
        builder = RecordBuilder()
        ChunkIndex(**values).write(builder)
        assert chunk_index_record(*values.values()) == builder.end()


def test_a_copy_that_cannot_be_written_leaves_nothing(bags: dict[str, Path], tmp_path: Path) -> None:
    """The copy thread meets a file size limit (as a full disk would stop it): exit 2, one line naming the
    output, no output and no temporary file left."""
    import resource
    import signal
    import subprocess
    import sys

    bag = bags['sensor-heavy']
    scenario_file = tmp_path / 's.yaml'
    scenario_file.write_text(scenario('sensor-heavy', 'a'))
    out = tmp_path / 'out' / 'run.mcap'
    out.parent.mkdir()
    limit = bag.stat().st_size // 2

    def limited() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # the write fails with EFBIG instead of killing
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    done = subprocess.run([sys.executable, '-m', 'bagfault.cli', 'run', str(scenario_file), str(bag), '-o', str(out)],
                          capture_output=True, text=True, preexec_fn=limited, check=False, timeout=120)
    assert done.returncode == 2, done.stderr
    assert done.stderr.strip().splitlines() == [f'bagfault: error: {out}: cannot write: File too large']
    assert list(out.parent.iterdir()) == []


@pytest.mark.parametrize('text', [IMU_WINDOW.replace('start: 1.0', 'start: 100.0'), IMU_WINDOW])
def test_long_copied_runs_sit_64_kib_from_their_input_place_after_a_record_every_reader_skips(
        bags: dict[str, Path], tmp_path: Path, text: str) -> None:
    """A kernel copy that moves bytes by a multiple of 64 KiB runs at `cp`'s speed (docs/notes/performance.md):
    every run of copied chunks of 1 MiB or more lands so, after a record of zeros of an application opcode;
    the mcap library (indexed and reading through), rosbags, rosbags-convert, Foxglove's MCAP library (both
    ways) and bagfault itself read every message as the input holds it."""
    bag = bags['sensor-heavy']
    out = tmp_path / 'out.mcap'
    api.run(parse_scenario(text), [bag], out, seed=4)
    data, written = bag.read_bytes(), out.read_bytes()
    inputs = {(c.message_start_time, c.compressed_size): c for c in chunk_indexes(bag)}
    runs: list[list[int]] = []  # [input offset, output offset, length] of chunks copied one after another
    for chunk in chunk_indexes(out):
        source = inputs.get((chunk.message_start_time, chunk.compressed_size))
        size = chunk.chunk_length + chunk.message_index_length
        if source is None or data[source.chunk_start_offset:][:size] != written[chunk.chunk_start_offset:][:size]:
            continue
        last = runs[-1] if runs else None
        if last and last[0] + last[2] == source.chunk_start_offset and last[1] + last[2] == chunk.chunk_start_offset:
            last[2] += size
        else:
            runs.append([source.chunk_start_offset, chunk.chunk_start_offset, size])
    long_runs = [r for r in runs if r[2] >= 1 << 20]
    assert long_runs and len(long_runs) == (1 if 'start: 100' in text else 2)
    assert all((target - source) % 65536 == 0 for source, target, _ in long_runs)
    records = mcap_records(written)
    unknown = [(position, 9 + length) for position, opcode, length in records if opcode not in range(0x01, 0x10)]
    assert {opcode for _, opcode, _ in records} - set(range(0x01, 0x10)) == {0xA1}
    assert {position + length for position, length in unknown} <= {target for _, target, _ in long_runs}
    assert all(written[position + 9:position + length] == bytes(length - 9) for position, length in unknown)
    expected = streams(bag)
    if 'start: 100' in text:
        assert streams(out) == expected
    linear: dict[str, int] = {}
    with out.open('rb') as stream:
        channels = {}
        for record in StreamReader(stream, skip_magic=False).records:
            if isinstance(record, Channel):
                channels[record.id] = record.topic
            if isinstance(record, Message):
                linear[channels[record.channel_id]] = linear.get(channels[record.channel_id], 0) + 1
    assert linear == {topic: len(found) for topic, found in streams(out).items()}
    assert {t: n for t, n in linear.items() if not t.startswith('/fault_injection')} == \
        {topic: len(found) for topic, found in expected.items()}
    assert rosbags_count(out) == sum(linear.values())
    assert converted(out, tmp_path) == linear
    foxglove = foxglove_reads(out)
    assert foxglove['indexed'] == foxglove['stream']['counts'] == linear
    assert foxglove['stream']['done'] and foxglove['stream']['unknown'] == [0xA1] * len(unknown)
    again = tmp_path / 'again.mcap'  # bagfault reads its own output (its records walked, the padding skipped)
    result = api.run(parse_scenario(IMU_WINDOW.replace('start: 1.0', 'start: 100.0')), [out], again, seed=4)
    assert result.stats.chunks_copied > 0
    assert streams(again) == streams(out)


@pytest.fixture(scope='module')
def rosbags_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A rosbag2 MCAP bag written by rosbags (its own chunking: 1 MiB uncompressed chunks, message indexes)."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    types = store.types
    folder = tmp_path_factory.mktemp('rosbags') / 'bag'
    with Writer(folder, version=8, storage_plugin=StoragePlugin.MCAP) as writer:
        imu = writer.add_connection('/imu', 'sensor_msgs/msg/Imu', typestore=store)
        camera = writer.add_connection('/camera', 'sensor_msgs/msg/Image', typestore=store)
        for i in range(2000):
            t = 10**9 + i * 5_000_000
            header = types['std_msgs/msg/Header'](stamp=types['builtin_interfaces/msg/Time'](sec=t // 10**9,
                                                                                              nanosec=t % 10**9),
                                                  frame_id='imu')
            vector = types['geometry_msgs/msg/Vector3']
            message = types['sensor_msgs/msg/Imu'](
                header=header, orientation=types['geometry_msgs/msg/Quaternion'](x=0.0, y=0.0, z=0.0, w=1.0),
                orientation_covariance=np.zeros(9), angular_velocity=vector(x=0.0, y=0.0, z=0.01 * i),
                angular_velocity_covariance=np.zeros(9), linear_acceleration=vector(x=0.0, y=0.0, z=9.8),
                linear_acceleration_covariance=np.zeros(9))
            writer.write(imu, t, store.serialize_cdr(message, 'sensor_msgs/msg/Imu'))
            if i % 20 == 0:
                pixels = np.random.default_rng(i).integers(0, 255, 160 * 120, dtype=np.uint8)
                image = types['sensor_msgs/msg/Image'](header=header, height=120, width=160, encoding='mono8',
                                                        is_bigendian=0, step=160, data=pixels)
                writer.write(camera, t, store.serialize_cdr(image, 'sensor_msgs/msg/Image'))
    return folder / 'bag.mcap'


def test_a_bag_rosbags_wrote_comes_out_aligned_and_every_reader_reads_it(rosbags_bag: Path, tmp_path: Path) -> None:
    """rosbags' own chunking (1 MiB chunks, not bagfault's): with no fault due, every chunk is copied, each a
    multiple of 64 KiB from its input place after one padding record; rosbags, the mcap library and
    Foxglove's read the 2000 IMU and 100 image messages rosbags wrote."""
    out = tmp_path / 'out.mcap'
    result = api.run(parse_scenario(IMU_WINDOW.replace('start: 1.0', 'start: 100.0')), [rosbags_bag], out, seed=4)
    found = chunk_indexes(rosbags_bag)
    assert len(found) >= 3 and result.stats.chunks_copied == len(found)
    data, written = rosbags_bag.read_bytes(), out.read_bytes()
    for source, target in zip(found, chunk_indexes(out), strict=True):
        size = source.chunk_length + source.message_index_length
        assert data[source.chunk_start_offset:][:size] == written[target.chunk_start_offset:][:size]
        assert (target.chunk_start_offset - source.chunk_start_offset) % 65536 == 0
    assert [op for _, op, _ in mcap_records(written) if op >= 0x80] == [0xA1]
    expected = {'/imu': 2000, '/camera': 100}
    assert dict(rosbags_counts(out)) == expected
    assert {topic: len(found) for topic, found in streams(out).items()} == expected
    foxglove = foxglove_reads(out)
    assert foxglove['indexed'] == foxglove['stream']['counts'] == expected


def test_an_mcap_from_the_plain_writer_gets_its_chunks_copied_and_its_channels_kept(tmp_path: Path) -> None:
    """Channels without rosbag2's QoS (the plain mcap writer's, as Foxglove and converters write them): every
    untouched chunk copied (none was: the missing QoS sent the whole bag down the slow path, 7x cp), each such
    channel kept as the input has it, the stream the reference path writes, and every reader opens it."""
    from rosbags.typesys import Stores, get_typestore
    from rosbags.typesys.stores.ros2_jazzy import std_msgs__msg__String as String
    from support.toolchain import assert_toolchain_opens

    bag = tmp_path / 'plain.mcap'
    store = get_typestore(Stores.ROS2_JAZZY)
    with bag.open('wb') as stream:
        writer = Writer(stream, chunk_size=4096)
        writer.start(profile='ros2', library='plain')
        schema = writer.register_schema('std_msgs/msg/String', 'ros2msg', b'string data\n')
        channels = {topic: writer.register_channel(topic, 'cdr', schema) for topic in ('/a', '/b')}
        for k in range(600):
            topic = '/a' if k % 2 else '/b'
            data = store.serialize_cdr(String(data=f'{topic} {k}'), 'std_msgs/msg/String')
            writer.add_message(channels[topic], 1_700_000_000 * 10**9 + k * 10**7, bytes(data),
                               1_700_000_000 * 10**9 + k * 10**7)
        writer.finish()
    text = """
injectors:
  - {id: b, type: topic, input_topic: /b, output_topic: /b}
faults:
  - {id: gap, injector_id: b, start: 2.5, duration: 0.5, config: {drop_probability: 1.0}}
"""
    fast, _ = both(bag, text, tmp_path)
    chunks = len(chunk_records(bag))
    assert 0 < fast.stats.chunks_copied < fast.stats.chunks == chunks
    (tmp_path / 'none').mkdir()
    none, _ = both(bag, 'injectors: []\n', tmp_path / 'none')
    assert none.stats.chunks_copied == none.stats.chunks == chunks
    with (tmp_path / 'none' / 'copy.mcap').open('rb') as stream:
        summary = make_reader(stream).get_summary()
    assert {c.topic: dict(c.metadata) for c in summary.channels.values() if c.topic in ('/a', '/b')} == \
        {'/a': {}, '/b': {}}  # as the input has them
    (tmp_path / 'readers').mkdir()
    assert_toolchain_opens(tmp_path / 'none' / 'copy.mcap', tmp_path / 'readers')
