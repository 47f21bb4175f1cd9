"""The campaign's tables and report: results.parquet, results.csv, campaign.json, report.html.

One row per job, in job order (sweep jobs bag-major, then search rounds), so
the table is the same whatever ran the jobs. `seconds` and `cpu_s` (the
job process's CPU seconds, its system under test's included) are the only
columns that are not a function of the inputs (`MEASURED`).
"""

from __future__ import annotations

import csv
import io
import json
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from bagfault.errors import CampaignError
from bagfault.io.outputs import write_atomic
from bagfault.report.page import LEGEND, Page, template, title

if TYPE_CHECKING:
    from bagfault.campaign.plan import Bag, Job, Plan
    from bagfault.campaign.search import BreakingPoint

FIXED = ('job', 'kind', 'bag', 'seed')
# the rate tables' colours (hue 0 at 0 % passed to 120 at 100 %): plotly.js has no 'RdYlGn', and its fallback
# drew 100 % passed in deep red
PASS_COLORS = [[0.0, 'hsl(0,65%,60%)'], [0.5, 'hsl(60,65%,60%)'], [1.0, 'hsl(120,65%,45%)']]
TAIL = ('status', 'message', 'warnings')


@dataclass
class Table:
    """Columns in order and one dict per row."""

    columns: list[str]
    rows: list[dict[str, Any]]
    parameters: list[str]
    assertions: list[str]

    def sweep_rows(self) -> list[dict[str, Any]]:
        """The rows of the sweep (not of the search)."""
        return [r for r in self.rows if r['kind'] == 'sweep']


def bag_name(plan: Plan, bag: Bag) -> str:
    """A bag as the table shows it: its URL, or relative to the campaign file's folder when inside it."""
    if not isinstance(bag, Path):
        return str(bag)
    base = plan.campaign.source.parent.absolute() if plan.campaign.source is not None else Path.cwd()
    try:  # as the campaign names it: a symlinked folder of bags keeps its name
        return str(bag.absolute().relative_to(base))
    except ValueError:
        return str(bag.absolute())


MEASURED = ('seconds', 'cpu_s')  # columns measured as the job ran: wall and CPU seconds


def make_table(plan: Plan, done: list[tuple[Job, dict[str, Any], str]], assertions: list[str]) -> Table:
    """Rows of (job, its result, its kept output relative to the campaign folder or '')."""
    parameters = list(plan.campaign.sweep)
    search = plan.campaign.search
    if search is not None and search.parameter not in parameters:
        parameters.append(search.parameter)
    codes = sorted({code for _, result, _ in done for code in result.get('detections', {})})
    columns = [*FIXED, *parameters, *TAIL]
    for a in assertions:
        columns += [a, f'{a}.value', f'{a}.unit', f'{a}.t_s']
    columns += [f'{code}.confirmed_s' for code in codes] + [*MEASURED, 'output', 'key']  # (no assertion suffix)
    rows = [_row(plan, job, result, output, parameters, assertions, codes) for job, result, output in done]
    return Table(columns, rows, parameters, assertions)


def _row(plan: Plan, job: Job, result: dict[str, Any], output: str, parameters: list[str], assertions: list[str],
         codes: list[str]) -> dict[str, Any]:
    """One job's row: its parameters, status, each assertion's outcome, each code's detection, what it cost."""
    row: dict[str, Any] = {'job': job.index, 'kind': job.kind, 'bag': bag_name(plan, job.bag), 'seed': job.seed}
    row.update({p: job.values.get(p) for p in parameters})
    row['status'], row['message'] = result['status'], result.get('message') or None
    row['warnings'] = '; '.join(result.get('warnings') or []) or None  # what the job's run warned about
    for a in assertions:
        got = result.get('assertions', {}).get(a, {})
        row[a], row[f'{a}.value'] = got.get('state'), got.get('value')
        row[f'{a}.unit'], row[f'{a}.t_s'] = got.get('unit') or None, got.get('t_s')
    for code in codes:
        row[f'{code}.confirmed_s'] = result.get('detections', {}).get(code)
    row['seconds'], row['cpu_s'] = result.get('seconds'), result.get('cpu_s')
    row['output'], row['key'] = output or None, job.key
    return row


