"""The guess of a run's leading copy, made from the scenario's YAML and the input's summary before any heavy import.

What a good guess is comes from outside the code under test: the chunks a
run without a leading copy put in its output byte for byte from its first
chunk on (compared as bytes), and the chunk times of the input read with the
`mcap` library. A guess may stop short of that (it is made on the safe side)
but never go past it, and it places the chunks where the run puts them.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
import yaml
from mcap.reader import make_reader
from support.helpers import EXTERNAL, chunk_indexes, third_party

from bagfault import api
from bagfault.cli import main
from bagfault.demo.workloads import write_bag
from bagfault.engine import lead
from bagfault.engine.activation import Activation
from bagfault.engine.lead import leading_pieces, start_lead
from bagfault.io.leading_copy import Piece
from bagfault.io.mcap_summary import FOOTER_LENGTH, parse_summary, read_footer
from bagfault.io.mcap_writer import McapWriter
from bagfault.io.outputs import PartialFile
from bagfault.scenario import parse_scenario

IMU = """
injectors:
  - {id: imu, type: imu, input_topic: /imu, output_topic: /imu}
faults:
  - {id: bias, injector_id: imu, start: 1.5, duration: 0.4, config: {angular_velocity_z_bias: 0.05}}
"""
NS = 1_000_000_000


@pytest.fixture(scope='module')
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp('guess') / 'sensor.mcap'
    write_bag(path, 'sensor-heavy', 3.0)
    return path


def topics_of(path: Path) -> dict[int, str]:
    with path.open('rb') as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None
    return {cid: channel.topic for cid, channel in summary.channels.items()}


def guess(bag: Path, text: str, **options: Any) -> list[Piece]:
    with bag.open('rb') as stream:
        size = stream.seek(0, 2)
        start, _ = read_footer(stream, size)
        stream.seek(start)
        summary = parse_summary(stream.read(size - 8 - FOOTER_LENGTH - start))
    return leading_pieces(summary, yaml.safe_load(text), options.get('start_offset', 0.0),
                          options.get('activations', ()), options.get('observed', ()))


def run_alone(bag: Path, scenario: str | Path, out: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A run with no leading copy at all (seed 0, as `bagfault run`'s)."""
    with monkeypatch.context() as patch:
        patch.setattr(lead, 'start_lead', lambda *args, **kwargs: None)
        api.run(scenario if isinstance(scenario, Path) else parse_scenario(scenario), [bag], out, seed=0)


def copied(bag: Path, out: Path) -> tuple[int, int]:
    """(output offset of the output's first chunk, bytes of the input's leading chunks found there in a row)."""
    data, written = bag.read_bytes(), out.read_bytes()
    target = chunk_indexes(out)[0].chunk_start_offset
    length = 0
    for chunk in chunk_indexes(bag):
        size = chunk.chunk_length + chunk.message_index_length
        offset = chunk.chunk_start_offset
        if data[offset:offset + size] != written[target + length:target + length + size]:
            break
        length += size
    return target, length


def spans_until(bag: Path, before: float) -> int:
    """Bytes of the input's leading chunks that end before `before` seconds from the first message."""
    found = chunk_indexes(bag)
    limit = found[0].message_start_time + before * NS
    return sum(c.chunk_length + c.message_index_length for c in found if c.message_end_time < limit)


