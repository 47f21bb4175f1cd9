"""report.html of an exploration: the failures with their minimal causes, each shrink path, the margins over the
search. Built from explore.json's document alone, so the page of a finished exploration can be made again."""

from __future__ import annotations

from typing import Any

from bagfault.report.page import LEGEND, STYLE, Page, template, title


def cause(faults: list[dict[str, Any]] | None) -> str:
    """'yaw_bias(angular_velocity_z_bias=0.3, start=8) + ...' of explore.json's faults."""
    if faults is None:
        return '-'
    return ' + '.join(f'{f["fault"]}(' + ', '.join(f'{n.removeprefix("config.")}={v:g}' for n, v in
                                                      f['values'].items()) + ')' for f in faults) or 'no fault'


def render_report(document: dict[str, Any]) -> str:
    """The whole page."""
    parts = template('bagfault.explore', 'report.html.j2')
    failures = document['failures']
    counts = {'shrunk': sum(f['state'] == 'shrunk' for f in failures),
              'unconfirmed': sum(f['state'] == 'unconfirmed' for f in failures),
              'search': sum(r['purpose'] in ('search', 'refine') for r in document['runs'])}
    heading = f'bagfault explore: {document["scenario"]}'
    page = Page(heading)
    page.html(f'<style>{STYLE}</style>')
    page.html(str(parts.header(document, counts, heading)))
    if document.get('baseline_warnings'):  # the clock check's among them: what every run's verdicts rest on
        page.html(str(parts.warnings(document['baseline_warnings'])))
    if failures:
        page.section('Failures')
        page.html(str(parts.failures([_failure_row(f) for f in failures])))
    _margins_figure(page, document)
    for f in failures:
        steps = [{**s, 'cause': cause(s['faults'])} for s in f['steps']]
        page.html(str(parts.shrink_path(f['name'], cause(f['original_faults']), steps)))
        _shrink_figure(page, document, f)
    return page.render()


def _failure_row(failure: dict[str, Any]) -> dict[str, Any]:
    """A failure's row: its cause (the minimal one when shrunk), its files and how its replay went."""
    files = [('original', failure['original'])]
    if failure['minimal']:
        files.append(('minimal', failure['minimal']))
    if failure['faulty_bag']:
        files.append(('faulty bag', failure['faulty_bag']))
    replay = failure['replay']['status'] if failure['replay'] else 'not replayed'
    return {**failure, 'cause': cause(failure['minimal_faults'] or failure['original_faults']), 'files': files,
            'replay': replay}


def _margins_figure(page: Page, document: dict[str, Any]) -> None:
    """Each assertion's margin in each run, as a share of its margin with no fault; failures below zero."""
    runs = document['runs']
    baseline = next((r for r in runs if r['purpose'] == 'baseline'), None)
    if baseline is None:
        return
    base = {k: m for k, (m, _) in baseline['margins'].items() if m is not None and m > 0}
    traces = []
    for assertion in document['assertions']:
        traces += _margin_traces(assertion, *_margins(runs, assertion, base.get(assertion)))
    if not traces:
        return
    page.section('Margins over the search')
    page.paragraph("Each assertion's margin in each run, as a share of its margin in the baseline run (no fault): "
                   '1 is as far from failing as with no fault, 0 is at the edge; a run that failed the assertion is '
                   'a cross below zero. The search refines the runs that came closest first.')
    page.figure(traces, {'title': title('margins over the search'), 'height': 380, 'legend': LEGEND,
                         'xaxis': {'title': {'text': 'run'}},
                         'yaxis': {'title': {'text': 'margin / baseline margin'}}}, name='margins')


def _margin_traces(assertion: str, xs: list[int], ys: list[float], failed_x: list[int]) -> list[dict[str, Any]]:
    """An assertion's margins as dots, and its failures as crosses below zero (each only when there are some)."""
    traces = []
    if xs:
        traces.append({'type': 'scatter', 'mode': 'markers', 'name': assertion, 'x': xs, 'y': ys,
                       'marker': {'size': 5}, 'legendgroup': assertion,
                       'hovertemplate': f'{assertion}: run %{{x}}, %{{y:.3f}} of the baseline margin<extra></extra>'})
    if failed_x:
        traces.append({'type': 'scatter', 'mode': 'markers', 'name': f'{assertion} failed', 'x': failed_x,
                       'y': [-0.05] * len(failed_x), 'legendgroup': assertion,
                       'marker': {'symbol': 'x', 'size': 7, 'color': '#c62828'},
                       'hovertemplate': f'{assertion} failed in run %{{x}}<extra></extra>'})
    return traces


def _margins(runs: list[dict[str, Any]], assertion: str, base: float | None,
             ) -> tuple[list[int], list[float], list[int]]:
    """The runs where the assertion held, with its margin as a share of `base` (the baseline's, when above 0),
    and the runs where it failed; runs that could not run are left out."""
    xs: list[int] = []
    ys: list[float] = []
    failed_x: list[int] = []
    for run in runs:
        if run['status'] == 'error':
            continue
        margin = run['margins'].get(assertion, [None, ''])[0]
        if assertion in run['failing']:
            failed_x.append(run['index'])
        elif margin is not None and base is not None:
            xs.append(run['index'])
            ys.append(margin / base)
    return xs, ys, failed_x


def _shrink_figure(page: Page, document: dict[str, Any], failure: dict[str, Any]) -> None:
    """Each dimension of the faults kept, along the kept steps, as a share of its range."""
    kept = [(failure['found_at_run'], failure['original_faults'])]
    kept += [(s['run'], s['faults']) for s in failure['steps'] if s['kept']]
    series = _shares(document, kept)
    if not series or len(kept) < 2:
        return
    traces = [{'type': 'scatter', 'mode': 'lines+markers', 'name': f'{fault}.{name.removeprefix("config.")}',
               'x': xs, 'y': ys, 'line': {'shape': 'hv'}} for (fault, name), (xs, ys) in series.items()]
    below = {'orientation': 'h', 'x': 0, 'xanchor': 'left', 'y': -0.3, 'yanchor': 'top'}  # many: under the plot
    page.figure(traces, {'title': title(f'{failure["name"]}: each dimension along the kept steps'),
                         'height': 320 + 20 * (len(traces) // 4), 'legend': below, 'xaxis': {'title': {'text': 'run'}},
                         'yaxis': {'title': {'text': 'share of its range'}, 'range': [-0.05, 1.05]}},
                name=f'shrink:{failure["name"]}')


def _shares(document: dict[str, Any], kept: list[tuple[int, list[dict[str, Any]]]],
            ) -> dict[tuple[str, str], tuple[list[int], list[float]]]:
    """(fault, dimension) -> the runs of the kept steps and the dimension's value there, as a share of its range."""
    spans = {(f['id'], d['name']): (d['low'], d['high']) for f in document['space'] for d in f['dimensions']}
    series: dict[tuple[str, str], tuple[list[int], list[float]]] = {}
    for run, faults in kept:
        for drawn in faults:
            for name, value in drawn['values'].items():
                low, high = spans[(drawn['fault'], name)]
                xs, ys = series.setdefault((drawn['fault'], name), ([], []))
                xs.append(run)
                ys.append((value - low) / (high - low))
    return series