def _kind(values: list[Any]) -> str:
    """The column type of `values` (Nones aside): bool, int, float (ints and floats), else string."""
    kinds = {_scalar_kind(v) for v in values if v is not None}
    if kinds == {'bool'}:
        return 'bool'
    if kinds <= {'int'}:
        return 'int'
    return 'float' if kinds <= {'int', 'float'} else 'string'


def _scalar_kind(value: Any) -> str:
    if isinstance(value, bool):
        return 'bool'
    if isinstance(value, int):
        return 'int'
    return 'float' if isinstance(value, float) else 'string'


def _cell(value: Any, kind: str) -> Any:
    if value is None:
        return None
    if kind == 'string' and not isinstance(value, str):
        return json.dumps(value, sort_keys=True)
    if kind == 'float':
        return float(value)
    return value


def parquet_available() -> bool:
    """True when pyarrow can be imported (the campaign extra)."""
    try:
        import pyarrow  # noqa: F401, PLC0415
    except ImportError:
        return False
    return True


def write_parquet(table: Table, path: Path, metadata: dict[str, str] | None = None) -> None:
    """results.parquet, typed columns (parameters numeric when every value is a number), and `metadata` (what
    made it: the campaign, bagfault's version, the scenario's digest) in the file's key-value metadata."""
    try:
        import pyarrow as pa  # noqa: PLC0415
        import pyarrow.parquet as pq  # noqa: PLC0415
    except ImportError:
        raise CampaignError('results.parquet needs pyarrow: pip install "bagfault[campaign]"') from None
    arrays, fields = [], []
    types = {'bool': pa.bool_(), 'int': pa.int64(), 'float': pa.float64(), 'string': pa.string()}
    for column in table.columns:
        values = [row.get(column) for row in table.rows]
        kind = 'int' if column == 'seed' else _kind(values)
        arrays.append(pa.array([_cell(v, kind) for v in values], type=types[kind] if column != 'seed' else pa.uint64()))
        fields.append(pa.field(column, arrays[-1].type))
    buffer = pa.BufferOutputStream()
    schema = pa.schema(fields, metadata={f'bagfault.{k}': v for k, v in (metadata or {}).items()})
    pq.write_table(pa.Table.from_arrays(arrays, schema=schema), buffer)
    write_atomic(path, buffer.getvalue().to_pybytes(), 'table')


def write_csv(table: Table, path: Path) -> None:
    """results.csv, the same columns; empty cells for missing values."""
    text = io.StringIO()
    writer = csv.writer(text, lineterminator='\n')
    writer.writerow(table.columns)
    for row in table.rows:
        writer.writerow(['' if row.get(c) is None else _csv(row[c]) for c in table.columns])
    write_atomic(path, text.getvalue(), 'table')


def _csv(value: Any) -> str:
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, (dict, list)):
        return json.dumps(value, sort_keys=True)
    return str(value)


# -- report.html --------------------------------------------------------------------------------------

STYLE = """
td.l,th.l{text-align:left} td,th{text-align:right} th{background:#f4f4f4} table{width:auto;margin:.5em 0}
"""


def _label(value: Any) -> str:
    """A parameter value as the tables and figures show it (plain text: the template escapes it)."""
    return f'{value:g}' if isinstance(value, float) else str(value)


def _order(values: list[Any]) -> list[Any]:
    seen: list[Any] = []
    for v in values:
        if v not in seen:
            seen.append(v)
    return seen


def _passes(group: list[dict[str, Any]], column: str = 'status') -> dict[str, int]:
    decided = [r for r in group if r[column] is not None]
    return {'passed': sum(r[column] == 'passed' for r in decided), 'total': len(decided)}


def render_report(plan: Plan, table: Table, points: list[BreakingPoint], engine: str) -> str:
    """A one-file HTML page: pass rates per parameter value (table and plot), a heatmap of two parameters,
    breaking points with the search's jobs, failed jobs with links to their kept outputs. The HTML comes from a
    Jinja2 template, the figures from Plotly, between its sections."""
    c = plan.campaign
    rows = table.sweep_rows()
    counts = {s: sum(r['status'] == s for r in rows) for s in ('passed', 'failed', 'error')}
    page = Page(f'{c.name}: bagfault campaign')
    parts = template('bagfault.campaign', 'report.html.j2')
    page.html(str(parts.header(c.name, str(c.scenario), c.mode, len(plan.bags), len(rows), counts, engine, STYLE)))
    _per_bag(page, parts, rows, table)
    for parameter in table.parameters:
        _per_value(page, parts, rows, table, parameter, [r[parameter] for r in rows if parameter in c.sweep])
    _rest(page, parts, plan, table, points)
    return page.render()


