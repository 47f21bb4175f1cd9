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
        rows = []
        for f in failures:
            files = [('original', f['original'])]
            if f['minimal']:
                files.append(('minimal', f['minimal']))
            if f['faulty_bag']:
                files.append(('faulty bag', f['faulty_bag']))
            replay = f['replay']['status'] if f['replay'] else 'not replayed'
            rows.append({**f, 'cause': cause(f['minimal_faults'] or f['original_faults']), 'files': files,
                         'replay': replay})
        page.html(str(parts.failures(rows)))
    _margins_figure(page, document)
    for f in failures:
        steps = [{**s, 'cause': cause(s['faults'])} for s in f['steps']]
        page.html(str(parts.shrink_path(f['name'], cause(f['original_faults']), steps)))
        _shrink_figure(page, document, f)
    return page.render()


def _margins_figure(page: Page, document: dict[str, Any]) -> None:
    """Each assertion's margin in each run, as a share of its margin with no fault; failures below zero."""
    runs = document['runs']
    baseline = next((r for r in runs if r['purpose'] == 'baseline'), None)
    if baseline is None:
        return
    base = {k: m for k, (m, _) in baseline['margins'].items() if m is not None and m > 0}
    traces = []
    for assertion in document['assertions']:
        xs, ys, failed_x = [], [], []
        for run in runs:
            if run['status'] == 'error':
                continue
            margin = run['margins'].get(assertion, [None, ''])[0]
            if assertion in run['failing']:
                failed_x.append(run['index'])
            elif margin is not None and assertion in base:
                xs.append(run['index'])
                ys.append(margin / base[assertion])
        if xs:
            traces.append({'type': 'scatter', 'mode': 'markers', 'name': assertion, 'x': xs, 'y': ys,
                           'marker': {'size': 5}, 'legendgroup': assertion,
                           'hovertemplate': f'{assertion}: run %{{x}}, %{{y:.3f}} of the baseline margin'
                                            '<extra></extra>'})
        if failed_x:
            traces.append({'type': 'scatter', 'mode': 'markers', 'name': f'{assertion} failed', 'x': failed_x,
                           'y': [-0.05] * len(failed_x), 'legendgroup': assertion,
                           'marker': {'symbol': 'x', 'size': 7, 'color': '#c62828'},
                           'hovertemplate': f'{assertion} failed in run %{{x}}<extra></extra>'})
    if not traces:
        return
    page.section('Margins over the search')
    page.paragraph("Each assertion's margin in each run, as a share of its margin in the baseline run (no fault): "
                   '1 is as far from failing as with no fault, 0 is at the edge; a run that failed the assertion is '
                   'a cross below zero. The search refines the runs that came closest first.')
    page.figure(traces, {'title': title('margins over the search'), 'height': 380, 'legend': LEGEND,
                         'xaxis': {'title': {'text': 'run'}},
                         'yaxis': {'title': {'text': 'margin / baseline margin'}}}, name='margins')


def _shrink_figure(page: Page, document: dict[str, Any], failure: dict[str, Any]) -> None:
    """Each dimension of the faults kept, along the kept steps, as a share of its range."""
    spans = {(f['id'], d['name']): (d['low'], d['high']) for f in document['space'] for d in f['dimensions']}
    kept = [(failure['found_at_run'], failure['original_faults'])]
    kept += [(s['run'], s['faults']) for s in failure['steps'] if s['kept']]
    series: dict[tuple[str, str], tuple[list[int], list[float]]] = {}
    for run, faults in kept:
        for drawn in faults:
            for name, value in drawn['values'].items():
                low, high = spans[(drawn['fault'], name)]
                xs, ys = series.setdefault((drawn['fault'], name), ([], []))
                xs.append(run)
                ys.append((value - low) / (high - low))
    if not series or len(kept) < 2:
        return
    traces = [{'type': 'scatter', 'mode': 'lines+markers', 'name': f'{fault}.{name.removeprefix("config.")}',
               'x': xs, 'y': ys, 'line': {'shape': 'hv'}} for (fault, name), (xs, ys) in series.items()]
    below = {'orientation': 'h', 'x': 0, 'xanchor': 'left', 'y': -0.3, 'yanchor': 'top'}  # many: under the plot
    page.figure(traces, {'title': title(f'{failure["name"]}: each dimension along the kept steps'),
                         'height': 320 + 20 * (len(traces) // 4), 'legend': below, 'xaxis': {'title': {'text': 'run'}},
                         'yaxis': {'title': {'text': 'share of its range'}, 'range': [-0.05, 1.05]}},
                name=f'shrink:{failure["name"]}')
