"""The environment variables bagfault reads, each parsed and checked in one place: a bad value is a
SettingError (exit 2) naming the variable, never a traceback or a cache path outside its root.

`check()` reads them all; the command line calls it before anything runs, so a campaign's jobs never meet a
bad value one by one.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

from bagfault.errors import BagfaultError

CACHE_GB_DEFAULT = 50.0
EXECUTORS = ('events', 'single')


class SettingError(BagfaultError):
    """An environment variable bagfault reads has a value that cannot work."""


def _text(name: str) -> str | None:
    value = os.environ.get(name)
    return value if value else None


def _folder(name: str) -> Path | None:
    """A variable naming a folder (made when needed): None when unset, SettingError when it names something else."""
    text = _text(name)
    if text is None:
        return None
    path = Path(text)
    if path.exists() and not path.is_dir():
        raise SettingError(f'{name}={text}: not a folder')
    return path


def cache_folder() -> Path | None:
    """`BAGFAULT_CACHE`: the bag cache's folder (digests go in its `digests/`); None for the default."""
    return _folder('BAGFAULT_CACHE')


def user_cache() -> Path:
    """`$XDG_CACHE_HOME/bagfault`, else `~/.cache/bagfault`."""
    return Path(_text('XDG_CACHE_HOME') or Path.home() / '.cache') / 'bagfault'


def cache_node() -> str | None:
    """`BAGFAULT_CACHE_NODE`: one folder name below the cache root (never a path that leaves it)."""
    node = _text('BAGFAULT_CACHE_NODE')
    if node is None:
        return None
    if node in ('.', '..') or '/' in node or '\0' in node or node.startswith('.'):
        raise SettingError(f"BAGFAULT_CACHE_NODE={node!r}: give one plain folder name (a node's own part of the "
                           'cache), not a path')
    return node


def cache_gigabytes() -> float:
    """`BAGFAULT_CACHE_GB`: what the bag cache may hold, a positive number of gigabytes (default 50)."""
    text = _text('BAGFAULT_CACHE_GB')
    if text is None:
        return CACHE_GB_DEFAULT
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value) or value <= 0:
        raise SettingError(f'BAGFAULT_CACHE_GB={text!r}: give a positive number of gigabytes (default 50)')
    return value


def domain_port_base(default: int) -> int:
    """`BAGFAULT_DOMAIN_PORT_BASE`: domain_coordinator's base port, for tests of leases alone."""
    text = _text('BAGFAULT_DOMAIN_PORT_BASE')
    if text is None:
        return default
    if not text.isdigit() or not 1024 <= int(text) <= 65535 - 232:
        raise SettingError(f'BAGFAULT_DOMAIN_PORT_BASE={text!r}: give a port from 1024 to {65535 - 232} '
                           '(ROS domain ids 0-232 are added to it)')
    return int(text)


def domain_locks() -> Path | None:
    """`BAGFAULT_DOMAIN_LOCKS`: where domain lease lock files live, for tests; None for the default."""
    return _folder('BAGFAULT_DOMAIN_LOCKS')


def executor() -> str:
    """`BAGFAULT_EXECUTOR`: 'events' (rclpy's events executor where there is one, the default) or 'single'."""
    text = _text('BAGFAULT_EXECUTOR') or 'events'
    if text not in EXECUTORS:
        raise SettingError(f'BAGFAULT_EXECUTOR={text!r}: give one of {", ".join(EXECUTORS)}')
    return text


def check() -> None:
    """Every setting read once: the first bad one raises SettingError."""
    cache_folder()
    cache_node()
    cache_gigabytes()
    domain_port_base(0)
    domain_locks()
    executor()


BLAS_THREADS = 'OPENBLAS_NUM_THREADS'
BLAS_THREADS_OURS = 'BAGFAULT_SET_OPENBLAS_NUM_THREADS'  # marks the value as bagfault's, not the user's


def one_blas_thread() -> None:
    """Have numpy load without OpenBLAS's thread pool, in this process and the ones bagfault starts for itself.

    bagfault multiplies no matrices; OpenBLAS starts a thread per core when numpy loads and they spin
    (0.05-0.09 s of CPU per process here, a tenth of what a run without faults spends beyond a copy). The command
    line calls this before numpy loads; a value the user set is left as it is.
    """
    if BLAS_THREADS not in os.environ:
        os.environ[BLAS_THREADS] = '1'
        os.environ[BLAS_THREADS_OURS] = '1'


def users_environment(environment: dict[str, str]) -> dict[str, str]:
    """`environment` without what `one_blas_thread` set: the system under test gets the user's own."""
    if environment.get(BLAS_THREADS_OURS) != '1':
        return environment
    return {k: v for k, v in environment.items() if k not in (BLAS_THREADS, BLAS_THREADS_OURS)}