def _rest(page: Page, parts: Any, plan: Plan, table: Table, points: list[BreakingPoint]) -> None:
    """The report after the pass rates: the heatmap of two swept parameters, the breaking points, the jobs that
    did not pass."""
    rows = table.sweep_rows()
    swept = list(plan.campaign.sweep)
    if len(swept) >= 2:
        _heatmap(page, parts, rows, swept[0], swept[1])
    if points:
        _breaking_points(page, parts, plan, table, points)
    bad = [_bad_job(r, swept) for r in rows if r['status'] != 'passed']
    if bad:
        page.html(str(parts.bad_table(swept, bad)))


def _bad_job(row: dict[str, Any], swept: list[str]) -> dict[str, Any]:
    """A job that did not pass, as the report's table lists it."""
    output = row['output']
    return {'job': row['job'], 'bag': row['bag'], 'swept': [_label(row[p]) for p in swept], 'seed': row['seed'],
            'status': row['status'], 'message': row['message'] or '', 'output': output or '',
            'output_name': Path(output).name if output else ''}


def _per_bag(page: Page, parts: Any, rows: list[dict[str, Any]], table: Table) -> None:
    """Pass rates per bag, first: a bag that lacks a topic shows here, not as a lower rate of every value."""
    bags = _order([r['bag'] for r in rows])
    if len(bags) > 1:
        lines = [{'label': bag, 'cells': [_passes(group), *(_passes(group, a) for a in table.assertions)]}
                 for bag in bags for group in [[r for r in rows if r['bag'] == bag]]]
        page.html(str(parts.rate_table('bag', ['job passed', *table.assertions], lines)))


def _per_value(page: Page, parts: Any, rows: list[dict[str, Any]], table: Table, parameter: str,
               swept: list[Any]) -> None:
    """Pass rates at each value of one swept parameter: a table and a plot."""
    values = _order(swept)
    if not values:
        return
    lines = []
    for value in values:
        group = [r for r in rows if r[parameter] == value]
        cells = [_passes(group), *(_passes(group, a) for a in table.assertions)]
        lines.append({'label': _label(value), 'cells': cells})
    page.html(str(parts.rate_table(parameter, ['job passed', *table.assertions], lines)))
    _pass_rate_figure(page, parameter, values, rows, table.assertions)


def _heatmap(page: Page, parts: Any, rows: list[dict[str, Any]], first: str, second: str) -> None:
    """Jobs passed at each pair of values of the first two swept parameters: a grid and a heatmap."""
    xs, ys = _order([r[second] for r in rows]), _order([r[first] for r in rows])
    groups = [[_group(rows, {first: y, second: x}) for x in xs] for y in ys]
    page.html(str(parts.grid_table(first, second, [_label(x) for x in xs], _grid_lines(ys, groups))))
    rates = [[_rate(group) for group in line] for line in groups]
    page.figure([{'type': 'heatmap', 'x': [_label(x) for x in xs], 'y': [_label(y) for y in ys], 'z': rates,
                  'zmin': 0, 'zmax': 100, 'colorscale': PASS_COLORS, 'colorbar': {'title': {'text': '% passed'}},
                  'hovertemplate': f'{second} %{{x}}, {first} %{{y}}: %{{z:.0f}}% passed<extra></extra>'}],
                _heatmap_layout(first, second), name=f'heatmap:{first}:{second}')


def _grid_lines(ys: list[Any], groups: list[list[list[dict[str, Any]]]]) -> list[dict[str, Any]]:
    """The grid table's lines: each value of the first parameter, its jobs passed at each of the second's."""
    return [{'label': _label(y), 'cells': [_passes(group) for group in line]}
            for y, line in zip(ys, groups, strict=True)]


def _heatmap_layout(first: str, second: str) -> dict[str, Any]:
    return {'title': title(f'jobs passed: {first} against {second}'), 'height': 320,
            'xaxis': {'type': 'category', 'title': {'text': second}},
            'yaxis': {'type': 'category', 'title': {'text': first}}}


