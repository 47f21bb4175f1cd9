"""The contract of the differential tests: one input, bagfault's `run` with a pass-through scenario, and the
count an independent reader finds in the input. Either exit 0 with exactly that many messages in the output
(read back indexed and streamed, CRCs checked), or exit 2 with one `bagfault: error:` line and no output.
Never a traceback, an internal error, a hang, a changed input or a leftover temporary file.
"""

from __future__ import annotations

import bz2
import contextlib
import hashlib
import io
import signal
import struct
from typing import TYPE_CHECKING, Literal

import lz4.frame
from mcap.reader import make_reader
from mcap.records import Chunk, Message, MessageIndex
from mcap.stream_reader import StreamReader, breakup_chunk

from bagfault.cli import main

if TYPE_CHECKING:
    from collections.abc import Iterator
    from pathlib import Path

    import pytest

SCENARIO = 'injectors: []\nfaults: []\n'  # every message passes through as it is
SECONDS = 20
Verdict = Literal['written', 'refused']
Outcome = tuple[Verdict, str]  # and the run's stderr


class Hang(BaseException):
    """A run went past its time (a BaseException, so no `except Exception` in bagfault swallows it)."""


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


def streamed_counts(data: bytes) -> tuple[int, int] | None:
    """(Message records, those inside chunks) of an MCAP by the `mcap` library's streamed reader: every record
    in file order, top level and inside chunks, chunk CRCs checked; None when it cannot read to the end."""
    total = chunked = 0
    try:
        for record in StreamReader(io.BytesIO(data), validate_crcs=True, emit_chunks=True).records:
            if isinstance(record, Chunk):
                found = sum(isinstance(r, Message) for r in breakup_chunk(record, validate_crc=True))
                total, chunked = total + found, chunked + found
            elif isinstance(record, Message):
                total += 1
    except Exception:
        return None
    return total, chunked


def streamed_count(data: bytes) -> int | None:
    """Message records of an MCAP, wherever they sit, by the streamed reader; None when it cannot read it."""
    counts = streamed_counts(data)
    return None if counts is None else counts[0]


def declared_counts(data: bytes) -> dict[str, int]:
    """What an MCAP says it holds, read by the `mcap` library: its Statistics record's message count and the
    entries of its message indexes (where it has them)."""
    out: dict[str, int] = {}
    try:
        summary = make_reader(io.BytesIO(data)).get_summary()
        if summary is not None and summary.statistics is not None:
            out['statistics'] = summary.statistics.message_count
    except Exception:
        pass
    try:
        entries = [len(r.records) for r in StreamReader(io.BytesIO(data), skip_magic=False, emit_chunks=True).records
                   if isinstance(r, MessageIndex)]
        if entries:
            out['message indexes'] = sum(entries)
    except Exception:
        pass
    return out


def output_count(path: Path) -> tuple[int, dict[str, int]]:
    """Messages in bagfault's output, by the `mcap` library's indexed reader and its streamed reader (which
    agree), and what the output declares."""
    data = path.read_bytes()
    indexed = sum(1 for _ in make_reader(io.BytesIO(data), validate_crcs=True).iter_messages())
    assert streamed_counts(data) == (indexed, indexed), f'{path}: its index and its records disagree'
    return indexed, declared_counts(data)


def digest(path: Path) -> str:
    files = sorted(p for p in path.rglob('*') if p.is_file()) if path.is_dir() else [path]
    hasher = hashlib.sha256()
    for file in files:
        hasher.update(file.name.encode() + file.read_bytes())
    return hasher.hexdigest()


