"""Structured fuzzing of every input format: seeded, record-aware mutations (support/mutations.py) of the
fixture bags and, when ../shared is present, of third-party bags. Each variant runs the real command line
and must end one of two ways: exit 0 with every message the pristine input holds (counted by an independent
reader in the output, the output's CRCs checked), or exit 2 with one `bagfault: error:` line and no output.
Never a traceback or an internal error, never a hang (20 s per variant), never a changed input.
"""

from __future__ import annotations

import contextlib
import hashlib
import random
import shutil
import signal
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore
from support import mutations
from support.helpers import EXTERNAL, FIXTURES

from bagfault.cli import main
from bagfault.demo import synthetic

SCENARIO = 'injectors: []\nfaults: []\n'  # every message passes through as it is
VARIANT_SECONDS = 20


class Hang(BaseException):
    """A variant ran past its time (a BaseException, so no `except Exception` in bagfault swallows it)."""


@contextlib.contextmanager
def deadline(seconds: int) -> Iterator[None]:
    def expired(_number: int, _frame: object) -> None:
        raise Hang(f'no end after {seconds} s')

    previous = signal.signal(signal.SIGALRM, expired)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


def independent_count(path: Path) -> int:
    """Messages in a pristine input, by the `mcap` library (CRCs checked) or rosbags."""
    if path.suffix == '.mcap':
        with path.open('rb') as stream:
            return sum(1 for _ in make_reader(stream, validate_crcs=True).iter_messages())
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
        return sum(c.msgcount for c in reader.connections)


def output_count(path: Path) -> int:
    """Messages in bagfault's output, by the `mcap` library reading every chunk with CRCs checked."""
    with path.open('rb') as stream:
        return sum(1 for _ in make_reader(stream, validate_crcs=True).iter_messages())


def digest(path: Path) -> str:
    files = sorted(p for p in path.rglob('*') if p.is_file()) if path.is_dir() else [path]
    hasher = hashlib.sha256()
    for file in files:
        hasher.update(file.name.encode() + file.read_bytes())
    return hasher.hexdigest()


def judge(case: Path, folder: Path, expected: int, extra: list[str], capsys: pytest.CaptureFixture[str],
          what: str) -> str:
    """Run one variant and assert the contract; 'ok' or 'error'."""
    scenario = folder / 'scenario.yaml'
    scenario.write_text(SCENARIO)
    out = folder / 'out.mcap'
    before = digest(case)
    capsys.readouterr()
    try:
        with deadline(VARIANT_SECONDS):
            code = main(['run', str(scenario), str(case), '-o', str(out), *extra])
    except Hang:
        pytest.fail(f'{what}: hangs')
    err = capsys.readouterr().err
    assert digest(case) == before, f'{what}: the input was changed'
    assert 'internal error' not in err and 'Traceback' not in err, f'{what}: {err}'
    assert not list(folder.glob('.*.partial')), f'{what}: a temporary file was left'
    if code == 2:
        lines = [line for line in err.splitlines() if not line.startswith('warning:')]
        assert len(lines) == 1 and lines[0].startswith('bagfault: error: '), f'{what}: {err}'
        assert not out.exists(), f'{what}: exit 2 with an output'
        return 'error'
    assert code == 0, f'{what}: exit {code}: {err}'
    found = output_count(out)
    assert found == expected, f'{what}: exit 0 with {found} of the {expected} messages the input holds: {err}'
    out.unlink()
    return 'ok'


def fuzz(source: Path, mutate: Callable[[Path, random.Random], str], seed: str, variants: int, tmp_path: Path,
         capsys: pytest.CaptureFixture[str], extras: list[list[str]]) -> dict[str, int]:
    """`variants` seeded mutations of `source` (a file or a rosbag2 folder), each judged."""
    expected = independent_count(source if source.is_file() else mutations.storage_of(source))
    verdicts = {'ok': 0, 'error': 0}
    for number in range(variants):
        rng = random.Random(f'{seed}-{number}')
        folder = tmp_path / f'v{number}'
        folder.mkdir()
        case = folder / source.name
        if source.is_dir():
            shutil.copytree(source, case)
        else:
            shutil.copy(source, case)
        what = f'{source.name} variant {number} ({mutate(case, rng)})'
        extra = extras[number % len(extras)]
        verdicts[judge(case, folder, expected, extra, capsys, f'{what} {" ".join(extra)}')] += 1
        shutil.rmtree(folder)
    return verdicts


def mcap_mutator(*, inside_chunks: bool) -> Callable[[Path, random.Random], str]:
    def mutate(path: Path, rng: random.Random) -> str:
        data, done = mutations.mutate_mcap(path.read_bytes(), rng, inside_chunks=inside_chunks)
        path.write_bytes(data)
        return str(done)
    return mutate


def ros1_mutator(path: Path, rng: random.Random) -> str:
    data, done = mutations.mutate_ros1(path.read_bytes(), rng)
    path.write_bytes(data)
    return str(done)


