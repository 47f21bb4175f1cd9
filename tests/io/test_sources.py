"""Inputs written by other tools: every storage, metadata version, compression and quirk."""

from __future__ import annotations

import re
from collections import Counter
from pathlib import Path

import pytest
from support.helpers import EXTERNAL, third_party
from support.io_cases import ROSBAG2_DIRS, metadata_counts

from bagfault.errors import InputError
from bagfault.io.sources import InputSet, open_source


def read_all(path: Path) -> tuple[Counter[str], list[int]]:
    source = open_source(path)
    try:
        topics = Counter()
        times = []
        for channel, log_time, _, _ in source.messages():
            topics[source.channels[channel].topic] += 1
            times.append(log_time)
        return topics, times
    finally:
        source.close()


@pytest.mark.parametrize('relative', third_party(ROSBAG2_DIRS))
def test_rosbag2_directory_counts_match_metadata(external, relative):
    path = external / relative
    topics, times = read_all(path)
    assert topics == metadata_counts(path)
    assert times == sorted(times)


@pytest.mark.parametrize(('relative', 'total'), third_party([
    ('rosbag2-humble/rosbag2_tests/resources/reindex_test_bags/file_compression', 775),
    ('rosbag2-humble/rosbag2_tests/resources/reindex_test_bags/message_compression', 1127),
    ('rosbag2-humble/rosbag2_tests/resources/reindex_test_bags/multiple_files', 52),
], arity=2))
def test_directories_without_metadata_read_all_storage_files(external, relative, total):
    target = external / 'rosbag2-humble/rosbag2_tests/resources/reindex_test_bags/target_metadata' / Path(relative).name
    topics, times = read_all(external / relative)
    assert sum(topics.values()) == total
    assert topics == metadata_counts(target)
    assert times == sorted(times)


@pytest.mark.parametrize(('relative', 'expected'), third_party([
    ('rosbag2/rosbag2_cpp/test/rosbag2_cpp/bags/only_topics.mcap', {'/parameter_events': 7}),
    ('rosbag2/rosbag2_cpp/test/rosbag2_cpp/bags/only_services.mcap', {'/add_two_ints/_service_event': 12}),
    ('rosbag2/rosbag2_cpp/test/rosbag2_cpp/bags/topics_and_services.db3',
     {'/parameter_events': 7, '/add_two_ints/_service_event': 6}),
    ('rosbag2/rosbag2_cpp/test/rosbag2_cpp/bags/topics_and_services.mcap',
     {'/parameter_events': 7, '/add_two_ints/_service_event': 6}),
    ('mcap/testdata/db3/chatter.db3', {'/chatter': 7}),
    ('evo/test/data/nav2_turtlebot.mcap', {'/odom': 2639, '/tf': 5422, '/tf_static': 1, '/amcl_pose': 135}),
], arity=2))
def test_bare_storage_files(external, relative, expected):
    topics, _ = read_all(external / relative)
    assert topics == Counter(expected)


def test_split_bag_topics_keep_their_names_across_files(external):
    """Each file of a split bag numbers its topics differently; merged counts still match."""
    topics, _ = read_all(external / 'rosbag2/rosbag2_py/test/resources/mcap/wbag')
    assert topics == metadata_counts(external / 'rosbag2/rosbag2_py/test/resources/mcap/wbag')


def test_humble_bag_without_definitions_reports_its_distro(external):
    source = open_source(external / 'Turtlebot_Walker_Algorithm_ROS2/walker_bag_topics_list')
    try:
        assert source.ros_distro == 'humble'
        assert all(not c.schema_text for c in source.channels)
        imu = next(c for c in source.channels if c.topic == '/imu')
        assert imu.msgtype == 'sensor_msgs/msg/Imu' and 'reliability' in imu.qos
    finally:
        source.close()


def test_old_type_names_are_normalized(external):
    source = open_source(external / 'rosbag2/rosbag2_transport/test/resources/sqlite3/test_bag_for_seek')
    try:
        assert {c.msgtype for c in source.channels} == {'test_msgs/msg/BasicTypes'}
    finally:
        source.close()


CONFORMANCE = sorted((EXTERNAL / 'mcap/tests/conformance/data').glob('*/*.mcap'))


@pytest.mark.parametrize('path', third_party(CONFORMANCE), ids=lambda p: p.name)
def test_mcap_conformance_inputs(path):
    expected = {'NoData': 0, 'OneMessage': 1, 'TenMessages': 10, 'OneAttachment': 0, 'OneMetadata': 0}
    topics, times = read_all(path)
    assert sum(topics.values()) == expected[path.parent.name]
    assert times == sorted(times)
    if topics:
        assert set(topics) == {'example'}


