"""Differential tests of the rule "every message record the file holds is in the output, or the run refuses":
generated, record-aware edits of small bags (Hypothesis, shrinking to the smallest failing edit list), each run
through `bagfault run` on every reading path and compared with an independent reader of the edited input.

A few hundred cases run in the default suite; before a release, `BAGFAULT_RELEASE_EXAMPLES=5000 pytest -n 2
tests/test_differential.py` runs thousands per test (random, not the suite's fixed draw; minutes).
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import sqlite3
import tempfile
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Literal

import pytest
import yaml
from hypothesis import HealthCheck, Phase, event, given, settings
from hypothesis import strategies as st
from mcap.records import Channel, Message
from mcap.stream_reader import StreamReader
from support import mcap_records as m
from support import ros1_records as r1
from support.differential import (
    declared_counts,
    judge,
    output_count,
    ros1_walk_count,
    run,
    streamed_count,
    streamed_counts,
)

EditKind = Literal['inner-delete', 'inner-duplicate', 'inner-move', 'inner-unknown', 'message-out', 'insert-message',
                   'delete', 'duplicate', 'move', 'insert-unknown', 'data-end-at', 'chunk-duplicate', 'chunk-move']
INNER: tuple[EditKind, ...] = ('inner-delete', 'inner-duplicate', 'inner-move', 'inner-unknown', 'message-out',
                               'chunk-duplicate', 'chunk-move')
VALID: tuple[EditKind, ...] = ('inner-delete', 'inner-duplicate', 'inner-move', 'message-out', 'insert-message',
                               'insert-unknown', 'chunk-duplicate', 'chunk-move')  # with honest indexes and summary, a file the spec allows
PATHS = [[], ['--no-chunk-copy'], ['--verify']]  # chunks copied unread; read record by record; copied, then read
RELEASE = os.environ.get('BAGFAULT_RELEASE_EXAMPLES')


@dataclass(frozen=True)
class Edit:
    """One edit of the data section; positions are taken modulo what is there, so every draw applies."""

    kind: EditKind
    at: int = 0
    inner: int = 0
    to: int = 0
    stale_index: bool = False  # an edit inside a chunk leaves its message indexes describing the old content


@dataclass(frozen=True)
class McapCase:
    """A generated MCAP: the source's shape, the edits, the summary rule and the bytes damage."""

    compression: Literal['', 'zstd'] = ''
    crc: bool = True
    per_chunk: int = 5
    chunks: int = 4
    edits: tuple[Edit, ...] = ()
    summary: m.SummaryRule = 'honest'
    tail: bytes = b''
    cut_back: int | None = None  # the file loses this many bytes at its end

    def bytes(self) -> bytes:
        file = m.source(per_chunk=self.per_chunk, chunks=self.chunks, compression=self.compression, crc=self.crc)
        for edit in self.edits:
            apply(file, edit)
        file.summary = self.summary
        file.tail = self.tail
        if self.cut_back is not None:
            file.cut = max(len(m.MAGIC), len(file.write()) - self.cut_back)
        return file.write()


