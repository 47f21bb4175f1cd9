"""`bagfault latency` measured: every usable path of an architecture file on bags, JSON-ready."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from bagfault.errors import LatencyError
from bagfault.latency.architecture import Architecture, NamedPath, load_architecture
from bagfault.latency.collect import fault_windows, read_series
from bagfault.latency.compute import PathResult, by_fault, path_latency, statistics
from bagfault.units import NS

if TYPE_CHECKING:
    from collections.abc import Sequence
    from pathlib import Path



@dataclass
class LatencyReport:
    """Everything `bagfault latency` shows."""

    architecture: Architecture
    inputs: list[str]
    origin: int
    results: list[PathResult]
    windows: dict[str, list[tuple[int, int | None]]]
    unusable: dict[str, list[str]] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form, per path: statistics of the samples and of each response-time case, per fault window."""
        return {
            'tool': 'bagfault',
            'architecture': str(self.architecture.source),
            'inputs': self.inputs,
            'warnings': self.architecture.warnings,
            'unusable_paths': self.unusable,
            'paths': [{
                'path': r.name,
                'topics': r.topics,
                'inputs': r.inputs,
                'dropped_inputs': r.dropped,
                'latency_ms': statistics(r.latency_ms),
                'response_time_ms': {case: statistics(values) for case, (_, values) in r.cases.items()},
                'by_fault': by_fault(r, self.windows),
                'samples': [[round((t - self.origin) / NS, 9), round(v, 6)]
                            for t, v in zip(r.sample_times.tolist(), r.latency_ms.tolist(), strict=True)],
                'notes': r.notes,
            } for r in self.results],
        }


def _check_named(arch_file: str | Path, architecture: Architecture, path: str) -> None:
    """LatencyError when the path asked for was dropped or is not in the file."""
    if path in architecture.dropped:
        raise LatencyError(f'{arch_file}: path {path} was dropped: {architecture.dropped[path]}')
    if path not in architecture.paths:
        raise LatencyError(f'{arch_file}: no path {path!r} (paths: {", ".join(architecture.paths)})')


def _paths(arch_file: str | Path, architecture: Architecture, path: str | None,
           ) -> tuple[list[NamedPath], dict[str, list[str]]]:
    """The paths to measure (the one named, or all) and the problems of those that cannot be; LatencyError when
    the one named is dropped, missing or cannot be measured."""
    if path is not None:
        _check_named(arch_file, architecture, path)
    wanted = [architecture.paths[path]] if path else list(architecture.paths.values())
    usable = [p for p in wanted if p.usable]
    unusable = {p.name: p.problems for p in wanted if not p.usable}
    if path is not None and not usable:
        raise LatencyError(f'{arch_file}: path {path} cannot be measured: {"; ".join(unusable[path])}')
    return usable, unusable


def measure(arch_file: str | Path, bags: Sequence[str | Path], *, path: str | None = None,
            stamp_origin: bool = False) -> LatencyReport:
    """Load the architecture, read the path topics of the bags, compute every usable path."""
    from pathlib import Path as _Path  # noqa: PLC0415

    architecture = load_architecture(arch_file)
    usable, unusable = _paths(arch_file, architecture, path)
    topics = sorted({t for p in usable for t in p.topics})
    series, events = read_series([_Path(b) for b in bags], topics)
    starts = [s.times[0] for s in series.values() if s.times.size]
    origin = min(starts) if starts else 0
    results = [path_latency(architecture, p, series, stamp_origin=stamp_origin) for p in usable]
    return LatencyReport(architecture, [str(b) for b in bags], origin, results, fault_windows(events), unusable)
