"""A campaign file as data."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

Mode = Literal['run', 'test']
Keep = Literal['all', 'failed', 'none']
# An offline run is byte-identical for its seed, so a second sample says nothing new; a closed loop depends on the
# system's scheduling: 3 samples per value catch a value that fails one run in three 70 % of the time, and cost 3x.
REPEAT: dict[str, int] = {'run': 1, 'test': 3}


@dataclass(frozen=True)
class Until:
    """The state an assertion must reach for a searched value to count as 'detected'."""

    assertion: str
    state: Literal['passed', 'failed'] = 'passed'


@dataclass(frozen=True)
class Search:
    """Bisection of one parameter, per bag: the smallest value in [low, high] at which `until` holds."""

    parameter: str
    low: float
    high: float
    tolerance: float
    until: Until
    repeat: int | None = None  # samples per value and seed; None: REPEAT of the campaign's mode

    def samples(self, mode: Mode) -> int:
        """How often each value is run per seed."""
        return self.repeat if self.repeat is not None else REPEAT[mode]


@dataclass
class Campaign:
    """What to run: a scenario, the bags, the swept parameters and seeds, how to pick points, what to keep."""

    name: str
    scenario: Path
    mode: Mode = 'run'
    bags: list[str] = field(default_factory=list)  # globs, relative to the campaign file
    sweep: dict[str, list[Any]] = field(default_factory=dict)  # dotted path -> values, in file order
    seeds: list[int] = field(default_factory=lambda: [0])
    design: Literal['grid', 'random'] = 'grid'
    samples: int = 0  # random design: how many points
    design_seed: int = 0
    search: Search | None = None
    keep: Keep = 'failed'
    timeout: float = 3600.0  # seconds a job may take
    source: Path | None = None
    text: str = ''
