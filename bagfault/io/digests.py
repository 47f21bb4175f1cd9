"""Input digests kept between runs: a bag's BLAKE3 is computed once per file version, not once per run.

A run's provenance names each input file's BLAKE3 digest. Hashing a 10 GB bag
costs 3.5 s of CPU, paid again by every run on the same bag (a scenario
edited and run again, a CI job, a campaign on this machine). The digest is
kept under the file's stat key (device, inode, size, mtime, ctime: any write
changes the ctime, which nobody can set), in `~/.cache/bagfault/digests`
(`$XDG_CACHE_HOME`, or `$BAGFAULT_CACHE/digests`), one small file per key.

A file written within a second of being hashed is not kept, as git treats a
"racily clean" index entry: a second write within the clock tick of the first
(ext4 stamps ctime from a clock that ticks every few milliseconds) would keep
the stat key while changing the bytes. Nothing here is needed: a cache that
cannot be read or written is a cache miss.

The folder keeps at most `KEPT` digests: a file version that is gone (a bag
deleted or rewritten) is never asked for again, so keeping a digest past
`KEPT` lets the least recently used go (a recall marks its digest used).
"""

from __future__ import annotations

import contextlib
import logging
import os
import re
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING

from bagfault import settings
from bagfault.io.regular import read_text

if TYPE_CHECKING:
    from bagfault.io.sources import StatKey

log = logging.getLogger(__name__)
SETTLED_NS = 1_000_000_000  # a file unchanged this long before it was hashed cannot change within its ctime tick
HEX = re.compile(r'[0-9a-f]{64}')
KEPT = 20_000  # digests kept (a 4 KB block each); past it, the least recently used go down to 90 % of it


def root() -> Path | None:
    """Where digests are kept; None when BAGFAULT_CACHE cannot be used (the cache is only a speed-up: the
    command line refuses the setting before, an API caller just hashes)."""
    try:
        folder = settings.cache_folder()
    except settings.SettingError:
        return None
    return (folder or settings.user_cache()) / 'digests'


def _name(key: StatKey) -> str:
    return '-'.join(str(part) for part in key)


def recall(key: StatKey) -> str | None:
    """The digest kept for this version of a file, or None."""
    folder = root()
    if folder is None:
        return None
    path = folder / _name(key)
    try:
        text = read_text(path, 'ascii').strip()
    except (OSError, UnicodeDecodeError):
        return None
    if not HEX.fullmatch(text):
        return None
    with contextlib.suppress(OSError):
        os.utime(path)  # used now: the last to go
    return text


def keep(key: StatKey, digest: str, hashed_from_ns: int) -> bool:
    """Keep the digest of a file hashed from `hashed_from_ns` (wall clock) on, when the file had settled by
    then; True when kept."""
    if max(key[3], key[4]) > hashed_from_ns - SETTLED_NS or not HEX.fullmatch(digest):
        return False
    folder = root()
    if folder is None:
        return False
    staging: str | None = None
    try:
        folder.mkdir(parents=True, exist_ok=True)
        handle, staging = tempfile.mkstemp(dir=folder, prefix='.', suffix='.tmp')
        with os.fdopen(handle, 'w', encoding='ascii') as out:
            out.write(digest)
        os.replace(staging, folder / _name(key))
        staging = None
    except OSError as exc:
        log.debug('input digest not kept in %s: %s', folder, exc)
        return False
    finally:
        if staging is not None:
            with contextlib.suppress(OSError):
                os.unlink(staging)
    with contextlib.suppress(OSError):  # kept either way
        _prune(folder)
    return True


def _prune(folder: Path) -> None:
    """Past KEPT digests, the least recently used go, down to 90 % of KEPT (so not at every keep)."""
    kept = []
    with os.scandir(folder) as entries:
        for entry in entries:
            if not entry.name.startswith('.'):
                with contextlib.suppress(OSError):  # gone meanwhile: another run pruned it
                    kept.append((entry.stat().st_mtime_ns, entry.name))
    if len(kept) <= KEPT:
        return
    kept.sort()
    for _, name in kept[:len(kept) - KEPT * 9 // 10]:
        with contextlib.suppress(OSError):
            os.unlink(folder / name)