def _breaking_points(page: Page, parts: Any, plan: Plan, table: Table, points: list[BreakingPoint]) -> None:
    """Each bag's breaking point of the searched parameter, and the search's jobs."""
    search = plan.campaign.search
    assert search is not None
    shown = [{'bag': bag_name(plan, p.bag), 'holds': '-' if p.value is None else _label(p.value),
              'below': '-' if p.below is None else _label(p.below), 'jobs': p.jobs, 'note': p.note,
              'samples': ', '.join(s.describe() for s in p.samples)} for p in points]
    page.html(str(parts.points_table(search.parameter, search.until.assertion, search.until.state,
                                     f'{search.tolerance:g}', shown)))
    _search_figure(page, search.parameter, [r for r in table.rows if r['kind'] == 'search'], points, plan)


def _group(rows: list[dict[str, Any]], values: dict[str, Any]) -> list[dict[str, Any]]:
    """The rows with these values of these columns."""
    return [r for r in rows if all(r[column] == value for column, value in values.items())]


def _rate(group: list[dict[str, Any]], column: str = 'status') -> float | None:
    decided = [r for r in group if r[column] is not None]
    return 100.0 * sum(r[column] == 'passed' for r in decided) / len(decided) if decided else None


def _pass_rate_figure(page: Page, parameter: str, values: list[Any], rows: list[dict[str, Any]],
                      assertions: list[str]) -> None:
    """Share of passed jobs (and of each assertion) at each value of one swept parameter."""
    numeric = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values)
    x = values if numeric else [_label(v) for v in values]
    data = [{'type': 'scatter', 'mode': 'lines+markers', 'x': x, 'name': name,
             'y': _rates(rows, parameter, values, column)}
            for name, column in (('job passed', 'status'), *((a, a) for a in assertions))]
    page.figure(data, {'title': title(f'pass rate against {parameter}'), 'height': 320, 'legend': LEGEND,
                       'xaxis': {'title': {'text': parameter}, **({} if numeric else {'type': 'category'})},
                       'yaxis': {'title': {'text': '% passed'}, 'range': [-5, 105]}}, name=f'pass_rate:{parameter}')


def _rates(rows: list[dict[str, Any]], parameter: str, values: list[Any], column: str) -> list[float | None]:
    """The pass rate (%) of a column at each value of a parameter."""
    return [_rate([r for r in rows if r[parameter] == v], column) for v in values]


def _search_trace(parameter: str, state: str, color: str, chosen: list[dict[str, Any]]) -> dict[str, Any]:
    """The search's jobs of one state, at their parameter value on their bag's line."""
    return {'type': 'scatter', 'mode': 'markers', 'x': [r[parameter] for r in chosen], 'y': [r['bag'] for r in chosen],
            'name': state, 'marker': {'size': 10, 'color': color}, 'text': [f'job {r["job"]}' for r in chosen]}


def _search_traces(parameter: str, search: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The search's jobs as a trace per state that occurs."""
    return [_search_trace(parameter, state, color, chosen)
            for state, color in (('passed', '#2a7d2a'), ('failed', '#c62828'), ('error', '#616161'))
            for chosen in [[r for r in search if r['status'] == state]] if chosen]


def _search_figure(page: Page, parameter: str, search: list[dict[str, Any]], points: list[BreakingPoint],
                   plan: Plan) -> None:
    """Every search job at its parameter value, passed or not, and each bag's breaking point."""
    data = _search_traces(parameter, search)
    found = [p for p in points if p.value is not None]
    if found:
        data.append({'type': 'scatter', 'mode': 'markers', 'x': [p.value for p in found], 'name': 'breaking point',
                     'y': [bag_name(plan, p.bag) for p in found],
                     'marker': {'symbol': 'line-ns-open', 'size': 26, 'line': {'width': 3}, 'color': '#000'}})
    page.figure(data, {'title': title(f'search of {parameter}'), 'height': 160 + 40 * len(points),
                       'legend': LEGEND, 'xaxis': {'title': {'text': parameter}},
                       'yaxis': {'type': 'category', 'automargin': True}}, name=f'search:{parameter}')

