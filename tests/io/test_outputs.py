"""No output lands on anything a command reads, by file identity; existing files bagfault did not write need --force.

Each case runs the real command line on a small bag and checks the exit code, the single error line, and that
every file the command reads is byte for byte what it was.
"""

from __future__ import annotations

import os
import shutil
import sqlite3

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from support.helpers import make_bag

from bagfault.cli import main
from bagfault.io.outputs import written_by_bagfault

SCENARIO = """
injector: {id: imu, type: imu, input_topic: /imu, output_topic: /imu_out}
faults:
  - {id: bias, injector_id: imu, start: 0.5, duration: 1.0, config: {linear_acceleration_z_bias: 1.0}}
"""


@pytest.fixture
def bag(tmp_path):
    return make_bag(tmp_path / 'in.mcap', [('/imu', 'sensor_msgs/msg/Imu', 20.0)], 2.0)


@pytest.fixture
def scenario(tmp_path):
    path = tmp_path / 'scenario.yaml'
    path.write_text(SCENARIO)
    return path


def _refused(capsys, argv, *needles):
    """The command exits 2 with one line holding every needle."""
    assert main(argv) == 2
    error = capsys.readouterr().err.strip()
    assert error.count('\n') == 0, error
    for needle in needles:
        assert needle in error, error
    return error


def test_a_hard_link_of_the_input_is_the_input(tmp_path, bag, scenario, capsys):
    before = bag.read_bytes()
    os.link(bag, tmp_path / 'alias.mcap')
    _refused(capsys, ['run', str(scenario), str(bag), '-o', str(tmp_path / 'alias.mcap')], 'same file as the input')
    assert bag.read_bytes() == before


def test_a_symlink_to_the_scenario_is_the_scenario(tmp_path, bag, scenario, capsys):
    (tmp_path / 'link.mcap').symlink_to(scenario)
    _refused(capsys, ['run', str(scenario), str(bag), '-o', str(tmp_path / 'link.mcap')], 'the scenario')
    assert scenario.read_text() == SCENARIO


def test_a_report_on_a_msg_path_file_is_refused(tmp_path, bag, scenario, capsys):
    """A `--msg-path` folder is read: no report may replace one of its definitions (here through a hard link)."""
    folder = tmp_path / 'defs' / 'my_msgs' / 'msg'
    folder.mkdir(parents=True)
    definition = folder / 'Thing.msg'
    definition.write_text('float64 x\n')
    os.link(definition, tmp_path / 'report.md')
    _refused(capsys, ['run', str(scenario), str(bag), '-o', str(tmp_path / 'out.mcap'), '--msg-path',
                      str(tmp_path / 'defs'), '--report', str(tmp_path / 'report.md')], 'the --msg-path')
    assert definition.read_text() == 'float64 x\n'
    assert not (tmp_path / 'out.mcap').exists()


def test_an_sqlite_inputs_sidecars_are_never_written(tmp_path, scenario, capsys):
    """A `-wal` written beside a database is replayed into it by the next reader: refused even when absent."""
    source = make_bag(tmp_path / 'src.mcap', [('/imu', 'sensor_msgs/msg/Imu', 20.0)], 1.0)
    database = tmp_path / 'bag.db3'
    database.write_bytes(b'')
    with sqlite3.connect(database) as connection:
        connection.execute('CREATE TABLE t (x)')
    before = database.read_bytes()
    for suffix in ('-wal', '-shm', '-journal'):
        _refused(capsys, ['run', str(scenario), str(database), '-o', str(tmp_path / f'bag.db3{suffix}')],
                 'SQLite sidecar')
        assert not (tmp_path / f'bag.db3{suffix}').exists()
    assert database.read_bytes() == before
    assert source.exists()


