"""Input digests kept between runs (bagfault/io/digests.py): a file version is hashed once; any write, or a file
too fresh to trust its stat key, means hashing again. Expected digests come from the blake3 library on the file's
bytes."""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import time
from pathlib import Path

import blake3
import pytest
from mcap.reader import make_reader
from support.helpers import FIXTURES

from bagfault.cli import main
from bagfault.io import digests, sources
from bagfault.io.sources import fingerprint, stat_key

BAG = FIXTURES / 'rover_20s.mcap'  # checked out long ago: its stat key has settled


def b3(path: Path) -> str:
    return blake3.blake3(path.read_bytes()).hexdigest()


@pytest.fixture
def cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv('BAGFAULT_CACHE', str(tmp_path / 'cache'))
    return tmp_path / 'cache' / 'digests'


def no_hashing(*_: object, **__: object) -> str:
    raise AssertionError('the file was hashed again')


def test_a_settled_file_is_hashed_once_and_its_digest_recalled(cache: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    expected = b3(BAG)
    assert [f.blake3 for f in fingerprint(BAG)] == [expected]
    key = stat_key(BAG)
    assert (cache / '-'.join(map(str, key))).read_text() == expected
    monkeypatch.setattr(sources, '_blake3', no_hashing)
    assert [f.blake3 for f in fingerprint(BAG)] == [expected]


def test_a_file_written_just_now_is_hashed_but_not_kept(cache: Path, tmp_path: Path,
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    """Within a second of its last write a second write could keep the stat key (the ctime clock ticks every few
    milliseconds): as git's racily clean entries, such a digest is not kept. (The second is made an hour here, so
    a stalled machine cannot let the copy below settle before it is hashed.)"""
    monkeypatch.setattr(digests, 'SETTLED_NS', 3600 * 10**9)
    fresh = tmp_path / 'fresh.mcap'
    shutil.copyfile(BAG, fresh)
    assert [f.blake3 for f in fingerprint(fresh)] == [b3(BAG)]
    assert not cache.exists() or list(cache.iterdir()) == []


def test_a_rewritten_file_is_hashed_again(cache: Path, tmp_path: Path) -> None:
    """Same name, size and mtime (set back by hand), other bytes: the ctime moved, so the kept digest of the old
    bytes is not used."""
    path = tmp_path / 'bag.mcap'
    shutil.copyfile(BAG, path)
    old = path.stat()
    cache.mkdir(parents=True)
    stale = '0' * 64
    (cache / '-'.join(map(str, stat_key(path)))).write_text(stale)
    assert [f.blake3 for f in fingerprint(path)] == [stale]  # (what a kept digest does: it is believed)
    time.sleep(0.05)
    data = bytearray(path.read_bytes())
    data[-100] ^= 0xFF
    path.write_bytes(bytes(data))
    os.utime(path, ns=(old.st_atime_ns, old.st_mtime_ns))
    assert path.stat().st_size == old.st_size and path.stat().st_mtime_ns == old.st_mtime_ns
    assert [f.blake3 for f in fingerprint(path)] == [b3(path)] != [stale]


def test_a_cache_that_cannot_be_written_is_only_a_miss(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    blocker = tmp_path / 'cache'
    blocker.write_text('a file where the cache folder would be')
    monkeypatch.setenv('BAGFAULT_CACHE', str(blocker))
    assert [f.blake3 for f in fingerprint(BAG)] == [b3(BAG)]
    assert digests.recall(stat_key(BAG)) is None
    assert list(tmp_path.iterdir()) == [blocker]  # no staging file left


def test_two_runs_write_the_same_bytes_the_second_without_hashing(cache: Path, tmp_path: Path,
                                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    scenario = FIXTURES / 'scenarios' / 'rover_multi.yaml'
    assert main(['run', str(scenario), str(BAG), '-o', str(tmp_path / 'first.mcap')]) in (0, 1)
    monkeypatch.setattr(sources, '_blake3', no_hashing)
    assert main(['run', str(scenario), str(BAG), '-o', str(tmp_path / 'second.mcap')]) in (0, 1)
    assert (tmp_path / 'first.mcap').read_bytes() == (tmp_path / 'second.mcap').read_bytes()
    with (tmp_path / 'second.mcap').open('rb') as stream:
        [meta] = [m for m in make_reader(stream).iter_metadata() if m.name == 'bagfault']
    assert json.loads(meta.metadata['inputs'])[0]['files'][0]['blake3'] == b3(BAG)


def test_past_the_limit_the_least_recently_used_digests_go(cache: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """KEPT 10: the eleventh digest kept prunes down to 9, oldest use first; a recall counts as a use."""
    monkeypatch.setattr(digests, 'KEPT', 10)
    long_ago = time.time_ns() - 10 * digests.SETTLED_NS
    keys = [(1, inode, 100, long_ago, long_ago) for inode in range(11)]
    for age, key in enumerate(keys[:10]):
        assert digests.keep(key, f'{age:064x}', time.time_ns())
        path = cache / '-'.join(map(str, key))
        os.utime(path, ns=(long_ago + age * 1000, long_ago + age * 1000))  # used in the order kept
    assert digests.recall(keys[0]) == f'{0:064x}'  # the oldest, used again now
    assert digests.keep(keys[10], f'{10:064x}', time.time_ns())
    left = sorted(int(p.name.split('-')[1]) for p in cache.iterdir())
    assert left == [0, 3, 4, 5, 6, 7, 8, 9, 10]  # 11 kept, 2 over 90 % of 10: the two least recently used
    assert digests.recall(keys[1]) is None and digests.recall(keys[3]) == f'{3:064x}'


def test_a_digest_another_run_prunes_meanwhile_is_passed_over(cache: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Two runs keeping digests at once: an entry gone between this run's listing and its stat is no error, and
    the digest being kept is kept."""
    monkeypatch.setattr(digests, 'KEPT', 1)
    long_ago = time.time_ns() - 10 * digests.SETTLED_NS
    first, second = (1, 1, 100, long_ago, long_ago), (1, 2, 100, long_ago, long_ago)
    assert digests.keep(first, f'{1:064x}', time.time_ns())
    original = os.scandir
    stale = list(original(cache))  # listed here, then pruned by the other run before this one reads its stat
    (cache / '-'.join(map(str, first))).unlink()

    def listing(path: Path) -> contextlib.nullcontext[list[os.DirEntry[str]]]:
        with original(path) as now:
            return contextlib.nullcontext(stale + [e for e in now if e.name not in {s.name for s in stale}])

    monkeypatch.setattr(os, 'scandir', listing)
    assert digests.keep(second, f'{2:064x}', time.time_ns())
    monkeypatch.undo()
    assert [p.name for p in cache.iterdir()] == ['-'.join(map(str, second))]
