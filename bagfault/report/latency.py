"""`bagfault latency` shown: per-path tables, and an HTML page with time series and histogram."""

from __future__ import annotations

from html import escape
from typing import TYPE_CHECKING, Any

from bagfault.latency.compute import by_fault, statistics
from bagfault.latency.measure import LatencyReport
from bagfault.report import svg

if TYPE_CHECKING:
    from bagfault.latency.architecture import Architecture

NS = 1_000_000_000


def _row(name: str, stats: dict[str, Any]) -> str:
    if not stats['count']:
        return f'  {name:<10} {0:>7}  no samples'
    return (f'  {name:<10} {stats["count"]:>7}  ' + '  '.join(f'{stats[k]:9.3f}' for k in
                                                              ('min', 'mean', 'p50', 'p95', 'p99', 'max')))


LABELS = {'worst-with-external-latency': 'worst+ext'}  # the table's 10-character column


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
                  *(_row(LABELS.get(case, case), statistics(values)) for case, (_, values) in result.cases.items())]
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
            kind = context.context_type if context else 'no message context: measurement ends here'
            lines.append(f'  hop {node}: {source} -> {target} [{kind}]')
        lines += [f'  problem: {p}' for p in path.problems]
    return '\n'.join(lines)
