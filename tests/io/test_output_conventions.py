"""The output MCAP follows rosbag2's conventions and is readable, checked and decodable by other tools."""

from __future__ import annotations

import errno
import struct
from pathlib import Path

import pytest
import yaml
from mcap.reader import make_reader
from mcap.writer import Writer
from rosbags.highlevel import AnyReader
from support.helpers import FIXTURES, counts, make_bag, run_inline
from support.readers import verify

from bagfault import api
from bagfault.cli import main
from bagfault.errors import OutputError
from bagfault.scenario import parse_scenario

PASS = parse_scenario('injectors: []\n')


def test_rover_output_passes_every_readers_checks_and_follows_rosbag2(tmp_path, scenarios):
    out = tmp_path / 'out.mcap'
    api.run(scenarios / 'rover_multi.yaml', [FIXTURES / 'rover_20s.mcap'], out, seed=3)
    found = counts(out)
    assert verify(out) == sum(found.values())
    with out.open('rb') as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        assert summary is not None
        with (FIXTURES / 'rover_20s.mcap').open('rb') as source:
            given = {c.topic: dict(c.metadata) for c in make_reader(source).get_summary().channels.values()}
        for channel in summary.channels.values():  # every channel bagfault makes says its QoS, events too
            if channel.topic in given and dict(channel.metadata) == given[channel.topic]:
                continue  # an input's channel kept as it is for chunk copy (the fixture's say no QoS)
            profiles = yaml.safe_load(channel.metadata['offered_qos_profiles'])
            assert profiles[0]['reliability'] in (1, 2)  # rmw's numbers, which every distro reads
        [record] = [m for m in reader.iter_metadata() if m.name == 'rosbag2']
    info = yaml.safe_load(record.metadata['serialized_metadata'])  # its keys at the top level, as rosbag2's
    assert info['ros_distro'] == ''  # the fixture names no distro, and none is guessed
    assert info['version'] == 8 and info['storage_identifier'] == 'mcap'
    assert info['message_count'] == sum(found.values())
    assert {t['topic_metadata']['name']: t['message_count'] for t in info['topics_with_message_count']} == dict(found)


def custom_type_bag(path: Path) -> Path:
    """An MCAP with a custom type whose schema is empty (a recorder that had no definition)."""
    with path.open('wb') as stream:
        writer = Writer(stream)
        writer.start('ros2', 'test')
        schema = writer.register_schema('rover_msgs/msg/Wheel', '', b'')
        channel = writer.register_channel('/wheel', 'cdr', schema)
        for k in range(5):  # CDR: header, float64 speed, int32 ticks
            writer.add_message(channel, 1_000_000_000 + k, b'\x00\x01\x00\x00' + struct.pack('<di', k * 0.5, k), 0)
        writer.finish()
    return path


def test_a_type_nobody_knows_keeps_rosbag2s_empty_schema(tmp_path):
    out = tmp_path / 'out.mcap'
    api.run(PASS, [custom_type_bag(tmp_path / 'in.mcap')], out)
    with out.open('rb') as stream:
        summary = make_reader(stream).get_summary()
    [schema] = [s for s in summary.schemas.values() if s.name == 'rover_msgs/msg/Wheel']
    assert (schema.encoding, schema.data) == ('', b'')
    assert counts(out)['/wheel'] == 5


def test_msg_path_gives_the_real_definition(tmp_path):
    package = tmp_path / 'defs' / 'rover_msgs' / 'msg'
    package.mkdir(parents=True)
    (package / 'Wheel.msg').write_text('float64 speed\nint32 ticks\n')
    out = tmp_path / 'out.mcap'
    assert main(['run', str(_scenario(tmp_path)), str(custom_type_bag(tmp_path / 'in.mcap')), '-o', str(out),
                 '--msg-path', str(tmp_path / 'defs')]) == 0
    assert verify(out) == 11  # /wheel, /wheel_out and the fault event: every reader decodes them now
    with AnyReader([out]) as reader:
        values = [(m.speed, m.ticks) for c, _, raw in reader.messages()
                  for m in [reader.deserialize(raw, c.msgtype)] if c.topic == '/wheel_out']
    assert values == [(0.0, 0), (1.0, 1), (2.0, 2), (3.0, 3), (4.0, 4)]  # speed k * 0.5, doubled by the fault


def _scenario(tmp_path: Path) -> Path:
    path = tmp_path / 'wheel.yaml'
    path.write_text('msg_paths: []\n'
                    'injector: {id: w, type: field, input_topic: /wheel, output_topic: /wheel_out}\n'
                    'faults: [{id: f, injector_id: w, active_on_startup: true, config: {operations: '
                    '[{op: scale, path: speed, value: 2.0}, {op: add, path: ticks, value: 0}]}}]\n')
    return path


def test_msg_paths_in_the_scenario_are_relative_to_it(tmp_path):
    package = tmp_path / 'defs' / 'rover_msgs' / 'msg'
    package.mkdir(parents=True)
    (package / 'Wheel.msg').write_text('float64 speed\nint32 ticks\n')
    scenario = _scenario(tmp_path)
    scenario.write_text(scenario.read_text().replace('msg_paths: []', 'msg_paths: [defs]'))
    out = tmp_path / 'out.mcap'
    api.run(scenario, [custom_type_bag(tmp_path / 'in.mcap')], out)
    assert verify(out) == 11


def test_a_full_disk_is_a_clean_error_and_leaves_nothing(tmp_path, monkeypatch):
    bag = make_bag(tmp_path / 'in.mcap', [('/imu', 'sensor_msgs/msg/Imu', 200.0)], 30.0)
    from bagfault.io import mcap_writer

    written = {'bytes': 0}

    def filling(real):  # the chunks bagfault writes, and those it copies (its channels are kept: copied)
        def write(*args, **kwargs):
            written['bytes'] += 1
            if written['bytes'] > 1:
                raise OSError(errno.ENOSPC, 'No space left on device')
            return real(*args, **kwargs)
        return write

    from bagfault.io import leading_copy

    monkeypatch.setattr(mcap_writer.McapWriter, '_write_chunk', filling(mcap_writer.McapWriter._write_chunk))
    def full(*_args, **_kwargs):
        raise OSError(errno.ENOSPC, 'No space left on device')

    for module in (mcap_writer, leading_copy):  # a single copy may take the whole bag: none gets through
        monkeypatch.setattr(module, 'copy_range', full)
    with pytest.raises(OutputError, match=r'out\.mcap: cannot write: No space left on device'):
        run_inline(tmp_path, 'injectors: []\n', bag)
    assert sorted(p.name for p in tmp_path.iterdir()) == ['in.mcap']
