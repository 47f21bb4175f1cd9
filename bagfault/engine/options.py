"""What a file run is asked to do, as one record: the options of `bagfault run` past the scenario, inputs and output."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from pathlib import Path

    from bagfault.engine.activation import Activation


@dataclass(frozen=True)
class RunOptions:
    """A run's options, checked (the API builds it from its keywords; the engine reads it)."""

    seed: int
    activations: tuple[Activation, ...] = ()
    start_offset: float = 0.0  # seconds of the bag skipped
    compression: str = 'zstd'  # of the chunks bagfault writes ('none', 'lz4', 'zstd')
    compression_level: int | None = None  # None: the MCAP C++ writer's default
    batch: bool = True  # False: message by message (the reference path)
    salvage: bool = False  # copy what can be read of a damaged input, saying what was skipped
    msg_paths: tuple[Path, ...] = ()  # message definitions beyond the inputs' and the scenario's
    chunk_copy: bool = True  # copy untouched chunks of a single MCAP input as they are
    verify: bool = False  # decompress and count the copied chunks on a second thread