def run(case: Path, folder: Path, extra: list[str],
        capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str, Path]:
    """`bagfault run` on the case; (exit code, stdout, stderr, output path). Asserts what holds for every run."""
    scenario = folder / 'scenario.yaml'
    scenario.write_text(SCENARIO)
    out = folder / 'out.mcap'
    before = digest(case)
    capsys.readouterr()
    try:
        with deadline(SECONDS):
            code = main(['run', str(scenario), str(case), '-o', str(out), *extra])
    except Hang:
        raise AssertionError(f'{" ".join(extra)}: hangs') from None
    said, err = capsys.readouterr()
    assert digest(case) == before, 'the input was changed'
    assert 'internal error' not in err and 'Traceback' not in err, err
    assert not list(folder.glob('.*.partial')), 'a temporary file was left'
    return code, said, err, out


def judge(case: Path, folder: Path, expected: int | None, extra: list[str], capsys: pytest.CaptureFixture[str], *,
          indexes_lie: bool = False) -> Outcome:
    """The contract for one run; `expected` None when the independent reader cannot read the input. The output
    declares what it holds, with one documented exception: the chunk copy (no --verify) copies chunks unread
    and trusts their message indexes, so an input whose indexes lie about a chunk's content (`indexes_lie`)
    gives an output with the same lie, and the run's summary says how many chunks went unverified."""
    code, said, err, out = run(case, folder, extra, capsys)
    flags = ' '.join(extra) or '(default)'
    if code == 2:
        lines = [line for line in err.splitlines() if not line.startswith('warning:')]
        assert len(lines) == 1 and lines[0].startswith('bagfault: error: '), f'{flags}: {err}'
        assert not out.exists(), f'{flags}: exit 2 with an output'
        return 'refused', err
    assert code == 0, f'{flags}: exit {code}: {err}'
    assert expected is not None, f'{flags}: exit 0 on an input the independent reader cannot read: {err}'
    found, declared = output_count(out)
    out.unlink()
    assert found == expected, f'{flags}: exit 0 with {found} messages; the input holds {expected}: {err}'
    if set(declared.values()) - {found}:
        copied = indexes_lie and not {'--verify', '--no-chunk-copy'} & set(extra) and 'unverified' in said
        assert copied, f'{flags}: the output holds {found} messages and declares {declared}: {said}{err}'
    return 'written', err


def ros1_walk_count(data: bytes) -> int | None:
    """Message data records of a ROS 1 bag, wherever they sit: every record walked from the version line on,
    every chunk decompressed and walked (no index is followed: rosbags follows the bag's index and chunk
    count, and so agrees with their lies); None when a record does not parse or runs past the end."""
    if not data.startswith(b'#ROSBAG V2.0\n'):
        return None
    try:
        return _ros1_count(memoryview(data)[13:], top=True)
    except (struct.error, ValueError, OSError, KeyError, EOFError):
        return None


def _ros1_count(data: memoryview, *, top: bool) -> int:
    count = at = 0
    while at < len(data):
        (length,) = struct.unpack_from('<I', data, at)
        header = bytes(data[at + 4:at + 4 + length])
        (size,) = struct.unpack_from('<I', data, at + 4 + length)
        body = data[at + 8 + length:at + 8 + length + size]
        if len(header) != length or len(body) != size:
            raise ValueError('a record runs past the end')
        values = {}
        pos = 0
        while pos < len(header):
            (field_length,) = struct.unpack_from('<I', header, pos)
            if pos + 4 + field_length > len(header) or b'=' not in header[pos + 4:pos + 4 + field_length]:
                raise ValueError('a header field runs past its header')
            name, _, value = header[pos + 4:pos + 4 + field_length].partition(b'=')
            values[name] = value
            pos += 4 + field_length
        op = values[b'op']
        if op == b'\x02':
            count += 1
        elif op == b'\x05' and top:
            compression = values[b'compression']
            raw = bytes(body)
            inner = bz2.decompress(raw) if compression == b'bz2' else lz4.frame.decompress(raw) \
                if compression == b'lz4' else raw
            if compression not in (b'none', b'bz2', b'lz4') or len(inner) != struct.unpack('<I', values[b'size'])[0]:
                raise ValueError('a chunk that does not decompress to its size')
            count += _ros1_count(memoryview(inner), top=False)
        at += 8 + length + size
    return count