def test_a_symlinked_databases_sidecars_beside_the_real_file_are_never_written(tmp_path, scenario, capsys):
    """SQLite writes `-wal` beside the file it opened, not beside the link: both names are protected."""
    real_folder = tmp_path / 'real'
    real_folder.mkdir()
    database = real_folder / 'bag.db3'
    with sqlite3.connect(database) as connection:
        connection.execute('CREATE TABLE t (x)')
    link = tmp_path / 'link.db3'
    link.symlink_to(database)
    before = database.read_bytes()
    for target in (real_folder / 'bag.db3-wal', tmp_path / 'link.db3-journal'):
        _refused(capsys, ['run', str(scenario), str(link), '-o', str(target)], 'SQLite sidecar')
        assert not target.exists()
    assert database.read_bytes() == before


def test_a_file_inside_an_input_folder_by_identity(tmp_path, scenario, capsys):
    """A rosbag2 folder's storage file, hard-linked elsewhere, is still the input."""
    folder = tmp_path / 'rosbag'
    folder.mkdir()
    inner = make_bag(folder / 'rosbag_0.mcap', [('/imu', 'sensor_msgs/msg/Imu', 20.0)], 1.0)
    before = inner.read_bytes()
    os.link(inner, tmp_path / 'elsewhere.mcap')
    _refused(capsys, ['run', str(scenario), str(folder), '-o', str(tmp_path / 'elsewhere.mcap')],
             'same file as the input')
    _refused(capsys, ['run', str(scenario), str(folder), '-o', str(folder / 'new.mcap')], 'inside the input')
    assert inner.read_bytes() == before


@pytest.mark.parametrize('kind', ['fifo', 'device', 'socket'])
def test_outputs_that_are_not_regular_files(tmp_path, bag, scenario, capsys, kind):
    """A FIFO, a device or a socket is not replaced by a rename (it used to be: /dev/null became a file)."""
    target = tmp_path / 'special'
    if kind == 'fifo':
        os.mkfifo(target)
        expected = 'a FIFO'
    elif kind == 'device':
        target = tmp_path / 'null'
        os.symlink('/dev/null', target)  # not writing to /dev/null: the check is on what the name points at
        expected = 'a character device'
    else:
        import socket

        server = socket.socket(socket.AF_UNIX)
        server.bind(str(target))
        expected = 'a socket'
    _refused(capsys, ['run', str(scenario), str(bag), '-o', str(target)], 'not a regular file', expected)
    assert os.stat('/dev/null').st_rdev == os.makedev(1, 3)


def test_a_folder_name_is_not_made_a_file(tmp_path, bag, scenario, capsys):
    with pytest.raises(SystemExit) as stopped:
        main(['run', str(scenario), str(bag), '-o', str(tmp_path / 'newdir') + '/'])
    assert stopped.value.code == 2
    assert 'names a folder' in capsys.readouterr().err
    assert not (tmp_path / 'newdir').exists()


def test_a_file_bagfault_did_not_write_needs_force(tmp_path, bag, scenario, capsys):
    out = tmp_path / 'out.mcap'
    out.write_bytes(b'my own data\n')
    _refused(capsys, ['run', str(scenario), str(bag), '-o', str(out)], 'bagfault did not write it', '--force')
    assert out.read_bytes() == b'my own data\n'
    capsys.readouterr()
    assert main(['run', str(scenario), str(bag), '-o', str(out), '--force']) == 0
    assert written_by_bagfault(out)


def test_every_report_bagfault_wrote_is_replaced_without_force(tmp_path, bag, scenario, capsys):
    """Run twice with every report: the second run recognises each file as bagfault's own."""
    names = {'--report': 'r.md', '--json': 'r.json', '--junit': 'r.xml', '--html': 'r.html'}
    argv = ['run', str(scenario), str(bag), '-o', str(tmp_path / 'out.mcap')]
    for option, name in names.items():
        argv += [option, str(tmp_path / name)]
    assert main(argv) == 0
    for name in [*names.values(), 'out.mcap']:
        assert written_by_bagfault(tmp_path / name), name
    assert main(argv) == 0
    shutil.copy(tmp_path / 'r.json', tmp_path / 'keep.json')
    (tmp_path / 'r.json').write_text('{"tool": "someone"}\n')
    capsys.readouterr()
    _refused(capsys, argv, 'r.json', 'bagfault did not write it')