def test_multiple_inputs_merge_in_time_order(external):
    bags = [external / 'rosbag2/rosbag2_py/test/resources/sqlite3/talker',
            external / 'rosbag2/rosbag2_py/test/resources/mcap/talker']
    inputs = InputSet(bags)
    try:
        times = [t for _, t, _, _ in inputs.messages()]
        assert len(times) == 40 and times == sorted(times)
        assert sorted(c.topic for c in inputs.channels) == ['/parameter_events', '/rosout', '/topic']
    finally:
        inputs.close()


def _file(name: str, data: bytes):
    def make(directory: Path) -> Path:
        (directory / name).write_bytes(data)
        return directory / name
    return make


def _folder(directory: Path) -> Path:
    (directory / 'dir').mkdir()
    return directory / 'dir'


@pytest.mark.parametrize(('make', 'message'), [
    (lambda d: d / 'missing.mcap', 'no such file or directory'),
    (_file('empty.mcap', b''), 'file is empty'),
    (_file('junk.db3', b'hello world, not a bag' * 10), 'not a bag'),
    (_file('junk.mcap', b'\x89MCAP0\r\n' + bytes(10)), 'truncated'),
    (_folder, 'no metadata.yaml and no .db3 or .mcap files'),
])
def test_bad_inputs_are_clear_errors(tmp_path, make, message):
    path = make(tmp_path)
    with pytest.raises(InputError, match=message) as info:
        open_source(path)
    assert str(path) in str(info.value)


def test_truncated_and_corrupt_mcap(tmp_path, rover_bag):
    data = rover_bag.read_bytes()
    truncated = tmp_path / 'truncated.mcap'
    truncated.write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match='truncated'):
        open_source(truncated)
    corrupt = tmp_path / 'corrupt.mcap'
    corrupt.write_bytes(data[:2000] + bytes(5000) + data[7000:])
    with pytest.raises(InputError, match='corrupt'):
        source = open_source(corrupt)
        for _ in source.messages():
            pass


def test_metadata_listing_missing_files(tmp_path, rover_sqlite):
    bag = tmp_path / 'bag'
    bag.mkdir()
    (bag / 'metadata.yaml').write_text((rover_sqlite / 'metadata.yaml').read_text())
    with pytest.raises(InputError, match=re.escape('files listed in metadata.yaml are missing')):
        open_source(bag)


def test_empty_file_bag_from_rosbag_js(external):
    with pytest.raises(InputError, match='file is empty'):
        open_source(external / 'rosbag.js/fixtures/empty-file.bag')


def test_input_digests_are_blake3_over_every_window_and_stop_when_asked(tmp_path: Path) -> None:
    import threading

    import blake3

    from bagfault.io import sources

    data = bytes(range(256)) * 41 + b'tail'  # windows of 4096 bytes: two whole and a partial one
    path = tmp_path / 'input.bin'
    path.write_bytes(data)
    assert sources._blake3(path, None, window=4096) == blake3.blake3(data).hexdigest()
    # the BLAKE3 test vector of the empty input (the reference implementation's test_vectors.json)
    (tmp_path / 'empty.bin').write_bytes(b'')
    assert sources.fingerprint(tmp_path / 'empty.bin')[0].blake3 == (
        'af1349b9f5f9a1a6a0404dea36dcc9499bcb25c9adc112b7cc9a93cae41f3262')
    stop = threading.Event()
    stop.set()
    with pytest.raises(sources.HashStopped):
        sources.fingerprint(path, stop)
    with pytest.raises(InputError, match=r'missing\.bin: cannot read: No such file'):
        sources.fingerprint(tmp_path / 'missing.bin')


def test_the_hash_keeps_pace_with_the_run_that_reads_the_input(tmp_path: Path) -> None:
    """A run that reads its one input in order (chunk copy) leads its hash: the hash reads a window only once
    the run is within `lead` of it, so the page cache holds what one brought in when the other needs it."""
    import threading

    import blake3

    from bagfault.io import sources

    data = bytes(range(256)) * 41 + b'tail'  # 10500 bytes: windows of 4096 end at 4096, 8192 and 12288
    path = tmp_path / 'input.bin'
    path.write_bytes(data)
    for finish in ('advance', 'release'):
        mark = sources.ReadMark(lead=4096)
        found: list[str] = []
        worker = threading.Thread(target=lambda m=mark, f=found: f.append(sources._blake3(path, None, m, window=4096)))
        worker.start()
        worker.join(0.3)
        assert worker.is_alive()  # the second window ends 8192 bytes in: beyond the run (0) plus the lead
        if finish == 'advance':
            mark.advance(8192)  # the run reached the third window's start: all of it is within the lead
        else:
            mark.release()  # the run ended, or reads the file another way: hash the rest freely
        worker.join(5)
        assert found == [blake3.blake3(data).hexdigest()]
    stop = threading.Event()
    waiting = sources.ReadMark(lead=0)
    worker = threading.Thread(target=waiting.wait_for, args=(4096, stop))
    worker.start()
    stop.set()  # a failed run: the hash gives up instead of waiting for a run that will not come
    worker.join(2)
    assert not worker.is_alive()


