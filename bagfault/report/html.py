"""Self-contained HTML report: fault timeline, assertions, topic rates, before/after fields.

One file, inline SVG and CSS, a few lines of script only to flag render
errors (the test renders the page in headless Chromium and reads them).
"""

from __future__ import annotations

import json
from html import escape
from typing import TYPE_CHECKING, Any

from bagfault.report import svg

if TYPE_CHECKING:
    from collections.abc import Sequence

    from bagfault.report.fields import FieldPlot
    from bagfault.report.rates import RateTracker

STYLE = """
body{font-family:system-ui,sans-serif;margin:24px;color:#222;max-width:820px}
h1{font-size:20px} h2{font-size:16px;margin-top:28px;border-bottom:1px solid #ddd}
table{border-collapse:collapse;font-size:12px;width:100%} td,th{border:1px solid #ddd;padding:3px 6px;text-align:left}
.pass{color:#2a7d2a;font-weight:bold} .fail{color:#c62828;font-weight:bold} .verdict{font-size:18px}
svg.plot{display:block;margin:8px 0} code{font-size:11px}
"""

SCRIPT = """
window.bagfaultErrors = [];
window.addEventListener('error', function (e) { window.bagfaultErrors.push(String(e.message)); });
window.addEventListener('load', function () {
  document.body.dataset.plots = document.querySelectorAll('svg.plot').length;
  document.body.dataset.errors = window.bagfaultErrors.length;
});
"""


def _windows(report: dict[str, Any], faults: set[str] | None = None) -> list[tuple[float, float, str]]:
    """Active intervals of the given faults (all faults when None)."""
    end = report['time']['duration_s'] or 0.0
    return [(w['start_s'], w['end_s'] if w['end_s'] is not None else end, w['fault_id'])
            for w in report['fault_windows'] if faults is None or w['fault_id'] in faults]


def _faults_on(report: dict[str, Any], topic: str) -> set[str]:
    """Faults of the injectors that read or write a topic."""
    return {f for i in report.get('injectors', []) if topic in (i['input_topic'], i['output_topic'])
            for f in i['faults']}


def _timeline(report: dict[str, Any]) -> str:
    rows: dict[str, list[tuple[float, float | None]]] = {}
    for window in report['fault_windows']:
        rows.setdefault(window['fault_id'], []).append((window['start_s'], window['end_s']))
    if not rows:
        return '<p>No fault changed state during the bag.</p>'
    return svg.timeline(list(rows.items()), title='Fault timeline', end=report['time']['duration_s'] or 1.0)


def _assertions(report: dict[str, Any]) -> str:
    if not report['assertions']:
        return '<p>No assertions in this scenario.</p>'
    rows = []
    for a in report['assertions']:
        css = 'pass' if a['state'] == 'passed' else 'fail'
        t = '' if a['t_s'] is None else f'{a["t_s"]:.3f}'
        rows.append(f'<tr><td class="{css}">{escape(a["state"].upper())}</td><td>{escape(a["id"])}</td>'
                    f'<td>{escape(a["type"])}</td><td>{t}</td><td>{escape(a["message"])}</td></tr>')
    return ('<table><tr><th>result</th><th>assertion</th><th>type</th><th>t (s)</th><th>message</th></tr>'
            + ''.join(rows) + '</table>')


def _rates(report: dict[str, Any], rates: RateTracker | None, topics: Sequence[str]) -> str:
    if rates is None:
        return '<p>Rates were not collected.</p>'
    charts = []
    for topic in topics:
        xs, ys = rates.series(topic)
        charts.append(svg.line_chart([(topic, xs, ys)], title=f'{topic} rate', ylabel='Hz',
                                     shaded=_windows(report, _faults_on(report, topic)), step=True,
                                     from_zero=True))
    return ''.join(charts)


def _fields(report: dict[str, Any], plots: Sequence[FieldPlot]) -> str:
    if not plots:
        return '<p>No field was changed by an active fault.</p>'
    charts = []
    for plot in plots:
        title = f'{plot.field} on {plot.output_topic} ({", ".join(plot.faults)})'
        charts.append(svg.line_chart(
            [(f'before: {plot.input_topic}', *plot.before), (f'after: {plot.output_topic}', *plot.after)],
            title=title, ylabel=plot.field, shaded=_windows(report, set(plot.faults))))
    return ''.join(charts)