def apply(file: m.McapFile, edit: Edit) -> None:
    """One edit, in place."""
    items = file.items
    if edit.kind in INNER:
        chunks = [number for number, item in enumerate(items) if isinstance(item, m.Chunk)]
        if not chunks:
            return
        where = chunks[edit.at % len(chunks)]
        chunk = items[where]
        assert isinstance(chunk, m.Chunk)
        if edit.kind == 'chunk-duplicate':
            items.insert(where, chunk)
            return
        if edit.kind == 'chunk-move':  # to another place among the chunks
            items.insert(chunks[edit.to % len(chunks)], items.pop(where))
            return
        records = list(chunk.records)
        if not records:
            return
        pick = edit.inner % len(records)
        if edit.kind == 'inner-delete':
            records.pop(pick)
        elif edit.kind == 'inner-duplicate':
            records.insert(pick, records[pick])
        elif edit.kind == 'inner-move':
            records.insert(edit.to % len(records), records.pop(pick))
        elif edit.kind == 'inner-unknown':
            records[pick] = m.Raw(m.UNKNOWN, records[pick].body)
        else:  # message-out: a Message record leaves its chunk for the top level
            moved = records.pop(pick)
            items[where] = m.edited_chunk(chunk, records, stale_index=edit.stale_index)
            items.insert(edit.to % (len(items) + 1), moved)
            return
        items[where] = m.edited_chunk(chunk, records, stale_index=edit.stale_index)
    elif edit.kind == 'insert-message':
        body = m.message_body(edit.inner % 2 + 1, 9999, 10**9 + edit.to * 10**6, m.string_cdr('inserted'))
        items.insert(edit.at % (len(items) + 1), m.Raw(m.MESSAGE, body))
    elif edit.kind == 'insert-unknown':
        items.insert(edit.at % (len(items) + 1), m.Raw(m.UNKNOWN, b'u' * (edit.inner % 24)))
    elif not items:
        return
    elif edit.kind == 'delete':
        items.pop(edit.at % len(items))
    elif edit.kind == 'duplicate':
        items.insert(edit.at % len(items), items[edit.at % len(items)])
    elif edit.kind == 'move':
        items.insert(edit.to % len(items), items.pop(edit.at % len(items)))
    else:  # data-end-at: the DataEnd record moves (early, it hides what follows from a reader that stops there)
        ends = [number for number, item in enumerate(items) if isinstance(item, m.Raw) and item.opcode == m.DATA_END]
        if ends:
            items.insert(edit.to % len(items), items.pop(ends[0]))


def edits(kinds: tuple[EditKind, ...]) -> st.SearchStrategy[Edit]:
    small = st.integers(0, 40)
    return st.builds(Edit, st.sampled_from(kinds), small, small, small, st.booleans())


def mcap_cases(*, valid: bool) -> st.SearchStrategy[McapCase]:
    shape = {'compression': st.sampled_from(['', 'zstd']), 'crc': st.booleans(), 'per_chunk': st.integers(1, 5),
             'chunks': st.integers(1, 4)}
    if valid:
        return st.builds(McapCase, **shape, edits=st.lists(edits(VALID), max_size=3).map(
            lambda found: tuple(replace(e, stale_index=False) for e in found)),
                         summary=st.sampled_from(['honest', 'none']))
    kinds: tuple[EditKind, ...] = EditKind.__args__  # type: ignore[attr-defined]
    return st.builds(McapCase, **shape, edits=st.lists(edits(kinds), max_size=3).map(tuple),
                     summary=st.sampled_from(['honest', 'chunks', 'stale', 'none']),
                     tail=st.one_of(st.just(b''), st.binary(min_size=1, max_size=12)),
                     cut_back=st.one_of(st.none(), st.none(), st.none(), st.integers(1, 200)))


