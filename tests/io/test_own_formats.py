"""Every input layout bagfault reads, written here by other libraries (rosbags, mcap) and read back.

The expected messages come from the writer's side: rosbags' and the mcap
library's own readers, never bagfault. Third-party recordings add coverage in
test_sources.py; these cases stand on their own.
"""

from __future__ import annotations

import shutil
from collections import Counter
from pathlib import Path

import pytest
import yaml
from mcap.writer import CompressionType, IndexType, Writer
from rosbags.highlevel import AnyReader
from rosbags.rosbag1 import Writer as Ros1Writer
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Rosbag2Writer
from rosbags.rosbag2.enums import CompressionFormat, CompressionMode
from support.helpers import raw_messages
from support.ros1 import ROS1, _to_ros1

from bagfault import api
from bagfault.demo import synthetic
from bagfault.io.sources import InputSet, open_source

STREAMS = (synthetic.Stream('/imu', 'sensor_msgs/msg/Imu', 50.0),
           synthetic.Stream('/odom', 'nav_msgs/msg/Odometry', 20.0),
           synthetic.Stream('/scan', 'sensor_msgs/msg/LaserScan', 5.0))
ROS2 = synthetic.store()


def read(path: Path) -> list[tuple[str, int, bytes]]:
    """(topic, log_time, data) of every message as bagfault reads it."""
    source = open_source(path)
    try:
        return [(source.channels[i].topic, t, bytes(d)) for i, t, _, d in source.messages()]
    finally:
        source.close()


def rosbags_view(path: Path) -> list[tuple[str, int, bytes]]:
    """The same as rosbags' AnyReader sees it."""
    with AnyReader([path], default_typestore=ROS2) as reader:
        return [(c.topic, t, bytes(d)) for c, t, d in reader.messages()]


def rosbag2(path: Path, *, version: int = 9, plugin: StoragePlugin = StoragePlugin.SQLITE3,
            compression: CompressionMode | None = None, duration: float = 2.0, start_offset: float = 0.0) -> Path:
    writer = Rosbag2Writer(path, version=version, storage_plugin=plugin)  # type: ignore[arg-type]
    if compression is not None:
        writer.set_compression(compression, CompressionFormat.ZSTD)
    with writer:
        connections = {}
        start = synthetic.DEFAULT_START + round(start_offset * 1e9)
        for stream, time, message in synthetic.messages(STREAMS, duration, start=start, ts=ROS2):
            if stream.topic not in connections:
                connections[stream.topic] = writer.add_connection(stream.topic, stream.msgtype, typestore=ROS2)
            writer.write(connections[stream.topic], time, ROS2.serialize_cdr(message, stream.msgtype))
    return path


LAYOUTS = [(plugin, compression) for plugin in (StoragePlugin.SQLITE3, StoragePlugin.MCAP)
           for compression in (None, CompressionMode.FILE, CompressionMode.MESSAGE)
           if not (plugin is StoragePlugin.MCAP and compression is CompressionMode.MESSAGE)]  # rosbag2 has no such bag


@pytest.mark.parametrize('version', [8, 9])
@pytest.mark.parametrize(('plugin', 'compression'), LAYOUTS,
                         ids=[f'{p.name.lower()}-{c.name.lower() if c else "plain"}' for p, c in LAYOUTS])
def test_rosbag2_directories_read_like_rosbags_reads_them(tmp_path, version, plugin, compression):
    bag = rosbag2(tmp_path / 'bag', version=version, plugin=plugin, compression=compression)
    expected = rosbags_view(bag)
    assert len(expected) == 2 * (50 + 20 + 5)
    assert read(bag) == expected
    info = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    source = open_source(bag)
    try:
        assert source.message_count == info['message_count'] == len(expected)
    finally:
        source.close()
    assert not list(tmp_path.glob('**/*.partial'))


def test_bare_storage_file_and_directory_without_metadata(tmp_path):
    bag = rosbag2(tmp_path / 'bag')
    expected = read(bag)
    [storage] = bag.glob('*.db3')
    assert read(storage) == expected  # a bare .db3
    (bag / 'metadata.yaml').unlink()
    assert read(bag) == expected  # a folder of storage files


def test_split_bag_listed_in_metadata_reads_as_one_in_time_order(tmp_path):
    first = rosbag2(tmp_path / 'first', duration=1.0)
    second = rosbag2(tmp_path / 'second', duration=1.0, start_offset=1.0)
    split = tmp_path / 'split'
    split.mkdir()
    shutil.copy(next(first.glob('*.db3')), split / 'split_0.db3')
    shutil.copy(next(second.glob('*.db3')), split / 'split_1.db3')
    meta = yaml.safe_load((first / 'metadata.yaml').read_text())
    info = meta['rosbag2_bagfile_information']
    info['relative_file_paths'] = ['split_0.db3', 'split_1.db3']
    info['message_count'] *= 2
    for topic in info['topics_with_message_count']:
        topic['message_count'] *= 2
    (split / 'metadata.yaml').write_text(yaml.safe_dump(meta))
    messages = read(split)
    assert messages == read(first) + read(second)
    times = [t for _, t, _ in messages]
    assert times == sorted(times)


