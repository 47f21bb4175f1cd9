"""`bagfault latency`: per-path tables, JSON, and an HTML page with time series and histogram."""

from __future__ import annotations

from dataclasses import dataclass, field
from html import escape
from typing import TYPE_CHECKING, Any

from bagfault.errors import LatencyError
from bagfault.latency.architecture import Architecture, load_architecture
from bagfault.latency.collect import fault_windows, read_series
from bagfault.latency.compute import PathResult, by_fault, path_latency, statistics
from bagfault.report import svg

if TYPE_CHECKING:
    from collections.abc import Sequence
    from pathlib import Path

NS = 1_000_000_000


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
                'response_time_ms': {'all': statistics(r.all_cases[1]), 'best': statistics(r.best[1]),
                                     'worst': statistics(r.worst[1])},
                'by_fault': by_fault(r, self.windows),
                'samples': [[round((t - self.origin) / NS, 9), round(v, 6)]
                            for t, v in zip(r.sample_times.tolist(), r.latency_ms.tolist(), strict=True)],
                'notes': r.notes,
            } for r in self.results],
        }


def measure(arch_file: str | Path, bags: Sequence[str | Path], *, path: str | None = None,
            stamp_origin: bool = False) -> LatencyReport:
    """Load the architecture, read the path topics of the bags, compute every usable path."""
    from pathlib import Path as _Path  # noqa: PLC0415

    architecture = load_architecture(arch_file)
    if path is not None and path not in architecture.paths:
        raise LatencyError(f'{arch_file}: no path {path!r} (paths: {", ".join(architecture.paths)})')
    wanted = [architecture.paths[path]] if path else list(architecture.paths.values())
    usable = [p for p in wanted if p.usable]
    unusable = {p.name: p.problems for p in wanted if not p.usable}
    if path is not None and not usable:
        raise LatencyError(f'{arch_file}: path {path} cannot be measured: {"; ".join(unusable[path])}')
    topics = sorted({t for p in usable for t in p.topics})
    series, events = read_series([_Path(b) for b in bags], topics)
    starts = [s.times[0] for s in series.values() if s.times.size]
    origin = min(starts) if starts else 0
    results = [path_latency(architecture, p, series, stamp_origin=stamp_origin) for p in usable]
    return LatencyReport(architecture, [str(b) for b in bags], origin, results, fault_windows(events), unusable)


def _row(name: str, stats: dict[str, Any]) -> str:
    if not stats['count']:
        return f'  {name:<10} {0:>7}  no samples'
    return (f'  {name:<10} {stats["count"]:>7}  ' + '  '.join(f'{stats[k]:9.3f}' for k in
                                                              ('min', 'mean', 'p50', 'p95', 'p99', 'max')))


def render_text(report: LatencyReport) -> str:
    """One table per path."""
    lines = [f'architecture {report.architecture.source}']
    for warning in report.architecture.warnings:
        lines.append(f'warning: {warning}')
    for name, problems in report.unusable.items():
        lines.append(f'path {name}: cannot be measured: {"; ".join(problems)}')
    header = f'  {"ms":<10} {"count":>7}  ' + '  '.join(f'{k:>9}' for k in ('min', 'mean', 'p50', 'p95', 'p99', 'max'))
    for result in report.results:
        lines += ['', f'path {result.name}: {" -> ".join(result.topics)}  ({result.inputs} inputs, '
                      f'{result.dropped} dropped)', header, _row('latency', statistics(result.latency_ms)),
                  _row('all', statistics(result.all_cases[1])), _row('best', statistics(result.best[1])),
                  _row('worst', statistics(result.worst[1]))]
        for fault_id, windows in by_fault(result, report.windows).items():
            for part in ('before', 'during', 'after'):
                lines.append(_row(f'{part[:6]}:{fault_id}'[:10], windows[part]))
        lines += [f'  note: {n}' for n in result.notes]
    return '\n'.join(lines)


def render_html(report: LatencyReport) -> str:
    """Time series with fault windows shaded, and a histogram, per path."""
    shaded = [((s - report.origin) / NS, ((e if e is not None else s) - report.origin) / NS, fault)
              for fault, spans in report.windows.items() for s, e in spans]
    parts = []
    for result in report.results:
        xs = [(t - report.origin) / NS for t in result.sample_times.tolist()]
        parts.append(f'<h2>{escape(result.name)}: {escape(" -> ".join(result.topics))}</h2>')
        parts.append(svg.line_chart([('latency', xs, result.latency_ms.tolist())], title=f'{result.name} latency',
                                    ylabel='ms', shaded=shaded))
        parts.append(svg.histogram(result.latency_ms.tolist(), title=f'{result.name} latency histogram',
                                   xlabel='latency (ms)'))
        parts.append('<pre>' + escape(render_text(LatencyReport(report.architecture, report.inputs, report.origin,
                                                                [result], report.windows))) + '</pre>')
    return ('<!DOCTYPE html><html lang="en"><head><meta charset="utf-8"><title>bagfault latency</title>'
            '<style>body{font-family:system-ui,sans-serif;margin:24px;max-width:820px}</style></head><body>'
            f'<h1>Path latency</h1><p>{escape(str(report.architecture.source))} on '
            f'{escape(", ".join(report.inputs))}</p>{"".join(parts)}</body></html>\n')


def render_validation(architecture: Architecture) -> str:
    """Paths, their hops and every problem, for `bagfault latency validate`."""
    lines = [f'architecture {architecture.source}: {len(architecture.paths)} paths, {len(architecture.nodes)} nodes']
    lines += [f'warning: {w}' for w in architecture.warnings]
    for path in architecture.paths.values():
        lines.append(f'path {path.name}: {"usable" if path.usable else "UNUSABLE"}')
        for element in path.chain:
            lines.append(f'  {element.node_name}: {element.subscribe_topic or "-"} -> {element.publish_topic or "-"}')
        for node, source, target, context in architecture.hops(path):
            kind = context.context_type if context else 'no message context'
            lines.append(f'  hop {node}: {source} -> {target} [{kind}]')
        lines += [f'  problem: {p}' for p in path.problems]
    return '\n'.join(lines)