def rosbag2_mutator(folder: Path, rng: random.Random) -> str:
    if rng.random() < 0.3:
        meta = folder / 'metadata.yaml'
        text, done = mutations.mutate_metadata(meta.read_text(), rng)
        meta.write_text(text)
        return f'metadata.yaml {done}'
    storage = mutations.storage_of(folder)
    data, done = mutations.mutate_sqlite(storage.read_bytes(), rng)
    storage.write_bytes(data)
    return f'{storage.name} {done}'


# The copy path checks copied chunks against their indexes; --verify (and the reference path) read them too.
MCAP_MODES = [['--verify'], ['--no-chunk-copy'], []]


def test_fuzz_a_bagfault_written_mcap(tmp_path, capsys):
    source = tmp_path / 'src' / 'imu.mcap'
    source.parent.mkdir()
    streams = [synthetic.Stream('/imu', 'sensor_msgs/msg/Imu', 100.0), synthetic.Stream('/odom', 'nav_msgs/msg/Odometry', 20.0)]
    synthetic.write_mcap(source, synthetic.messages(streams, 2.0), compression=CompressionType.ZSTD, chunk_size=4096)
    verdicts = fuzz(source, mcap_mutator(inside_chunks=False), 'bagfault-mcap', 24, tmp_path, capsys, MCAP_MODES)
    assert verdicts['error'] > 0 and verdicts['ok'] > 0  # the mutations do damage, and some are harmless


def test_fuzz_an_uncompressed_mcap_without_chunk_crcs(tmp_path, capsys):
    """As rosbag2's MCAP storage writes them: a flipped record inside a chunk has no CRC to betray it."""
    source = tmp_path / 'src' / 'plain.mcap'
    source.parent.mkdir()
    with source.open('wb') as stream:
        writer = Writer(stream, chunk_size=400, compression=CompressionType.NONE)
        writer.start(profile='', library='test')
        schema = writer.register_schema('raw', 'jsonschema', b'{}')
        channels = [writer.register_channel(t, 'json', schema, {'offered_qos_profiles': ''}) for t in ('/a', '/b')]
        for k in range(60):
            for number, channel in enumerate(channels):
                writer.add_message(channel, 10**9 + k * 10**7 + number, b'{"k": %04d}' % k, 0)
        writer.finish()
    verdicts = fuzz(source, mcap_mutator(inside_chunks=True), 'plain-mcap', 24, tmp_path, capsys,
                    [['--verify'], ['--no-chunk-copy']])
    assert verdicts['error'] > 0


def test_fuzz_a_rosbag2_sqlite3_folder(tmp_path, capsys):
    verdicts = fuzz(FIXTURES / 'rover_3s_sqlite3', rosbag2_mutator, 'rosbag2-sqlite3', 16, tmp_path, capsys, [[]])
    assert verdicts['error'] > 0


def test_fuzz_a_ros1_bag(tmp_path, capsys):
    from rosbags.rosbag1 import Writer as Ros1Writer
    from support.ros1 import ROS1, _to_ros1

    source = tmp_path / 'src' / 'robot.bag'
    source.parent.mkdir()
    writer = Ros1Writer(source)
    writer.chunk_threshold = 8 * 1024  # several chunks
    writer.open()
    connections = {}
    streams = [synthetic.Stream('/imu', 'sensor_msgs/msg/Imu', 100.0), synthetic.Stream('/odom', 'nav_msgs/msg/Odometry', 20.0)]
    for stream, time_ns, message in synthetic.messages(streams, 2.0, ts=synthetic.store()):
        if stream.topic not in connections:
            connections[stream.topic] = writer.add_connection(stream.topic, stream.msgtype, typestore=ROS1)
        writer.write(connections[stream.topic], time_ns,
                     ROS1.serialize_ros1(_to_ros1(message, stream.msgtype), stream.msgtype))
    writer.close()
    verdicts = fuzz(source, ros1_mutator, 'ros1', 20, tmp_path, capsys, [[]])
    assert verdicts['error'] > 0


THIRD_PARTY = [
    ('evo/test/data/nav2_turtlebot.mcap', mcap_mutator(inside_chunks=False), MCAP_MODES),
    ('rosbag.js/fixtures/example-lz4.bag', ros1_mutator, [[]]),
]


@pytest.mark.parametrize(('name', 'mutate', 'modes'), THIRD_PARTY, ids=[n for n, _, _ in THIRD_PARTY])
def test_fuzz_third_party_bags(tmp_path, capsys, name, mutate, modes):
    source = EXTERNAL / name  # $BAGFAULT_SHARED/external_bags, as every test of third-party data
    if not source.exists():
        pytest.skip(f'{source} is not on this machine (set BAGFAULT_SHARED)')
    fuzz(source, mutate, f'shared-{name}', 12, tmp_path, capsys, modes)
