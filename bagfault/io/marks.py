"""Proof that bagfault wrote a file, so a later run may replace it without `--force`.

A look at a file's first bytes (`# bagfault `, `"tool": "bagfault"`, a header's library string) is no proof: a
user's notes or a hand-edited report look the same. Every file bagfault writes carries a mark instead, a
SHA-256 over the file's own content (with the mark's place zeroed), so a foreign file cannot have one by chance
and an edited one no longer has it:

- text (Markdown, HTML, XML, YAML, JSON): `bagfault-mark:<hex>` inside a comment, or a JSON document's
  `bagfault_mark` key;
- tables and logs that cannot hold a comment (CSV, Parquet, JSON Lines): a sidecar `.<name>.bagfault-mark`;
- MCAP: a `bagfault.mark` metadata record, last in the data section, over its own offset and every chunk
  index record (a rewrite of the file moves both), checked from the summary without reading the chunks.
"""

from __future__ import annotations

import hashlib
import re
from pathlib import Path
from typing import Literal

Kind = Literal['markdown', 'html', 'xml', 'yaml', 'json', 'table']
TAG = b'bagfault-mark:'
PLACEHOLDER = TAG + b'0' * 64
FOUND = re.compile(rb'bagfault-mark:([0-9a-f]{64})')
MCAP_RECORD = 'bagfault.mark'  # the metadata record's name in an MCAP file
SIDECAR = '.{}.bagfault-mark'


def _digest(*parts: bytes) -> str:
    digest = hashlib.sha256(b'bagfault mark v1\0')
    for part in parts:
        digest.update(len(part).to_bytes(8, 'little'))
        digest.update(part)
    return digest.hexdigest()


def stamp(data: bytes, kind: Kind) -> bytes:
    """`data` with its mark (a table's is written beside it: see `sidecar`); text that has its mark already
    is kept as it is (a campaign's job ran those very bytes)."""
    if kind == 'table' or is_marked(data):
        return data
    if kind == 'json':
        body = data.rstrip()
        if not body.endswith(b'}'):
            raise ValueError('a JSON output is an object')
        inner = body[:-1].rstrip()
        separator = b'' if inner.endswith(b'{') else b','
        data = inner + separator + b'\n "bagfault_mark": "' + PLACEHOLDER + b'"\n}\n'
    elif kind == 'yaml':
        data = data + (b'' if data.endswith(b'\n') or not data else b'\n') + b'# ' + PLACEHOLDER + b'\n'
    else:  # markdown, html, xml: a comment after everything (XML allows one after the root element)
        data = data + (b'' if data.endswith(b'\n') or not data else b'\n') + b'<!-- ' + PLACEHOLDER + b' -->\n'
    return data.replace(PLACEHOLDER, TAG + _digest(data).encode())


def is_marked(data: bytes) -> bool:
    """Whether text holds its own valid mark (the last one it has)."""
    found = None
    for found in FOUND.finditer(data):  # noqa: B007 - the last
        pass
    if found is None:
        return False
    zeroed = data[:found.start()] + PLACEHOLDER + data[found.end():]
    return _digest(zeroed) == found.group(1).decode()


def sidecar(path: Path) -> Path:
    """Where a table's mark goes."""
    return path.with_name(SIDECAR.format(path.name))


def table_mark(name: str, data: bytes) -> str:
    """A table's mark: its name and content."""
    return _digest(name.encode(), data)


def mcap_mark(offset: int, chunk_indexes: list[bytes]) -> str:
    """An MCAP file's mark: the offset of its mark record and its chunk index records, as written."""
    return _digest(offset.to_bytes(8, 'little'), *chunk_indexes)