def test_black_boxes_are_checked_before_the_run(tmp_path, bag, scenario, capsys):
    """A file at a black box name of the output, bagfault's or not, is looked at before anything is written."""
    (tmp_path / 'out.blackbox.ANY.3.mcap').write_text('notes\n')
    _refused(capsys, ['run', str(scenario), str(bag), '-o', str(tmp_path / 'out.mcap')], 'a black box of',
             'bagfault did not write it')
    assert not (tmp_path / 'out.mcap').exists()


def test_black_box_names_with_glob_characters(tmp_path, bag, scenario, capsys):
    """`-o 'run[1].mcap'`: its black boxes are `run[1].blackbox.*.mcap`, looked for by that literal name."""
    (tmp_path / 'run[1].blackbox.ANY.1.mcap').write_text('notes\n')
    _refused(capsys, ['run', str(scenario), str(bag), '-o', str(tmp_path / 'run[1].mcap')], 'a black box of',
             'bagfault did not write it')


LOOKALIKES = {
    'notes.md': b'# bagfault notes\n\nmy own notes about the run\n',
    'results.csv': b'job,kind,bag,seed,status\n0,run,a.mcap,0,passed\n',
    'r.json': b'{"tool": "bagfault", "mine": true}\n',
    'c.json': b'{"tool": {"name": "bagfault", "version": "1"}, "bagfault": "1"}\n',
    'r.xml': b'<?xml version="1.0"?>\n<testsuites name="bagfault" tests="1"/>\n',
    'r.html': b'<html><head><meta name="generator" content="bagfault 1"><title>bagfault run</title></head></html>\n',
    'fake.json': b'{"x": 1,\n "bagfault_mark": "bagfault-mark:' + b'a' * 64 + b'"\n}\n',
}


@pytest.mark.parametrize('name', sorted(LOOKALIKES))
def test_a_file_that_only_looks_like_bagfaults_is_not_replaced(tmp_path, name):
    """The first bytes bagfault writes, or a made-up mark, are no proof (notes.md starting `# bagfault `, a CSV
    with the campaign's columns and a JSON naming the tool were replaced without --force)."""
    path = tmp_path / name
    path.write_bytes(LOOKALIKES[name])
    assert not written_by_bagfault(path)


def test_an_mcap_naming_bagfault_as_its_library_is_not_bagfaults(tmp_path):
    from mcap.writer import Writer

    path = tmp_path / 'foreign.mcap'
    with path.open('wb') as stream:
        writer = Writer(stream)
        writer.start(profile='ros2', library='bagfault 9.9')
        writer.add_metadata('bagfault.mark', {'mark': 'a' * 64})
        writer.finish()
    assert not written_by_bagfault(path)