@pytest.mark.parametrize('compression', [None, 'bz2', 'lz4'])
def test_ros1_bag_is_converted_to_ros2_cdr(tmp_path, compression):
    path = tmp_path / 'robot.bag'
    writer = Ros1Writer(path)
    if compression is not None:
        writer.set_compression(Ros1Writer.CompressionFormat[compression.upper()])
    writer.open()
    connections = {}
    written = []
    for stream, time, message in synthetic.messages(STREAMS[:2], 2.0, ts=ROS2):
        if stream.topic not in connections:
            connections[stream.topic] = writer.add_connection(stream.topic, stream.msgtype, typestore=ROS1)
        writer.write(connections[stream.topic], time, ROS1.serialize_ros1(_to_ros1(message, stream.msgtype),
                                                                          stream.msgtype))
        written.append((stream.topic, time, message.header.stamp.sec, message.header.frame_id))
    writer.close()
    source = open_source(path)
    try:
        got = []
        for index, time, _, data in source.messages():
            channel = source.channels[index]
            message = ROS2.deserialize_cdr(bytes(data), channel.msgtype)
            got.append((channel.topic, time, message.header.stamp.sec, message.header.frame_id))
        assert {c.msgtype for c in source.channels} == {'sensor_msgs/msg/Imu', 'nav_msgs/msg/Odometry'}
    finally:
        source.close()
    assert got == written


@pytest.mark.parametrize('layout', ['chunked-zstd', 'chunked-lz4', 'chunked-none', 'unchunked', 'no-index'])
def test_mcap_layouts_read_like_the_mcap_library_reads_them(tmp_path, layout):
    path = tmp_path / f'{layout}.mcap'
    options: dict[str, object] = {
        'chunked-zstd': {'compression': CompressionType.ZSTD},
        'chunked-lz4': {'compression': CompressionType.LZ4},
        'chunked-none': {'compression': CompressionType.NONE},
        'unchunked': {'use_chunking': False},
        'no-index': {'index_types': IndexType.NONE, 'use_summary_offsets': False, 'repeat_channels': False,
                     'repeat_schemas': False, 'use_statistics': False, 'compression': CompressionType.LZ4},
    }[layout]
    with path.open('wb') as stream:
        writer = Writer(stream, chunk_size=4096, **options)  # type: ignore[arg-type]
        writer.start('ros2', 'test')
        channels = {}
        for item in synthetic.messages(STREAMS, 2.0, ts=ROS2):
            stream_spec, time, message = item
            if stream_spec.topic not in channels:
                text, _ = ROS2.generate_msgdef(stream_spec.msgtype, ros_version=2)
                schema = writer.register_schema(stream_spec.msgtype, 'ros2msg', text.encode())
                channels[stream_spec.topic] = writer.register_channel(stream_spec.topic, 'cdr', schema)
            data = bytes(ROS2.serialize_cdr(message, stream_spec.msgtype))
            writer.add_message(channels[stream_spec.topic], time, data, time)
        writer.finish()
    expected = [(topic, t, d) for topic, rows in raw_messages(path).items() for t, _, d in rows]
    got = read(path)
    assert Counter(topic for topic, _, _ in got) == Counter({'/imu': 100, '/odom': 40, '/scan': 10})
    assert sorted(got) == sorted(expected)
    assert [t for _, t, _ in got] == sorted(t for _, t, _ in got)


def test_several_inputs_of_different_formats_merge_in_time_order(tmp_path):
    sqlite = rosbag2(tmp_path / 'a', duration=1.0)
    mcap = rosbag2(tmp_path / 'b', duration=1.0, start_offset=0.5, plugin=StoragePlugin.MCAP)
    inputs = InputSet([sqlite, mcap])
    try:
        merged = [(inputs.channels[i].topic, t) for i, t, _, _ in inputs.messages()]
        assert sorted(c.topic for c in inputs.channels) == ['/imu', '/odom', '/scan']
    finally:
        inputs.close()
    expected = sorted([(topic, t) for topic, t, _ in read(sqlite)] + [(topic, t) for topic, t, _ in read(mcap)],
                      key=lambda x: x[1])
    assert [t for _, t in merged] == [t for _, t in expected]
    assert Counter(merged) == Counter(expected)


def test_run_on_every_own_format_copies_untouched_topics_byte_for_byte(tmp_path):
    scenario = tmp_path / 'scenario.yaml'
    scenario.write_text('injector: {id: imu, type: imu, input_topic: /imu, output_topic: /imu_out}\n'
                        'faults: [{id: bias, injector_id: imu, start: 0.5, config: {angular_velocity_z_bias: 1.0}}]\n')
    for name, bag in (('sqlite', rosbag2(tmp_path / 'sqlite')),
                      ('mcap', rosbag2(tmp_path / 'mcap', plugin=StoragePlugin.MCAP)),
                      ('zstd', rosbag2(tmp_path / 'zstd', compression=CompressionMode.FILE))):
        out = tmp_path / f'{name}.mcap'
        result = api.run(scenario, [bag], out)
        assert result.stats.input_messages == 150
        written = raw_messages(out)
        original = rosbags_view(bag)
        for topic in ('/odom', '/scan', '/imu'):
            assert [d for _, _, d in written[topic]] == [d for t, _, d in original if t == topic], (name, topic)
        assert len(written['/imu_out']) == 100
