"""Message definitions a user supplies (`--msg-path DIR`, scenario `msg_paths:`), for types no bag carries.

A folder is searched for `<package>/msg/<Name>.msg` and `.idl` files (a
ROS workspace's `src/`, an install's `share/`, or a folder of packages);
the type of `<...>/<package>/msg/<Name>.msg` is `<package>/msg/<Name>`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from bagfault.errors import InputError, one_line
from bagfault.io.regular import read_text

if TYPE_CHECKING:
    from collections.abc import Sequence
    from pathlib import Path

Definitions = dict[str, tuple[str, str]]  # msgtype -> (schema encoding, text)
SUFFIXES = {'.msg': 'ros2msg', '.idl': 'ros2idl'}


def load_definitions(folders: Sequence[Path]) -> Definitions:
    """Every .msg/.idl file below the folders; the first folder that defines a type wins."""
    found: Definitions = {}
    for folder in folders:
        if not folder.is_dir():
            raise InputError(f'{folder}: message definition folder not found')
        for path in sorted(p for p in folder.rglob('*') if p.suffix in SUFFIXES and p.parent.name == 'msg'):
            msgtype = f'{path.parent.parent.name}/msg/{path.stem}'
            if msgtype in found:
                continue
            try:
                found[msgtype] = (SUFFIXES[path.suffix], read_text(path))
            except (OSError, UnicodeDecodeError) as exc:
                raise InputError(f'{path}: cannot read message definition ({one_line(exc)})') from None
    return found