def test_bagfaults_own_files_stop_being_its_own_once_edited_or_rewritten(tmp_path, bag, scenario):
    """Every kind bagfault writes carries proof; an edited report, an edited table and an MCAP rewritten by
    another writer that copies its records (metadata included) lose it."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    from bagfault.io.outputs import write_atomic

    out = tmp_path / 'out.mcap'
    argv = ['run', str(scenario), str(bag), '-o', str(out), '--report', str(tmp_path / 'r.md'),
            '--json', str(tmp_path / 'r.json'), '--junit', str(tmp_path / 'r.xml'), '--html', str(tmp_path / 'r.html')]
    assert main(argv) == 0
    write_atomic(tmp_path / 't.csv', 'a,b\n1,2\n', 'table')
    write_atomic(tmp_path / 's.yaml', 'faults: []\n', 'yaml')
    names = ['out.mcap', 'r.md', 'r.json', 'r.xml', 'r.html', 't.csv', 's.yaml']
    assert all(written_by_bagfault(tmp_path / name) for name in names)
    for name in names[1:]:
        path = tmp_path / name
        data = path.read_bytes()
        at = len(data) // 3
        path.write_bytes(data[:at] + (b'Z' if data[at:at + 1] != b'Z' else b'Y') + data[at + 1:])
        assert not written_by_bagfault(path), name
    copy = tmp_path / 'copy.mcap'
    with out.open('rb') as source, copy.open('wb') as stream:
        reader = make_reader(source)
        summary = reader.get_summary()
        writer = Writer(stream)
        writer.start(profile=reader.get_header().profile, library=reader.get_header().library)
        for schema in summary.schemas.values():
            writer.register_schema(schema.name, schema.encoding, schema.data)
        for channel in summary.channels.values():
            writer.register_channel(channel.topic, channel.message_encoding, channel.schema_id, channel.metadata)
        for _, channel, message in reader.iter_messages(log_time_order=False):
            writer.add_message(channel.id, message.log_time, message.data, message.publish_time)
        for metadata in reader.iter_metadata():
            writer.add_metadata(metadata.name, metadata.metadata)
        writer.finish()
    assert [m.name for m in make_reader(copy.open('rb')).iter_metadata()][-1] == 'bagfault.mark'
    assert not written_by_bagfault(copy)
    shutil.copy(out, tmp_path / 'same.mcap')  # the same bytes: bagfault's file still
    assert written_by_bagfault(tmp_path / 'same.mcap')


@given(data=st.binary(max_size=2000), kind=st.sampled_from(['markdown', 'html', 'xml', 'yaml', 'json']),
       flip=st.integers(min_value=0), seed_bytes=st.binary(min_size=1, max_size=1))
@settings(max_examples=200, deadline=None)
def test_a_mark_is_never_found_by_chance_and_any_changed_byte_loses_it(data, kind, flip, seed_bytes):
    """Generated: text bagfault never stamped holds no valid mark; a stamped text holds one; and changing any
    one byte of the stamped text (mark included) loses it."""
    from bagfault.io.marks import is_marked, stamp

    assert not is_marked(data)
    body = b'{"x": ' + str(len(data)).encode() + b'}\n' if kind == 'json' else data
    stamped = stamp(body, kind)
    assert is_marked(stamped)
    at = flip % len(stamped)
    changed = stamped[:at] + bytes([stamped[at] ^ (seed_bytes[0] or 1)]) + stamped[at + 1:]
    assert not is_marked(changed)


def test_a_campaign_or_exploration_folder_inside_a_bag_folder_is_refused(tmp_path, capsys):
    """A rosbag2 bag is a folder: a campaign's or an exploration's -o may be neither it nor inside it (their files
    would land among the bag's); one line, exit 2, nothing made, the bag as it was."""
    from support.helpers import FIXTURES

    rover = shutil.copytree(FIXTURES / 'rover_3s_sqlite3', tmp_path / 'rover')
    before = {p.name: p.read_bytes() for p in rover.iterdir()}
    scenario = tmp_path / 'odom.yaml'
    scenario.write_text('injector: {id: odom, type: odom, input_topic: /odom_raw, output_topic: /odom}\n'
                        'faults:\n  - {id: bias, injector_id: odom, start: 0.5, duration: 1.0, config: {x_bias: 1.0}}\n'
                        'explore:\n  faults:\n    - {id: push, injector_id: odom, start: [0, 1], duration: 0.5, '
                        'config: {x_bias: [0.0, 1.0]}}\n')
    campaign = tmp_path / 'campaign.yaml'
    campaign.write_text('campaign: inside\nscenario: plain.yaml\nbags: [rover]\nsweep: {faults.bias.start: [0.5]}\n')
    (tmp_path / 'plain.yaml').write_text(scenario.read_text().split('explore:')[0])
    for out in (rover, rover / 'results'):
        _refused(capsys, ['campaign', str(campaign), '-o', str(out)], 'would be inside the bag', str(rover))
        _refused(capsys, ['explore', str(scenario), str(rover), '-o', str(out)], 'would be inside the bag')
    assert {p.name: p.read_bytes() for p in rover.iterdir()} == before