def generated(default: int) -> settings:
    """The suite's fixed draw of `default` examples, or the release run's random thousands."""
    return settings(max_examples=int(RELEASE) if RELEASE else default, deadline=None, derandomize=not RELEASE,
                    database=None, phases=[p for p in Phase if p != Phase.explain], suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


def check_mcap(case: McapCase, capsys: pytest.CaptureFixture[str]) -> tuple[int | None, list[str]]:
    """Every reading path on the case's bytes; (the independent count, each path's verdict). A path that reads
    chunk contents says so when what the file declares (its Statistics, its message indexes) disagrees with
    what it holds; the chunk copy reads indexes, not contents, and is checked by its output instead."""
    data = case.bytes()
    counts = streamed_counts(data)
    expected = None if counts is None else counts[0]
    truth = {} if counts is None else {'statistics': counts[0], 'message indexes': counts[1]}
    lies = {what: count for what, count in declared_counts(data).items() if count != truth.get(what)}
    verdicts = []
    with tempfile.TemporaryDirectory() as name:
        folder = Path(name)
        path = folder / 'case.mcap'
        path.write_bytes(data)
        for extra in PATHS:
            verdict, err = judge(path, folder, expected, extra, capsys, indexes_lie='message indexes' in lies)
            if verdict == 'written' and lies and extra:
                assert 'warning' in err, f'{extra}: {expected} messages, the file declares {lies}; not said: {err}'
            verdicts.append(verdict)
    return expected, verdicts


@generated(300)
@given(case=mcap_cases(valid=False))
def test_every_mcap_message_record_is_written_or_refused(case: McapCase, capsys: pytest.CaptureFixture[str]) -> None:
    """Any edit, lie or damage: exit 0 with exactly the messages the streamed reader finds, or one line, exit 2."""
    expected, verdicts = check_mcap(case, capsys)
    event(f'readable: {expected is not None}, verdicts: {verdicts}')


@generated(60)
@given(case=mcap_cases(valid=True))
def test_every_valid_mcap_is_written_whole(case: McapCase, capsys: pytest.CaptureFixture[str]) -> None:
    """Top-level messages, unknown records, reordered or duplicated messages, no summary: all allowed by the MCAP
    specification, so never refused, and every message written."""
    expected, verdicts = check_mcap(case, capsys)
    assert expected is not None  # by construction: the streamed reader reads every valid file
    assert verdicts == ['written'] * len(PATHS)


# -- ROS 1 ------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Ros1Case:
    """A generated ROS 1 bag: the source's shape, the edits, the index rule and the bytes damage."""

    compression: Literal['none', 'bz2'] = 'none'
    per_chunk: int = 5
    chunks: int = 3
    edits: tuple[Edit, ...] = ()
    index: r1.IndexRule = 'honest'
    chunk_count_lie: int = 0
    tail: bytes = b''
    cut_back: int | None = None

    def bytes(self) -> tuple[bytes, int]:
        """The bag, and how many of its bytes can hold records (the rest is the appended tail)."""
        bag = r1.source(per_chunk=self.per_chunk, chunks=self.chunks, compression=self.compression)
        for edit in self.edits:
            apply_ros1(bag, edit)
        bag.index, bag.chunk_count_lie = self.index, self.chunk_count_lie
        whole = len(bag.write())
        if self.cut_back is not None:
            bag.cut = max(len(r1.VERSION), whole - self.cut_back)
        bag.tail = self.tail
        data = bag.write()
        return data, min(whole, len(data))


def apply_ros1(bag: r1.Bag, edit: Edit) -> None:
    """One edit of a bag's data section, in place (as `apply` for MCAP)."""
    items = bag.items
    if edit.kind in INNER:
        chunks = [number for number, item in enumerate(items) if isinstance(item, r1.Chunk)]
        if not chunks:
            return
        where = chunks[edit.at % len(chunks)]
        chunk = items[where]
        assert isinstance(chunk, r1.Chunk)
        if edit.kind == 'chunk-duplicate':
            items.insert(where, chunk)
            return
        if edit.kind == 'chunk-move':
            items.insert(chunks[edit.to % len(chunks)], items.pop(where))
            return
        records = list(chunk.records)
        if not records:
            return
        pick = edit.inner % len(records)
        if edit.kind == 'inner-delete':
            records.pop(pick)
        elif edit.kind == 'inner-duplicate':
            records.insert(pick, records[pick])
        elif edit.kind == 'inner-move':
            records.insert(edit.to % len(records), records.pop(pick))
        elif edit.kind == 'inner-unknown':
            records[pick] = replace(records[pick], op=r1.UNKNOWN)
        else:
            moved = records.pop(pick)
            items[where] = r1.edited_chunk(chunk, records, stale_index=edit.stale_index)
            items.insert(edit.to % (len(items) + 1), moved)
            return
        items[where] = r1.edited_chunk(chunk, records, stale_index=edit.stale_index)
    elif edit.kind == 'insert-message':
        items.insert(edit.at % (len(items) + 1), r1.message_record(edit.inner % 2, 10**9 + edit.to * 10**6, 'new'))
    elif edit.kind == 'insert-unknown':
        items.insert(edit.at % (len(items) + 1), r1.Rec(r1.UNKNOWN, b'', b'u' * (edit.inner % 24)))
    elif not items or edit.kind == 'data-end-at':
        return
    elif edit.kind == 'delete':
        items.pop(edit.at % len(items))
    elif edit.kind == 'duplicate':
        items.insert(edit.at % len(items), items[edit.at % len(items)])
    else:
        items.insert(edit.to % len(items), items.pop(edit.at % len(items)))


ROS1_VALID: tuple[EditKind, ...] = ('inner-delete', 'inner-duplicate', 'inner-move', 'chunk-duplicate', 'chunk-move')


def ros1_cases(*, valid: bool) -> st.SearchStrategy[Ros1Case]:
    shape = {'compression': st.sampled_from(['none', 'bz2']), 'per_chunk': st.integers(1, 5),
             'chunks': st.integers(1, 3)}
    if valid:
        return st.builds(Ros1Case, **shape, edits=st.lists(edits(ROS1_VALID), max_size=3).map(
            lambda found: tuple(replace(e, stale_index=False) for e in found)))
    kinds: tuple[EditKind, ...] = tuple(k for k in EditKind.__args__ if k != 'data-end-at')  # type: ignore[attr-defined]
    return st.builds(Ros1Case, **shape, edits=st.lists(edits(kinds), max_size=3).map(tuple),
                     index=st.sampled_from(['honest', 'stale', 'none']),
                     chunk_count_lie=st.sampled_from([0, 0, 0, -1, 1]),
                     tail=st.one_of(st.just(b''), st.binary(min_size=1, max_size=12)),
                     cut_back=st.one_of(st.none(), st.none(), st.none(), st.integers(1, 300)))


def check_ros1(case: Ros1Case, capsys: pytest.CaptureFixture[str]) -> tuple[int | None, str]:
    """The case's bag through `bagfault run`; (the walk's count, the verdict)."""
    data, extent = case.bytes()
    expected = ros1_walk_count(data[:extent])
    with tempfile.TemporaryDirectory() as name:
        folder = Path(name)
        path = folder / 'case.bag'
        path.write_bytes(data)
        verdict, _ = judge(path, folder, expected, [], capsys)
    return expected, verdict


@generated(250)
@given(case=ros1_cases(valid=False))
def test_every_ros1_message_record_is_written_or_refused(case: Ros1Case, capsys: pytest.CaptureFixture[str]) -> None:
    """Any edit, lie or damage of a ROS 1 bag: exit 0 with exactly the message records a walk of every chunk
    finds, or one line and exit 2 (a lying index or chunk_count is refused, never followed in silence)."""
    expected, verdict = check_ros1(case, capsys)
    event(f'readable: {expected is not None}, verdict: {verdict}')


@generated(60)
@given(case=ros1_cases(valid=True))
def test_every_valid_ros1_bag_is_written_whole(case: Ros1Case, capsys: pytest.CaptureFixture[str]) -> None:
    """Messages reordered, removed or repeated inside chunks, chunks repeated or reordered, the index honest:
    a bag rosbag could have written, so never refused, and every message written."""
    expected, verdict = check_ros1(case, capsys)
    assert expected is not None and verdict == 'written'


# -- rosbag2 folders ----------------------------------------------------------------------------------------

MetadataEdit = Literal['count', 'topic-count', 'unlist', 'list-missing', 'list-twice', 'reorder']
RowEdit = Literal['delete', 'duplicate', 'unknown-topic', 'retime']


@dataclass(frozen=True)
class Rosbag2Case:
    """A generated rosbag2 folder: one or two MCAP storage files (the first edited as an McapCase) or one
    sqlite3 file (rows edited), and metadata.yaml edits (counts that lie, files listed or not)."""

    storage: Literal['mcap', 'sqlite3'] = 'mcap'
    files: int = 1
    first: McapCase = McapCase()
    rows: tuple[tuple[RowEdit, int], ...] = ()
    metadata: tuple[tuple[MetadataEdit, int], ...] = ()

    def write(self, folder: Path) -> None:
        """The folder's files; metadata.yaml describes the storage files as written, then takes the edits."""
        names = [f'bag_{n}.{"mcap" if self.storage == "mcap" else "db3"}' for n in range(self.files)]
        counts: dict[str, int] = {}
        for number, name in enumerate(names):
            if self.storage == 'sqlite3':
                write_sqlite(folder / name, self.rows)
                counts = {'/topic1': 10, '/topic2': 10}
                continue
            case = self.first if number == 0 else McapCase()
            (folder / name).write_bytes(case.bytes())
            source = McapCase(per_chunk=case.per_chunk, chunks=case.chunks) if number == 0 else case
            total = source.per_chunk * source.chunks
            for topic, share in (('/topic1', (total + 1) // 2), ('/topic2', total // 2)):
                counts[topic] = counts.get(topic, 0) + share
        listed = list(names)
        total = sum(counts.values())
        for edit, amount in self.metadata:
            if edit == 'count':
                total += amount % 5 - 2 or 1
            elif edit == 'topic-count':
                counts['/topic1'] += amount % 5 - 2 or 1
            elif edit == 'unlist' and len(listed) > 1:
                listed.pop(amount % len(listed))
            elif edit == 'list-missing':
                listed.append('gone.mcap')
            elif edit == 'list-twice' and listed:
                listed.append(listed[amount % len(listed)])
            elif edit == 'reorder':
                listed.reverse()
        topics = [{'message_count': count, 'topic_metadata': {
            'name': topic, 'type': 'std_msgs/msg/String', 'serialization_format': 'cdr', 'offered_qos_profiles': [],
            'type_description_hash': ''}} for topic, count in counts.items()]
        info = {'version': 8, 'storage_identifier': self.storage, 'relative_file_paths': listed,
                'duration': {'nanoseconds': 10**9}, 'starting_time': {'nanoseconds_since_epoch': 10**9},
                'message_count': total, 'topics_with_message_count': topics, 'compression_format': '',
                'compression_mode': '', 'ros_distro': 'jazzy', 'custom_data': {}, 'files': []}
        (folder / 'metadata.yaml').write_text(yaml.safe_dump({'rosbag2_bagfile_information': info}))


def write_sqlite(path: Path, edits: tuple[tuple[RowEdit, int], ...]) -> None:
    """A rosbag2 sqlite3 file (schema version 4, as Jazzy writes it) of 20 std_msgs/String messages on two
    topics, then row edits: a row deleted or duplicated, a row of a topic id no topic has, a timestamp moved."""
    with contextlib.closing(sqlite3.connect(path)) as db, db:
        db.executescript("""
            CREATE TABLE schema(schema_version INTEGER PRIMARY KEY, ros_distro TEXT NOT NULL);
            CREATE TABLE metadata(id INTEGER PRIMARY KEY, metadata_version INTEGER NOT NULL, metadata TEXT NOT NULL);
            CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL,
                serialization_format TEXT NOT NULL, offered_qos_profiles TEXT NOT NULL,
                type_description_hash TEXT NOT NULL);
            CREATE TABLE message_definitions(id INTEGER PRIMARY KEY, topic_type TEXT NOT NULL, encoding TEXT NOT NULL,
                encoded_message_definition TEXT NOT NULL, type_description_hash TEXT NOT NULL);
            CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL, timestamp INTEGER NOT NULL,
                data BLOB NOT NULL);
            CREATE INDEX timestamp_idx ON messages (timestamp ASC);
            INSERT INTO schema VALUES (4, 'jazzy');
            INSERT INTO message_definitions VALUES (1, 'std_msgs/msg/String', 'ros2msg', 'string data', '');
        """)
        db.executemany('INSERT INTO topics VALUES (?, ?, ?, ?, ?, ?)',
                       [(n, f'/topic{n}', 'std_msgs/msg/String', 'cdr', '', '') for n in (1, 2)])
        db.executemany('INSERT INTO messages VALUES (?, ?, ?, ?)',
                       [(k + 1, k % 2 + 1, 10**9 + k * 10**7, m.string_cdr(f'm{k}')) for k in range(20)])
        for edit, pick in edits:
            ids = [row[0] for row in db.execute('SELECT id FROM messages ORDER BY id')]
            if not ids:
                return
            row = ids[pick % len(ids)]
            if edit == 'delete':
                db.execute('DELETE FROM messages WHERE id = ?', (row,))
            elif edit == 'duplicate':
                db.execute('INSERT INTO messages (topic_id, timestamp, data) SELECT topic_id, timestamp, data '
                           'FROM messages WHERE id = ?', (row,))
            elif edit == 'unknown-topic':
                db.execute('UPDATE messages SET topic_id = 9 WHERE id = ?', (row,))
            else:
                db.execute('UPDATE messages SET timestamp = ? WHERE id = ?', (10**9 + pick * 10**6, row))


def storage_count(path: Path) -> int | None:
    """Messages of one storage file read on its own: the streamed MCAP reader, or SQLite counting rows."""
    if path.suffix == '.mcap':
        return streamed_count(path.read_bytes())
    try:
        with contextlib.closing(sqlite3.connect(f'file:{path}?mode=ro', uri=True)) as db:
            return int(db.execute('SELECT COUNT(*) FROM messages').fetchone()[0])
    except sqlite3.Error:
        return None


def rosbag2_cases() -> st.SearchStrategy[Rosbag2Case]:
    kinds: tuple[EditKind, ...] = EditKind.__args__  # type: ignore[attr-defined]
    first = st.builds(McapCase, per_chunk=st.integers(1, 5), chunks=st.integers(1, 3),
                      edits=st.lists(edits(kinds), max_size=2).map(tuple),
                      summary=st.sampled_from(['honest', 'honest', 'chunks', 'none']),
                      cut_back=st.one_of(st.none(), st.none(), st.none(), st.integers(1, 200)))
    small = st.integers(0, 40)
    return st.builds(Rosbag2Case, storage=st.sampled_from(['mcap', 'mcap', 'sqlite3']), files=st.integers(1, 2),
                     first=first,
                     rows=st.lists(st.tuples(st.sampled_from(RowEdit.__args__), small), max_size=2).map(tuple),  # type: ignore[attr-defined]
                     metadata=st.lists(st.tuples(st.sampled_from(MetadataEdit.__args__), small),  # type: ignore[attr-defined]
                                       max_size=2).map(tuple))


@generated(150)
@given(case=rosbag2_cases())
def test_every_rosbag2_message_is_written_or_refused(case: Rosbag2Case, capsys: pytest.CaptureFixture[str]) -> None:
    """A rosbag2 folder whose files or metadata.yaml were edited: exit 0 with exactly the messages its listed
    storage files hold (each read on its own, not through metadata.yaml), or one line and exit 2. A count in
    metadata.yaml that differs from what the files hold is said; a storage file the metadata does not list is
    not read (as rosbag2 reads only listed files) and is said."""
    with tempfile.TemporaryDirectory() as name:
        folder = Path(name) / 'bag'
        folder.mkdir()
        case.write(folder)
        info = yaml.safe_load((folder / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
        listed = list(dict.fromkeys(info['relative_file_paths']))
        counts = [storage_count(folder / n) if (folder / n).exists() else 0 for n in listed]
        expected = None if None in counts else sum(c for c in counts if c is not None)
        verdict, err = judge(folder, Path(name), expected, [], capsys)
        event(f'readable: {expected is not None}, verdict: {verdict}')
        if verdict == 'written':
            per_topic = {t['topic_metadata']['name']: t['message_count'] for t in info['topics_with_message_count']
                         if t['message_count']}
            if info['message_count'] != expected or per_topic != topic_counts(folder, listed):
                assert 'warning' in err, f'metadata.yaml declares {info["message_count"]} {per_topic}; not said'
            unlisted = [p.name for p in folder.iterdir() if p.suffix in ('.mcap', '.db3') and p.name not in listed]
            if unlisted:
                assert 'not listed in metadata.yaml' in err, err


def topic_counts(folder: Path, listed: list[str]) -> dict[str, int]:
    """Messages per topic of the listed storage files, each read on its own (an independent reader)."""
    out: dict[str, int] = {}
    for name in listed:
        path = folder / name
        if path.suffix == '.mcap':
            topics: dict[int, str] = {}
            channels: list[int] = []
            for record in StreamReader(io.BytesIO(path.read_bytes())).records:
                if isinstance(record, Channel):
                    topics[record.id] = record.topic
                elif isinstance(record, Message):
                    channels.append(record.channel_id)
            for channel in channels:
                out[topics.get(channel, '?')] = out.get(topics.get(channel, '?'), 0) + 1
        else:
            with contextlib.closing(sqlite3.connect(f'file:{path}?mode=ro', uri=True)) as db:
                for topic, count in db.execute('SELECT topics.name, COUNT(*) FROM messages JOIN topics ON '
                                               'topics.id = messages.topic_id GROUP BY topics.name'):
                    out[topic] = out.get(topic, 0) + count
    return out


# -- --salvage ------------------------------------------------------------------------------------------------

LOST = re.compile(r'(\d+) missing|(\d+) messages? (?:could not be kept|not kept)')


def check_salvage(path: Path, folder: Path, expected: int | None, declared: int | None,
                  capsys: pytest.CaptureFixture[str]) -> str:
    """`--salvage` on a damaged input keeps what it can and says how many messages it could not keep: the
    number (what the input declares less what was kept) where the input declares a count, else that it is not
    known; never only where it stopped. Nothing is invented: never more than the input holds."""
    code, said, err, out = run(path, folder, ['--salvage'], capsys)
    if code == 2:
        lines = [line for line in err.splitlines() if not line.startswith('warning:')]
        assert len(lines) == 1 and lines[0].startswith('bagfault: error: '), err
        return 'refused'
    assert code == 0, err
    kept, _ = output_count(out)
    out.unlink()
    if expected is not None:
        assert kept <= expected, f'--salvage wrote {kept} messages; the input holds {expected}'
    if expected is None or kept < expected:
        numbers = {int(a or b) for a, b in LOST.findall(err)}
        if declared is not None and declared > kept:
            assert declared - kept in numbers, f'{declared} declared, {kept} kept; not said: {err}'
        else:
            assert numbers or 'not known' in err, f'{kept} kept of {expected}; how many lost is not said: {err}'
    return 'salvaged'


@generated(150)
@given(case=mcap_cases(valid=False))
def test_salvage_says_how_many_mcap_messages_it_could_not_keep(case: McapCase,
                                                                capsys: pytest.CaptureFixture[str]) -> None:
    data = case.bytes()
    with tempfile.TemporaryDirectory() as name:
        folder = Path(name)
        path = folder / 'case.mcap'
        path.write_bytes(data)
        event(check_salvage(path, folder, streamed_count(data), declared_counts(data).get('statistics'), capsys))


@generated(100)
@given(case=ros1_cases(valid=False))
def test_salvage_says_how_many_ros1_messages_it_could_not_keep(case: Ros1Case,
                                                                capsys: pytest.CaptureFixture[str]) -> None:
    data, extent = case.bytes()
    with tempfile.TemporaryDirectory() as name:
        folder = Path(name)
        path = folder / 'case.bag'
        path.write_bytes(data)
        event(check_salvage(path, folder, ros1_walk_count(data[:extent]), None, capsys))