def test_the_guess_is_where_the_run_puts_the_chunks_before_the_fault(bag: Path, tmp_path: Path,
                                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    run_alone(bag, IMU, tmp_path / 'out.mcap', monkeypatch)
    target, length = copied(bag, tmp_path / 'out.mcap')
    pieces = guess(bag, IMU)
    assert len(pieces) == 1
    assert (pieces[0].source, pieces[0].target) == (chunk_indexes(bag)[0].chunk_start_offset, target)
    assert spans_until(bag, 1.5 - 0.01) <= pieces[0].length <= length
    assert pieces[0].length < bag.stat().st_size / 2  # the chunks from 1.5 s on are not guessed


def test_with_no_fault_due_every_chunk_is_guessed(bag: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    text = IMU.replace('start: 1.5', 'start: 100')
    run_alone(bag, text, tmp_path / 'out.mcap', monkeypatch)
    assert [(p.target, p.length) for p in guess(bag, text)] == [copied(bag, tmp_path / 'out.mcap')]
    assert copied(bag, tmp_path / 'out.mcap')[1] == sum(c.chunk_length + c.message_index_length for c in chunk_indexes(bag))


@pytest.mark.parametrize(('change', 'until'), [
    ({'start': 1.5, 'active_on_startup': True}, 0.0),
    ({'start': 1.5, 'active': 'yes'}, 0.0),  # the anchor's older spelling, a YAML 1.1 boolean
    ({'start': 1.5, 'probability_per_second': 0.5}, 0.0),
    ({'start': 1.5, 'repeat': {'period': 1.0, 'on': 0.1}}, 0.0),
    ({'start': '0.5'}, 0.5),  # a quoted number, as the anchor reads it
])
def test_faults_on_from_zero_or_earlier_move_the_guess(bag: Path, change: dict[str, Any], until: float) -> None:
    document = yaml.safe_load(IMU)
    document['faults'][0].update(change)
    pieces = guess(bag, yaml.safe_dump(document))
    length = sum(p.length for p in pieces)
    assert spans_until(bag, until - 0.01) <= length <= spans_until(bag, until)


def test_a_follower_and_an_activation_count_from_their_leader_and_their_start(bag: Path) -> None:
    follower = IMU + '  - {id: later, injector_id: imu, after: {fault: first, delay: 0.1}}\n' \
                     '  - {id: first, injector_id: other, start: 0.8}\n'
    assert spans_until(bag, 0.79) <= sum(p.length for p in guess(bag, follower)) <= spans_until(bag, 0.8)
    early = guess(bag, IMU, activations=[Activation('bias', 0.6)])
    assert spans_until(bag, 0.59) <= sum(p.length for p in early) <= spans_until(bag, 0.6)
    assert sum(p.length for p in guess(bag, IMU, start_offset=1.0)) >= spans_until(bag, 2.49)


@pytest.mark.parametrize('text', [
    IMU + 'assertions:\n  - {id: a, type: topic_hz, topic: imu, min_hz: 10, message_type: sensor_msgs/msg/Imu}\n',
    IMU.replace('output_topic: /imu', 'output_topic: /imu_biased'),
    IMU.replace('config: {', 'config: {freeze: true, '),
])
def test_a_topic_that_something_watches_or_rewrites_stops_the_guess_at_its_first_chunk(bag: Path,
                                                                                         text: str) -> None:
    imu = next(cid for cid, topic in topics_of(bag).items() if topic == '/imu')
    first = next(k for k, c in enumerate(chunk_indexes(bag)) if imu in c.message_index_offsets)
    assert sum(p.length for p in guess(bag, text)) == sum(c.chunk_length + c.message_index_length
                                                          for c in chunk_indexes(bag)[:first])


def test_observers_name_topics_too(bag: Path) -> None:
    whole = sum(p.length for p in guess(bag, IMU.replace('start: 1.5', 'start: 100')))
    assert sum(p.length for p in guess(bag, IMU.replace('start: 1.5', 'start: 100'), observed=['scan'])) < whole


@pytest.mark.parametrize('document', [['not a mapping'], None, 'faults: ['])
def test_no_guess_from_what_is_not_a_scenario(bag: Path, tmp_path: Path, document: object) -> None:
    with PartialFile(tmp_path / 'out.mcap') as file:
        assert start_lead(document, bag, file) is None
        assert file.partial.read_bytes() == b''
    assert list(tmp_path.iterdir()) == []


def test_no_guess_from_what_is_not_an_indexed_mcap(tmp_path: Path) -> None:
    (tmp_path / 'bag.db3').write_bytes(b'SQLite format 3\x00' + bytes(200))
    with PartialFile(tmp_path / 'out.mcap') as file:
        assert start_lead(yaml.safe_load(IMU), tmp_path / 'bag.db3', file) is None
        assert start_lead(yaml.safe_load(IMU), tmp_path / 'missing.mcap', file) is None
        assert file.partial.read_bytes() == b''
    assert sorted(p.name for p in tmp_path.iterdir()) == ['bag.db3']


HEAVY = "{'numpy', 'rosbags', 'rclpy', 'jinja2', 'zstandard', 'lz4'}"
ENGINE = "('bagfault.scenario.validator', 'bagfault.injectors', 'bagfault.engine.offline', 'bagfault.io.mcap_writer')"


@pytest.mark.parametrize('reports', [[], ['--json', 'report.json', '--junit', 'report.xml']])
def test_bagfault_run_starts_its_leading_copy_before_anything_heavy_is_imported(
        bag: Path, tmp_path: Path, reports: list[str]) -> None:
    """What is imported when `bagfault run` starts its leading copy (seen from inside it, in a process of its
    own): no numpy, no decoder, no compressor, no validator, no engine."""
    (tmp_path / 'imu.yaml').write_text(IMU)
    code = f"""
import sys
from bagfault.io import leading_copy
seen = []
start = leading_copy.LeadingCopy.__init__
def watched(self, *args, **kwargs):
    seen.append((sorted({{m.split('.')[0] for m in sys.modules}} & {HEAVY}),
                 sorted(m for m in sys.modules if m.startswith({ENGINE}))))
    start(self, *args, **kwargs)
leading_copy.LeadingCopy.__init__ = watched
from bagfault.cli import main
code = main(['run', 'imu.yaml', {str(bag)!r}, '-o', 'out.mcap', *{reports!r}])
print(code, seen)
"""
    done = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, check=True, cwd=tmp_path)
    assert done.stdout.splitlines()[-1] == '0 [([], [])]'


def test_bagfault_run_with_its_leading_copy_writes_what_the_api_writes_alone(
        bag: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    copies: list[int] = []  # bytes the run's own copy thread copies
    original = McapWriter._copy_range

    def counted(writer: McapWriter, fd: int, offset: int, length: int, at: int) -> None:
        copies.append(length)
        original(writer, fd, offset, length, at)

    monkeypatch.setattr(McapWriter, '_copy_range', counted)
    (tmp_path / 'imu.yaml').write_text(IMU)
    assert main(['run', str(tmp_path / 'imu.yaml'), str(bag), '-o', str(tmp_path / 'cli.mcap')]) == 0
    by_cli, copies[:] = sum(copies), []
    run_alone(bag, tmp_path / 'imu.yaml', tmp_path / 'api.mcap', monkeypatch)
    assert (tmp_path / 'cli.mcap').read_bytes() == (tmp_path / 'api.mcap').read_bytes()
    assert by_cli == sum(copies) - sum(p.length for p in guess(bag, IMU))  # the rest came from the leading copy
    assert sorted(p.name for p in tmp_path.iterdir()) == ['api.mcap', 'cli.mcap', 'imu.yaml']


@pytest.mark.parametrize('problem', ['an output bagfault did not write', 'a scenario that does not validate'])
def test_bagfault_run_refusing_leaves_nothing_of_its_leading_copy(bag: Path, tmp_path: Path, problem: str,
                                                                  capsys: pytest.CaptureFixture[str]) -> None:
    scenario, out = tmp_path / 'imu.yaml', tmp_path / 'out.mcap'
    if problem == 'an output bagfault did not write':
        scenario.write_text(IMU)
        out.write_bytes(b'precious')
    else:
        scenario.write_text(IMU.replace('injector_id: imu', 'injector_id: nowhere'))
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    assert main(['run', str(scenario), str(bag), '-o', str(out)]) == 2
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


ROS2_MCAPS = sorted(p for p in EXTERNAL.rglob('*.mcap') if 'conformance' not in p.parts) if EXTERNAL.exists() else []
LATE = """
injectors:
  - {id: x, type: topic, input_topic: /not_in_the_bag, output_topic: /not_in_the_bag}
faults:
  - {id: f, injector_id: x, start: 1000.0, config: {drop_probability: 1.0}}
"""


@pytest.mark.parametrize('recorded', third_party(ROS2_MCAPS), ids=lambda p: p.name if p else 'none')
def test_bags_others_recorded_come_out_the_same_with_a_leading_copy(
        recorded: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / 'late.yaml').write_text(LATE)
    code = main(['run', str(tmp_path / 'late.yaml'), str(recorded), '-o', str(tmp_path / 'cli.mcap')])
    said = capsys.readouterr().err
    if code == 2:  # a bag bagfault refuses (a type it cannot write): refused alike without the leading copy
        with pytest.raises(api.BagfaultError):
            run_alone(recorded, tmp_path / 'late.yaml', tmp_path / 'api.mcap', monkeypatch)
        assert sorted(p.name for p in tmp_path.iterdir()) == ['late.yaml'], said
        return
    assert code == 0, said
    run_alone(recorded, tmp_path / 'late.yaml', tmp_path / 'api.mcap', monkeypatch)
    assert (tmp_path / 'cli.mcap').read_bytes() == (tmp_path / 'api.mcap').read_bytes()


@pytest.mark.parametrize('layout', [
    'injectors:\n  - {id: imu, type: imu, topic: {input_topic: imu, output_topic: imu}}\n',
    'injector: {id: imu, type: imu, input_topic: /imu, output_topic: /imu}\n',
    'injector:\n  id: imu\n  type: imu\n  topic: {input_topic: /imu, output_topic: /imu}\n',
])
def test_every_anchor_layout_gives_the_guess_of_the_flat_one(bag: Path, layout: str) -> None:
    faults = IMU[IMU.index('faults:'):]
    assert guess(bag, layout + faults) == guess(bag, IMU)
    assert 0 < sum(p.length for p in guess(bag, IMU)) < bag.stat().st_size / 2
