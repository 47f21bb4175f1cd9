"""Foxglove's view of an MCAP file: the official TypeScript library (@mcap/core) and Foxglove's decompressors,
run by node (foxglove_mcap.mjs), installed once with npm into a cache folder."""

from __future__ import annotations

import fcntl
import functools
import json
import os
import shutil
import subprocess
from pathlib import Path
from typing import Any

import pytest

PACKAGES = ['@mcap/core@2.2.2', '@foxglove/wasm-zstd@1.0.1', '@foxglove/wasm-lz4@1.0.2']
HERE = Path(__file__).parent


@functools.cache
def reader_dir() -> Path | None:
    """The folder holding the reader script beside its packages; None without node and npm, or when npm fails."""
    npm, node = shutil.which('npm'), shutil.which('node')
    if npm is None or node is None:
        return None
    cache = Path(os.environ.get('XDG_CACHE_HOME', Path.home() / '.cache')) / 'bagfault-tests' / 'mcap-core-2.2.2'
    cache.mkdir(parents=True, exist_ok=True)
    with (cache / '.lock').open('w') as lock:  # test workers install once between them
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not (cache / 'node_modules' / '@mcap' / 'core').is_dir():
            (cache / 'package.json').write_text('{"name": "bagfault-mcap-reader", "private": true, "type": "module"}')
            done = subprocess.run([npm, 'install', '--no-audit', '--no-fund', '--loglevel=error', *PACKAGES],
                                  cwd=cache, capture_output=True, text=True, check=False, timeout=300)
            if done.returncode != 0:
                return None
        shutil.copy(HERE / 'foxglove_mcap.mjs', cache / 'read.mjs')
    return cache


def foxglove_reads(path: Path) -> dict[str, Any]:
    """What Foxglove's MCAP library reads of `path`: messages per topic through its indexed reader ('indexed')
    and its stream reader ('stream': counts, opcodes it did not know, whether it reached the end); skips the
    test where node or npm is missing."""
    folder = reader_dir()
    if folder is None:
        pytest.skip("node and npm are needed for Foxglove's MCAP reader")
    done = subprocess.run(['node', str(folder / 'read.mjs'), str(path)], capture_output=True, text=True,
                          check=False, timeout=120)
    assert done.returncode == 0, done.stderr
    found: dict[str, Any] = json.loads(done.stdout)
    assert 'error' not in found, found['error']
    return found
