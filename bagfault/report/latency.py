"""`bagfault latency` shown: per-path tables, and an HTML page with time series and histogram."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from bagfault.latency.compute import by_fault, statistics
from bagfault.latency.measure import LatencyReport
from bagfault.report.page import Page, envelope, macros, shade, title
from bagfault.units import NS

if TYPE_CHECKING:
    from bagfault.latency.architecture import Architecture



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
    """Per path: latency samples over bag time with fault windows shaded (linked zoom) and a histogram."""
    windows = [((s - report.origin) / NS, ((e if e is not None else s) - report.origin) / NS, fault)
               for fault, spans in report.windows.items() for s, e in spans]
    page = Page('bagfault latency')
    page.html(macros().latency_header(str(report.architecture.source), report.inputs))
    for result in report.results:
        page.section(f'{result.name}: {" -> ".join(result.topics)}')
        seconds = (result.sample_times - report.origin) / NS
        x, y = envelope(seconds, result.latency_ms)
        page.figure([{'type': 'scatter', 'mode': 'lines+markers', 'x': x, 'y': y, 'name': 'latency',
                      'marker': {'size': 3}, 'hovertemplate': '%{y:.3f} ms at %{x:.3f} s<extra></extra>'}],
                    {'title': title(f'{result.name} latency per sample'), 'height': 320,
                     'xaxis': {'title': {'text': 'bag time (s)'}}, 'yaxis': {'title': {'text': 'ms'}},
                     'shapes': shade(windows)}, timed=True, name=f'latency:{result.name}')
        page.figure([{'type': 'histogram', 'x': result.latency_ms, 'name': 'samples', 'nbinsx': 50}],
                    {'title': title(f'{result.name} latency histogram'), 'height': 280,
                     'xaxis': {'title': {'text': 'latency (ms)'}}, 'yaxis': {'title': {'text': 'samples'}}},
                    name=f'histogram:{result.name}')
        page.html(macros().preformatted(render_text(LatencyReport(report.architecture, report.inputs, report.origin,
                                                                  [result], report.windows))))
    return page.render()


def render_validation(architecture: Architecture) -> str:
    """Paths, their hops and every problem, for `bagfault latency validate` (its warnings go to stderr)."""
    lines = [f'architecture {architecture.source}: {len(architecture.paths)} paths, {len(architecture.nodes)} nodes']
    for path in architecture.paths.values():
        lines.append(f'path {path.name}: {"usable" if path.usable else "UNUSABLE"}')
        for element in path.chain:
            lines.append(f'  {element.node_name}: {element.subscribe_topic or "-"} -> {element.publish_topic or "-"}')
        for node, source, target, context in architecture.hops(path):
            kind = context.context_type if context else 'no message context: measurement ends here'
            lines.append(f'  hop {node}: {source} -> {target} [{kind}]')
        lines += [f'  problem: {p}' for p in path.problems]
    return '\n'.join(lines)