def test_the_hash_keeps_pace_with_a_leading_copy_the_run_took_chunks_from(tmp_path: Path,
                                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    """The run takes a leading copy's chunks before it has copied them: the run's position then counts only as
    far as the copy has read, until the copy is done."""
    import threading

    from bagfault.io import file_copy, leading_copy, sources
    from bagfault.io.leading_copy import LeadingCopy, Piece
    from bagfault.io.outputs import PartialFile

    for run in ('took everything', 'is done with the file'):
        mark = sources.ReadMark(lead=0)
        mark.advance(10_000)
        if run == 'is done with the file':
            mark.release()
        mark.cap(1000)  # the copy has read 1000 bytes
        waiter = threading.Thread(target=mark.wait_for, args=(5000, None))
        waiter.start()
        waiter.join(0.3)
        assert waiter.is_alive()
        mark.cap(None)  # the copy is done
        waiter.join(5)
        assert not waiter.is_alive()

    source = tmp_path / 'input.bin'
    source.write_bytes(bytes(range(256)) * 100)
    go = threading.Event()

    def held(*args: object, **kwargs: object) -> bool:
        go.wait(5)
        return file_copy.copy_range(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(leading_copy, 'copy_range', held)
    caps: list[int | None] = []
    mark = sources.ReadMark()
    mark.cap = caps.append  # type: ignore[method-assign]
    with PartialFile(tmp_path / 'out.bin') as file, LeadingCopy(source, [Piece(100, 50, 20_000)], file) as lead:
        lead.pace(mark)  # before it has copied: the run counts up to where the copy starts
        assert caps == [100]
        go.set()
        lead.stop(lead.end)
        assert caps == [100, 20_100, None]  # copied, then done: the run's own position counts again
        lead.pace(sources.ReadMark())  # a run that comes after the copy is not held back
    assert caps == [100, 20_100, None]


def test_a_leading_copy_does_not_leave_the_hash_behind(tmp_path: Path) -> None:
    """On a cold disk a copy far ahead of the hash leaves it pages the page cache no longer holds: the copy
    waits while a hash is more than `lead` behind it, and not once the hash is done or the copy is stopped."""
    import threading

    from bagfault.io import sources

    mark = sources.ReadMark(lead=100)
    for ends in ('the hash moves on', 'the hash is done', 'the copy is stopped'):
        stopping = threading.Event()
        mark.hashed(0)
        waiter = threading.Thread(target=mark.wait_for_hash, args=(500, stopping.is_set))
        waiter.start()
        waiter.join(0.2)
        assert waiter.is_alive()
        if ends == 'the hash moves on':
            mark.hashed(400)  # within 100 of the copy
        elif ends == 'the hash is done':
            mark.hashed(None)
        else:
            stopping.set()
        waiter.join(5)
        assert not waiter.is_alive()
    path = tmp_path / 'input.bin'
    path.write_bytes(bytes(50_000))
    mark = sources.ReadMark()
    sources._blake3(path, None, mark, window=4096)
    mark.wait_for_hash(10**9, lambda: False)  # returns: a finished hash holds nobody


def test_a_fifo_is_refused_before_it_is_read(tmp_path):
    """A FIFO as the input, or listed in metadata.yaml, blocked the run for ever (SIGTERM did not end it)."""
    import os
    import subprocess
    import sys

    fifo = tmp_path / 'in.mcap'
    os.mkfifo(fifo)
    scenario = tmp_path / 'pass.yaml'
    scenario.write_text('injectors: []\n')
    folder = tmp_path / 'bag'
    folder.mkdir()
    os.mkfifo(folder / 'bag_0.db3')
    (folder / 'metadata.yaml').write_text(
        'rosbag2_bagfile_information:\n  version: 5\n  storage_identifier: sqlite3\n'
        '  relative_file_paths: [bag_0.db3]\n  message_count: 0\n  topics_with_message_count: []\n')
    for bag, name in ((fifo, 'in.mcap'), (folder, 'bag_0.db3')):
        done = subprocess.run([sys.executable, '-m', 'bagfault.cli', 'run', str(scenario), str(bag), '-o',
                               str(tmp_path / 'out.mcap')], capture_output=True, text=True, timeout=60, check=False)
        assert done.returncode == 2 and done.stderr.count('\n') == 1, done.stderr
        assert f'{name}: not a regular file' in done.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ['bag', 'in.mcap', 'pass.yaml']
