"""Outputs the ROS toolchain opens: rosbag2's record layout and QoS rules (tests/rosbag2_rules.py, written from
rosbag2's C++), rosbags' AnyReader and `rosbags-convert` as independent readers."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
import yaml
from mcap.reader import make_reader
from mcap.writer import Writer
from rosbags.typesys import Stores, get_typestore
from support.helpers import EXTERNAL, FIXTURES, need
from support.rosbag2_rules import Rosbag2Error, check_mcap, decode_bag_metadata, decode_qos
from support.toolchain import assert_toolchain_opens

from bagfault import api
from bagfault.cli import main
from bagfault.scenario import parse_scenario

ROVER = FIXTURES / 'rover_20s.mcap'
ROSBAG2_MCAPS = EXTERNAL / 'rosbag2'
BIAS = parse_scenario(
    'injector: {id: imu, type: imu, input_topic: /imu, output_topic: /imu}\n'
    'faults: [{id: bias, injector_id: imu, active_on_startup: true, config: {gyro_bias_z: 0.1}}]\n')
# What bagfault 0.1 wrote, and what live recordings wrote: each made a rosbag2 reader throw.
NESTED = yaml.safe_dump({'rosbag2_bagfile_information': {'version': 9, 'storage_identifier': 'mcap'}})
NAMES = '- history: keep_last\n  depth: 10\n  reliability: reliable\n  durability: volatile\n' \
        '  deadline: {sec: 9223372036, nsec: 854775807}\n  lifespan: {sec: 9223372036, nsec: 854775807}\n' \
        '  liveliness: automatic\n  liveliness_lease_duration: {sec: 9223372036, nsec: 854775807}\n' \
        '  avoid_ros_namespace_conventions: false\n'
FOUR_KEYS = '- history: keep_last\n  depth: 10\n  reliability: reliable\n  durability: volatile\n'


def test_the_decoder_reads_rosbag2s_own_recordings_and_refuses_what_broke_it() -> None:
    real = sorted(need(ROSBAG2_MCAPS).rglob('*.mcap'))
    opened = 0
    for path in real:  # rosbag2's own files pass the rules the outputs are held to
        with path.open('rb') as stream:
            reader = make_reader(stream)
            channels = reader.get_summary().channels.values()
            has_record = any(m.name == 'rosbag2' for m in reader.iter_metadata())
        for channel in channels:
            if channel.message_encoding == 'cdr':
                for distro in ('humble', 'iron', 'jazzy'):
                    decode_qos(channel.metadata.get('offered_qos_profiles', ''), distro)
        if has_record:
            assert check_mcap(path)['version'] == 8
            opened += 1
    assert opened == 4 and len(real) > 15
    with pytest.raises(Rosbag2Error, match='first invalid key: "version"'):
        decode_bag_metadata(NESTED)
    with pytest.raises(Rosbag2Error, match='not an integer'):
        decode_qos(NAMES, 'humble')
    assert decode_qos(NAMES, 'jazzy')[0]['reliability'] == 'reliable'
    with pytest.raises(Rosbag2Error, match=r'"deadline"|"liveliness"'):
        decode_qos(FOUR_KEYS, 'jazzy')


def test_run_output_opens_in_the_ros_toolchain_with_the_inputs_distro(tmp_path: Path) -> None:
    out = tmp_path / 'out.mcap'
    api.run(BIAS, [ROVER], out, seed=1)
    with ROVER.open('rb') as stream:
        first = make_reader(stream).get_summary().statistics.message_start_time
    info = assert_toolchain_opens(out, tmp_path, distro='')  # the fixture names no distro: none is guessed
    assert info['starting_time'] == first
    with out.open('rb') as stream:
        [attachment] = make_reader(stream).iter_attachments()
    assert attachment.log_time == first  # the scenario at the run's start, on bag time


def test_an_input_that_names_no_distro_gives_none_and_info_reads_rosbag2s_record(tmp_path: Path,
                                                                                capsys: pytest.CaptureFixture) -> None:
    bag = tmp_path / 'plain.mcap'
    with bag.open('wb') as stream:  # an MCAP from a recorder that is not rosbag2: no record, no QoS
        writer = Writer(stream)
        writer.start('ros2', 'test')
        schema = writer.register_schema('std_msgs/msg/Int32', 'ros2msg', b'int32 data')
        channel = writer.register_channel('/n', 'cdr', schema)
        for k in range(3):
            writer.add_message(channel, 1_000 + k, b'\x00\x01\x00\x00' + k.to_bytes(4, 'little'), 1_000 + k)
        writer.finish()
    out = tmp_path / 'out.mcap'
    api.run(parse_scenario('injectors: []\n'), [bag], out)
    info = assert_toolchain_opens(out, tmp_path, distro='')
    # its channel kept as it is (copied chunks): no QoS, so ros2 bag play uses its defaults, as for the input
    assert [topic['offered_qos_profiles'] for topic, _ in info['topics']] == [[]]
    assert main(['info', str(out)]) == 0
    assert 'distro:    unknown' in capsys.readouterr().out
    real = need(ROSBAG2_MCAPS / 'rosbag2_cpp' / 'test' / 'rosbag2_cpp' / 'bags' / 'only_topics.mcap')
    assert main(['info', str(real)]) == 0
    assert 'distro:    rolling' in capsys.readouterr().out  # its record: serialized_metadata, ros_distro: rolling


def test_type_hashes_and_distro_of_a_real_rosbag2_mcap_are_kept(tmp_path: Path) -> None:
    source = need(ROSBAG2_MCAPS / 'rosbag2_cpp' / 'test' / 'rosbag2_cpp' / 'bags' / 'only_topics.mcap')
    with source.open('rb') as stream:
        summary = make_reader(stream).get_summary()
    hashes = {c.topic: c.metadata['topic_type_hash'] for c in summary.channels.values()}
    for chunk_copy in (True, False):
        out = tmp_path / f'out_{chunk_copy}.mcap'
        api.run(parse_scenario('injectors: []\n'), [source], out, chunk_copy=chunk_copy)
        info = check_mcap(out)
        assert info['ros_distro'] == 'rolling'
        kept = {topic['name']: topic['type_description_hash'] for topic, _ in info['topics']}
        assert {t: kept[t] for t in hashes} == hashes
        assert all(h.startswith('RIHS01_') for h in hashes.values())


def test_a_sqlite3_bag_of_version_9_gives_its_qos_and_hashes(tmp_path: Path) -> None:
    """rosbags writes version 9 (QoS as a sequence of names, type hashes): the output has both, as numbers."""
    from rosbags.rosbag2 import StoragePlugin
    from rosbags.rosbag2 import Writer as Rosbag2Writer
    from rosbags.rosbag2.metadata import parse_qos

    store = get_typestore(Stores.ROS2_JAZZY)
    bag = tmp_path / 'v9'
    best_effort = parse_qos('- history: 1\n  depth: 5\n  reliability: 2\n  durability: 2\n'
                            '  deadline: {sec: 0, nsec: 0}\n  lifespan: {sec: 0, nsec: 0}\n  liveliness: 1\n'
                            '  liveliness_lease_duration: {sec: 0, nsec: 0}\n'
                            '  avoid_ros_namespace_conventions: false\n')
    with Rosbag2Writer(bag, version=9, storage_plugin=StoragePlugin.SQLITE3) as writer:
        connection = writer.add_connection('/n', 'std_msgs/msg/Int32', typestore=store,
                                           offered_qos_profiles=best_effort)
        Int32 = store.types['std_msgs/msg/Int32']
        for k in range(4):
            writer.write(connection, 1_000 + k, store.serialize_cdr(Int32(k), 'std_msgs/msg/Int32'))
    out = tmp_path / 'out.mcap'
    api.run(parse_scenario('injectors: []\n'), [bag], out)
    info = check_mcap(out)
    [(topic, count)] = [(t, n) for t, n in info['topics'] if t['name'] == '/n']
    assert count == 4 and topic['offered_qos_profiles'][0]['reliability'] == 2  # best effort, as recorded
    assert topic['offered_qos_profiles'][0]['depth'] == 5
    declared = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    [expected] = [t['topic_metadata']['type_description_hash'] for t in declared['topics_with_message_count']]
    assert topic['type_description_hash'] == expected != ''


def test_a_version_9_qos_sequence_in_metadata_fills_a_storage_without_qos(tmp_path: Path) -> None:
    """Where the storage file keeps no QoS (its topics row empty), metadata.yaml's version 9 sequence is the
    offered QoS: best effort, depth 5 here, as written. (This path once named a function it never imported.)"""
    import sqlite3

    from rosbags.rosbag2 import StoragePlugin
    from rosbags.rosbag2 import Writer as Rosbag2Writer
    from rosbags.rosbag2.metadata import parse_qos

    store = get_typestore(Stores.ROS2_JAZZY)
    bag = tmp_path / 'v9'
    best_effort = parse_qos('- history: 1\n  depth: 5\n  reliability: 2\n  durability: 2\n'
                            '  deadline: {sec: 0, nsec: 0}\n  lifespan: {sec: 0, nsec: 0}\n  liveliness: 1\n'
                            '  liveliness_lease_duration: {sec: 0, nsec: 0}\n'
                            '  avoid_ros_namespace_conventions: false\n')
    with Rosbag2Writer(bag, version=9, storage_plugin=StoragePlugin.SQLITE3) as writer:
        connection = writer.add_connection('/n', 'std_msgs/msg/Int32', typestore=store,
                                           offered_qos_profiles=best_effort)
        Int32 = store.types['std_msgs/msg/Int32']
        for k in range(4):
            writer.write(connection, 1_000 + k, store.serialize_cdr(Int32(k), 'std_msgs/msg/Int32'))
    [database] = bag.glob('*.db3')
    with sqlite3.connect(database) as connection:
        connection.execute("UPDATE topics SET offered_qos_profiles = ''")
    declared = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    [qos] = [t['topic_metadata']['offered_qos_profiles'] for t in declared['topics_with_message_count']]
    assert isinstance(qos, list) and qos[0]['reliability'] == 'best_effort'  # the version 9 form, names
    out = tmp_path / 'out.mcap'
    api.run(parse_scenario('injectors: []\n'), [bag], out)
    [(topic, count)] = [(t, n) for t, n in check_mcap(out)['topics'] if t['name'] == '/n']
    assert count == 4 and topic['offered_qos_profiles'][0]['reliability'] == 2
    assert topic['offered_qos_profiles'][0]['depth'] == 5


@pytest.mark.parametrize('name', ['OneMessage-ch-chx-mx-rch-rsh-st-sum.mcap'])
def test_a_non_ros_mcap_gets_default_qos_every_distro_reads(tmp_path: Path, name: str) -> None:
    source = need(EXTERNAL / 'mcap' / 'tests' / 'conformance' / 'data' / 'OneMessage' / name)
    out = tmp_path / 'out.mcap'
    shutil.copy(source, tmp_path / name)
    api.run(parse_scenario('injectors: []\n'), [tmp_path / name], out)
    check_mcap(out)
