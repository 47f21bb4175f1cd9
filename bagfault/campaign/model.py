"""A campaign file as data."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

Mode = Literal['run', 'test']
Keep = Literal['all', 'failed', 'none']
JobStatus = Literal['passed', 'failed', 'error']  # error: the job could not run (crash, timeout, bad bag)


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
