"""A leading copy speeds a run up or costs it time, never a byte: right, wrong and far-fetched guesses alike.

Each case runs the scenario once with no leading copy (the reference) and
once with a `LeadingCopy` of guesses made here by hand (in place of the guess); the two outputs
must be the same bytes. Where the guess is right, the run's own copy thread
must not copy those bytes again. What a right guess is comes from the
reference output itself: the input chunks it holds byte for byte, from the
first chunk on, found by comparing bytes (not by asking bagfault).
"""

from __future__ import annotations

import errno
import os
import time
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader

from bagfault import api
from bagfault.demo.workloads import write_bag
from bagfault.engine import lead as guesses
from bagfault.engine import offline
from bagfault.errors import EngineError
from bagfault.io import file_copy
from bagfault.io.leading_copy import LeadingCopy, Piece
from bagfault.io.mcap_writer import McapWriter
from bagfault.io.outputs import PartialFile
from bagfault.scenario import parse_scenario

WINDOW = """
injectors:
  - {id: imu, type: imu, input_topic: /imu, output_topic: /imu}
faults:
  - {id: bias, injector_id: imu, start: 1.2, duration: 0.4, config: {angular_velocity_z_bias: 0.05}}
"""
DROP = """
injectors:
  - {id: pc, type: topic, input_topic: /points, output_topic: /points}
faults:
  - {id: gone, injector_id: pc, active_on_startup: true, config: {drop_probability: 1.0}}
"""


@pytest.fixture(scope='module')
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp('lead') / 'sensor.mcap'
    write_bag(path, 'sensor-heavy', 3.0)
    return path


def chunk_spans(path: Path) -> list[tuple[int, int]]:
    """(offset, length of the chunk and its message indexes) of every chunk, in file order (mcap library)."""
    with path.open('rb') as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None
    return sorted((c.chunk_start_offset, c.chunk_length + c.message_index_length) for c in summary.chunk_indexes)


def copied_prefix(source: Path, output: Path) -> tuple[int, int, int]:
    """(input offset, output offset, length) of the input's leading chunks that the output holds byte for byte
    and in a row from its own first chunk."""
    data, out = source.read_bytes(), output.read_bytes()
    start, target = chunk_spans(source)[0][0], chunk_spans(output)[0][0]
    length = 0
    for offset, size in chunk_spans(source):
        if offset != start + length or data[offset:offset + size] != out[target + length:target + length + size]:
            break
        length += size
    return start, target, length