def fault_manager_section(summary: dict[str, Any]) -> str:
    """The fault manager's final table, events and snapshots."""
    rows = ''.join(
        f'<tr><td>{escape(f["fault_code"])}</td><td>{escape(f["severity"])}</td><td>{escape(f["status"])}</td>'
        f'<td>{f["occurrence_count"]}</td><td>{f["first_occurred_s"]:.3f}</td><td>{f["last_occurred_s"]:.3f}</td></tr>'
        for f in summary['faults'])
    events = ''.join(f'<tr><td>{e["t_s"]:.3f}</td><td>{escape(e["event_type"])}</td><td>{escape(e["fault_code"])}'
                     f'</td><td>{escape(e["status"])}</td></tr>' for e in summary['events'][:200])
    snapshots = ''.join(
        f'<p>Snapshot of {escape(s["fault_code"])} at {s["t_s"]:.3f} s'
        f'{", black box " + escape(s["black_box"]) if s["black_box"] else ""}</p>'
        f'<pre>{escape(json.dumps(s["freeze_frame"], indent=1, sort_keys=True)[:4000])}</pre>'
        for s in summary['snapshots'])
    return (f'<p>{len(summary["confirmed"])} confirmed; {summary["muted_count"]} muted; '
            f'{summary["cluster_count"]} clusters.</p>'
            '<table><tr><th>code</th><th>severity</th><th>status</th><th>occurrences</th><th>first (s)</th>'
            f'<th>last (s)</th></tr>{rows}</table>'
            f'<table><tr><th>t (s)</th><th>event</th><th>code</th><th>status</th></tr>{events}</table>{snapshots}')


def render(
    report: dict[str, Any],
    rates: RateTracker | None = None,
    plots: Sequence[FieldPlot] = (),
    extra_sections: Sequence[tuple[str, str]] = (),
) -> str:
    """Whole HTML document."""
    counts = report['assertion_counts']
    verdict_css = 'fail' if report['verdict'] == 'failed' else 'pass'
    topics = sorted(report['messages']['per_topic_written'])
    rate_topics = [t for t in topics if not t.startswith('/fault_injection/')]
    counts_table = ''.join(f'<tr><td>{escape(t)}</td><td>{n}</td></tr>'
                           for t, n in report['messages']['per_topic_written'].items())
    inputs = ', '.join(f'<code>{escape(p)}</code>' for p in report['inputs'])
    if 'fault_manager' in report:
        extra_sections = [('Fault manager', fault_manager_section(report['fault_manager'])), *extra_sections]
    sections = ''.join(f'<h2>{escape(title)}</h2>{body}' for title, body in extra_sections)
    notes = ''.join(f'<li>{escape(n)}</li>' for n in report['notes'])
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<title>bagfault report: {escape(report['scenario']['name'])}</title>
<style>{STYLE}</style><script>{SCRIPT}</script></head>
<body>
<h1>bagfault report: {escape(report['scenario']['name'])}</h1>
<p class="verdict {verdict_css}">{escape(report['verdict'].upper())}: \
{counts['passed']} passed, {counts['failed']} failed</p>
<p>mode {escape(report['mode'])}; inputs {inputs}; output <code>{escape(str(report['output']))}</code>;
seed {report['seed']}; bag duration {report['time']['duration_s']} s; bagfault {escape(report['tool']['version'])}</p>
<h2>Fault timeline</h2>{_timeline(report)}
<h2>Assertions</h2>{_assertions(report)}
<h2>Before and after</h2>{_fields(report, plots)}
<h2>Topic rates</h2>{_rates(report, rates, rate_topics)}
{sections}
<h2>Messages written</h2><table><tr><th>topic</th><th>messages</th></tr>{counts_table}</table>
{f'<h2>Notes</h2><ul>{notes}</ul>' if notes else ''}
</body></html>
"""
