"""The fast paths (raw copy, CDR patching, batches) give the same bytes as the simple reference path.

The reference path (`batch=False`) decodes and re-encodes every message and
applies faults one message at a time. For each benchmark scenario kind, on
short versions of the benchmark bags, both paths must write identical files.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from mcap.reader import make_reader

from bagfault import api
from bagfault.demo.workloads import scenario, write_bag
from bagfault.injectors import base
from bagfault.scenario import parse_scenario

CASES = [('sensor-heavy', case) for case in 'abcd'] + [('message-heavy', case) for case in 'abd']
SECONDS = {'sensor-heavy': 0.35, 'message-heavy': 0.2}


@pytest.fixture(scope='module')
def bags(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp('bench')
    paths = {}
    for kind, seconds in SECONDS.items():
        paths[kind] = folder / f'{kind}.mcap'
        write_bag(paths[kind], kind, seconds)
    return paths


def topic_messages(path: Path) -> dict[str, list[tuple[int, bytes]]]:
    with path.open('rb') as stream:
        messages: dict[str, list[tuple[int, bytes]]] = {}
        for _, channel, message in make_reader(stream).iter_messages(log_time_order=False):
            messages.setdefault(channel.topic, []).append((message.log_time, message.data))
        return messages


@pytest.mark.parametrize(('kind', 'case'), CASES)
def test_fast_and_reference_paths_write_identical_files(
    bags: dict[str, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch, kind: str, case: str,
) -> None:
    patched = []
    original = base.patch_linear

    def spy(*args: object) -> object:
        result = original(*args)
        patched.append(result is not None)
        return result

    monkeypatch.setattr(base, 'patch_linear', spy)
    loaded = parse_scenario(scenario(kind, case))
    fast = api.run(loaded, [bags[kind]], tmp_path / 'fast.mcap', seed=3, chunk_copy=False)
    fast_patched = list(patched)
    reference = api.run(loaded, [bags[kind]], tmp_path / 'reference.mcap', seed=3, batch=False)
    assert fast.stats.output_messages == reference.stats.output_messages
    assert (tmp_path / 'fast.mcap').read_bytes() == (tmp_path / 'reference.mcap').read_bytes()
    if case == 'b':  # the IMU bias and noise went through the CDR patching path, not the decoder
        assert fast_patched and all(fast_patched)
    before, after = topic_messages(bags[kind]), topic_messages(tmp_path / 'fast.mcap')
    if case == 'd':  # every kept message is an input message 50 ms later; a fifth or so are gone
        for topic, messages in before.items():
            shifted = {(time + 50_000_000, data) for time, data in messages}
            assert set(after[topic]) <= shifted
        kept = sum(map(len, (after[t] for t in before))) / sum(map(len, before.values()))
        assert 0.7 < kept < 0.9
        return
    changed = {topic for topic in before if before[topic] != after.get(topic)}
    expected = {'a': set(), 'b': {t for t in before if 'imu' in t}, 'c': {'/points'}}[case]
    assert changed == expected


def test_patching_falls_back_when_layouts_differ(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """IMU messages whose frame ids differ in length cannot share one layout: decoded instead, same bytes."""
    from mcap.writer import CompressionType, Writer

    from bagfault.demo import synthetic

    ts = synthetic.store()
    bag = tmp_path / 'frames.mcap'
    with bag.open('wb') as stream:
        writer = Writer(stream, compression=CompressionType.ZSTD)
        writer.start(profile='ros2', library='test')
        text, _ = ts.generate_msgdef('sensor_msgs/msg/Imu', ros_version=2)
        channel = writer.register_channel('/imu', 'cdr', writer.register_schema('sensor_msgs/msg/Imu', 'ros2msg',
                                                                                text.encode()), {})
        for k in range(40):
            message = synthetic.BUILDERS['sensor_msgs/msg/Imu'](ts, k, k * 0.01)
            message.header.frame_id = 'imu' + 'x' * (k % 3)
            time = synthetic.DEFAULT_START + k * 10_000_000
            writer.add_message(channel, time, bytes(ts.serialize_cdr(message, 'sensor_msgs/msg/Imu')), time)
        writer.finish()
    patched = []
    original = base.patch_linear
    monkeypatch.setattr(base, 'patch_linear', lambda *a: patched.append(original(*a)) or patched[-1])
    loaded = parse_scenario(scenario('sensor-heavy', 'b'))
    api.run(loaded, [bag], tmp_path / 'fast.mcap', seed=5, chunk_copy=False)
    api.run(loaded, [bag], tmp_path / 'reference.mcap', seed=5, batch=False)
    assert patched and all(result is None for result in patched)
    assert (tmp_path / 'fast.mcap').read_bytes() == (tmp_path / 'reference.mcap').read_bytes()