class CopyCount:
    """Bytes the run's own copy thread copies (McapWriter._copy_range)."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        self.bytes = 0
        original = McapWriter._copy_range

        def counted(writer: McapWriter, fd: int, offset: int, length: int, at: int) -> None:
            self.bytes += length
            original(writer, fd, offset, length, at)

        monkeypatch.setattr(McapWriter, '_copy_range', counted)


@pytest.fixture(params=['prompt', 'late'])
def pace(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> str:
    """'late': the leading copy copies nothing until the writer stops it (or it is closed), the slowest it can
    be; so every byte the writer writes itself in its range would be overwritten unless the writer waits."""
    if request.param == 'late':
        original_copy, original_stop = LeadingCopy._copy, LeadingCopy.stop
        asked: set[int] = set()

        def late_copy(lead: LeadingCopy) -> None:
            while id(lead) not in asked and lead._limit == lead.end:
                time.sleep(0.001)
            original_copy(lead)

        def stop(lead: LeadingCopy, keep: int) -> None:
            asked.add(id(lead))
            original_stop(lead, keep)

        monkeypatch.setattr(LeadingCopy, '_copy', late_copy)
        monkeypatch.setattr(LeadingCopy, 'stop', stop)
    return str(request.param)


def reference(bag: Path, text: str, out: Path, monkeypatch: pytest.MonkeyPatch) -> Any:
    with monkeypatch.context() as patch:
        patch.setattr(guesses, 'start_lead', lambda *args, **kwargs: None)
        return api.run(parse_scenario(text), [bag], out, seed=3)


def with_lead(bag: Path, text: str, out: Path, pieces: list[Piece], monkeypatch: pytest.MonkeyPatch) -> Any:
    """The run with a leading copy of `pieces` (the guess made so)."""
    with monkeypatch.context() as patch:
        patch.setattr(guesses, 'leading_pieces', lambda *args, **kwargs: pieces)
        return api.run(parse_scenario(text), [bag], out, seed=3)


def test_a_right_guess_is_taken_and_not_copied_again(bag: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                      pace: str) -> None:
    count = CopyCount(monkeypatch)
    reference(bag, WINDOW, tmp_path / 'reference.mcap', monkeypatch)
    copied_by_run = count.bytes
    source, target, length = copied_prefix(bag, tmp_path / 'reference.mcap')
    assert 0 < length < copied_by_run  # chunks before the window, and after it
    count.bytes = 0
    with_lead(bag, WINDOW, tmp_path / 'lead.mcap', [Piece(source, target, length)], monkeypatch)
    assert (tmp_path / 'lead.mcap').read_bytes() == (tmp_path / 'reference.mcap').read_bytes()
    assert count.bytes == copied_by_run - length
    assert sorted(p.name for p in tmp_path.iterdir()) == ['lead.mcap', 'reference.mcap']


@pytest.mark.parametrize('guess', ['everything', 'read one byte off', 'placed one byte off', 'past the input',
                                   'too far and output smaller'])
def test_a_wrong_guess_costs_no_byte(bag: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, guess: str,
                                     pace: str) -> None:
    text = DROP if guess == 'too far and output smaller' else WINDOW
    reference(bag, text, tmp_path / 'reference.mcap', monkeypatch)
    size = bag.stat().st_size
    start, target = chunk_spans(bag)[0][0], chunk_spans(tmp_path / 'reference.mcap')[0][0]
    pieces = {
        'everything': [Piece(start, target, size - start)],  # the window's chunks too, and the summary
        'read one byte off': [Piece(start + 1, target, size - start - 1)],
        'placed one byte off': [Piece(start, target + 1, size - start)],
        'past the input': [Piece(start, target, 3 * size), Piece(2 * size, 4 * size, 100)],
        'too far and output smaller': [Piece(start, target, size - start)],  # no chunk of DROP is copied
    }[guess]
    if guess == 'too far and output smaller':
        assert (tmp_path / 'reference.mcap').stat().st_size < target + size - start
    result = with_lead(bag, text, tmp_path / 'lead.mcap', pieces, monkeypatch)
    assert result.stats.output_messages > 0
    assert (tmp_path / 'lead.mcap').read_bytes() == (tmp_path / 'reference.mcap').read_bytes()
    assert sorted(p.name for p in tmp_path.iterdir()) == ['lead.mcap', 'reference.mcap']


def test_a_closed_lead_leaves_its_copy_to_the_file_s_owner_which_removes_it_unpublished(
        bag: Path, tmp_path: Path) -> None:
    out = tmp_path / 'out.mcap'
    with PartialFile(out) as file:
        with LeadingCopy(bag, [Piece(0, 0, bag.stat().st_size)], file) as copy:
            copy.stop(copy.end)
        assert file.partial.parent == tmp_path and file.partial.name.startswith('.out.mcap.')
        assert file.partial.read_bytes() == bag.read_bytes()
    assert list(tmp_path.iterdir()) == []


def test_a_failed_run_removes_the_file_its_leading_copy_filled(bag: Path, tmp_path: Path,
                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    def fails(*args: object, **kwargs: object) -> None:
        raise EngineError('the run failed after the leading copy began')

    monkeypatch.setattr(offline, 'replay', fails)
    out = tmp_path / 'out.mcap'
    start, size = chunk_spans(bag)[0][0], bag.stat().st_size
    with pytest.raises(EngineError):
        with_lead(bag, WINDOW, out, [Piece(start, 8000, size - start)], monkeypatch)
    assert list(tmp_path.iterdir()) == []


def test_bytes_go_through_user_space_where_the_kernel_cannot_copy(tmp_path: Path,
                                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    def cross_device(*args: object) -> int:
        raise OSError(errno.EXDEV, 'Invalid cross-device link')

    source, target = tmp_path / 'source', tmp_path / 'target'
    source.write_bytes(bytes(range(256)) * 40_000)  # 10 MB, more than one read
    monkeypatch.setattr(os, 'copy_file_range', cross_device)
    with source.open('rb') as src, target.open('wb') as dst:
        assert file_copy.copy_range(src.fileno(), dst.fileno(), 1000, 9_000_000, 7, in_kernel=True) is False
    assert target.read_bytes() == bytes(7) + source.read_bytes()[1000:9_001_000]


def test_a_slow_open_of_the_input_holds_the_copy_until_it_ends(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """An open that takes longer than SLOW_OPEN reads from a cold disk: the copy does not share the disk with it
    (between parts it waits for the open to end), then copies the rest."""
    from bagfault.io import leading_copy

    parts: list[int] = []

    def slow_part(source: int, target: int, offset: int, length: int, at: int, *, in_kernel: bool = True) -> bool:
        parts.append(at)
        time.sleep(0.005)
        return file_copy.copy_range(source, target, offset, length, at, in_kernel=in_kernel)

    monkeypatch.setattr(leading_copy, 'copy_range', slow_part)
    monkeypatch.setattr(leading_copy, 'PART', 1000)
    monkeypatch.setattr(leading_copy, 'SLOW_OPEN', 0.05)
    source = tmp_path / 'input.bin'
    source.write_bytes(bytes(range(256)) * 800)  # 205 parts of 1000 bytes: a second at 5 ms each
    with PartialFile(tmp_path / 'out.bin') as file, LeadingCopy(source, [Piece(0, 0, source.stat().st_size)],
                                                                 file) as copy:
        with copy.opening():
            time.sleep(0.2)
            held = len(parts)
            time.sleep(0.3)
            assert len(parts) == held < 205  # nothing copied from 0.2 s to 0.5 s of a slow open
        copy.stop(copy.end)
        assert len(parts) == 205
        assert os.pread(file.fd, source.stat().st_size, 0) == source.read_bytes()
