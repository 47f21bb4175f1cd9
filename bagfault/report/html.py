"""Self-contained interactive HTML report: timeline, assertions, fault manager states, fields, media, rates.

Every time plot shares one bag-time axis (zoom one, all follow); clicking an
assertion row zooms them all to where it was decided. Built on report.page.
"""

from __future__ import annotations

import json
from typing import TYPE_CHECKING, Any

import numpy as np

from bagfault.report.fields import angle_of
from bagfault.report.page import LEGEND, Page, buckets_hit, colorscale, envelope, macros, paint, png, shade, title

if TYPE_CHECKING:
    from collections.abc import Sequence

    from bagfault.report.fields import ArrayImage, FieldPlot, MediaPlot
    from bagfault.report.rates import RateSeries, RateTracker

STATE_COLORS = {'PREFAILED': '#f4b400', 'PREPASSED': '#9ccc65', 'CONFIRMED': '#d62728', 'HEALED': '#2ca02c',
                'CLEARED': '#9e9e9e'}
ROW_PX = 90


def _windows(report: dict[str, Any], faults: set[str] | None = None) -> list[tuple[float, float, str]]:
    """Active intervals of the given faults (all faults when None)."""
    end = report['time']['duration_s'] or 0.0
    return [(w['start_s'], w['end_s'] if w['end_s'] is not None else end, w['fault_id'])
            for w in report['fault_windows'] if faults is None or w['fault_id'] in faults]


def _duration(report: dict[str, Any]) -> float:
    return float(report['time']['duration_s'] or 1.0)


def _timeline(page: Page, report: dict[str, Any], rates: RateTracker | None) -> None:
    """Fault windows as bars, assertion decisions and event-topic messages as markers, one row each."""
    data = _fault_bars(report) + _decisions(report) + _event_markers(report, rates)
    if not data:
        page.paragraph('No fault changed state and no assertion was decided.')
        return
    rows = len({str(d['y'][0]) for d in data if len(d['y'])})
    page.figure(data, {'height': 90 + 28 * rows, 'xaxis': {'title': {'text': 'bag time (s)'},
                                                            'range': [0, _duration(report)]},
                       'yaxis': {'type': 'category', 'automargin': True}, 'showlegend': True,
                       'legend': LEGEND},
                timed=True, name='timeline')


def _fault_bars(report: dict[str, Any]) -> list[dict[str, Any]]:
    """A bar per fault window, on the fault's row."""
    return [{'type': 'scatter', 'mode': 'lines', 'x': [start, end], 'y': [fault, fault],
             'line': {'width': 14, 'color': 'rgba(214,39,40,0.6)'}, 'name': fault, 'showlegend': False,
             'hovertemplate': f'{fault}: %{{x:.3f}} s<extra></extra>'}
            for start, end, fault in _windows(report)]


def _decisions(report: dict[str, Any]) -> list[dict[str, Any]]:
    """The assertions' decisions as markers, passed and failed apart."""
    data = []
    for state, color in (('passed', '#2a7d2a'), ('failed', '#c62828')):
        decided = [a for a in report['assertions'] if a['state'] == state and a['t_s'] is not None]
        if decided:
            data.append({'type': 'scatter', 'mode': 'markers', 'x': [a['t_s'] for a in decided],
                         'y': ['assertions'] * len(decided), 'text': [a['id'] for a in decided],
                         'marker': {'symbol': 'diamond', 'size': 11, 'color': color}, 'name': f'{state}',
                         'hovertemplate': '%{text} ' + state + ' at %{x:.3f} s<extra></extra>'})
    return data


def _event_markers(report: dict[str, Any], rates: RateTracker | None) -> list[dict[str, Any]]:
    """A row of markers per event topic that has messages: bagfault's, the fault manager's, the system's."""
    markers = [('/fault_injection/events', [e['t_s'] for e in report['fault_events']]),
               ('/fault_manager/events', [e['t_s'] for e in report.get('fault_manager', {}).get('events', [])])]
    if rates is not None:
        markers += [(topic, rates.seconds(topic).tolist()) for topic in sorted(rates.times)
                    if rates.is_event_topic(topic)]
    return [{'type': 'scatter', 'mode': 'markers', 'x': times, 'y': [topic] * len(times),
             'marker': {'symbol': 'line-ns-open', 'size': 12}, 'name': topic, 'showlegend': False,
             'hovertemplate': f'{topic} at %{{x:.3f}} s<extra></extra>'}
            for topic, times in markers if times]


def _assertions(page: Page, report: dict[str, Any]) -> None:
    if not report['assertions']:
        page.paragraph('No assertions in this scenario.')
        return
    span = max(1.0, 0.05 * _duration(report))
    rows = [{'state': a['state'], 'id': a['id'], 'type': a['type'], 'message': a['message'],
             't': '' if a['t_s'] is None else f'{a["t_s"]:.3f}',
             'zoom': '' if a['t_s'] is None else f'{a["t_s"] - span:.3f},{a["t_s"] + span:.3f}'}
            for a in report['assertions']]
    page.html(macros().assertions(rows))


def _fault_manager(page: Page, report: dict[str, Any], summary: dict[str, Any]) -> None:
    """Per-code state bands over bag time with confirmations marked; events folded into counts."""
    end = _duration(report)
    codes = sorted({c['fault_code'] for c in summary.get('status_changes', [])})
    if codes:
        page.figure(_state_bands(summary, codes, end),
                    {'height': 110 + 34 * len(codes), 'xaxis': {'title': {'text': 'bag time (s)'}, 'range': [0, end]},
                     'yaxis': {'type': 'category', 'automargin': True},
                     'legend': LEGEND}, timed=True, name='fault_manager_states')
    snapshots = [{'code': s['fault_code'], 't': s['t_s'], 'black_box': s['black_box'],
                  'frame': json.dumps(s['freeze_frame'], indent=1, sort_keys=True)[:4000]}
                 for s in summary['snapshots']]
    page.html(macros().fault_manager(summary, _fault_rows(summary), snapshots))


def _state_bands(summary: dict[str, Any], codes: list[str], end: float) -> list[dict[str, Any]]:
    """A band per code and status held, a legend entry per status that occurs, a star per confirmation."""
    data = _bands(summary, codes, end)
    shown = {d['name'] for d in data}
    data += [{'type': 'scatter', 'mode': 'lines', 'x': [None], 'y': [None], 'name': status,
              'line': {'width': 10, 'color': color}, 'legendgroup': status}
             for status, color in STATE_COLORS.items() if status in shown]
    confirmed = [e for e in summary['events'] if e['event_type'] == 'fault_confirmed']
    if confirmed:
        data.append({'type': 'scatter', 'mode': 'markers', 'x': [e['t_s'] for e in confirmed],
                     'y': [e['fault_code'] for e in confirmed], 'name': 'confirmed (FaultEvent)',
                     'marker': {'symbol': 'star', 'size': 13, 'color': '#000'},
                     'hovertemplate': '%{y} confirmed at %{x:.3f} s<extra></extra>'})
    return data


def _bands(summary: dict[str, Any], codes: list[str], end: float) -> list[dict[str, Any]]:
    """Each code's statuses as bands, each held until the next change (or the end of the bag)."""
    data: list[dict[str, Any]] = []
    for code in codes:
        changes = [c for c in summary['status_changes'] if c['fault_code'] == code]
        for number, change in enumerate(changes):
            until = changes[number + 1]['t_s'] if number + 1 < len(changes) else end
            data.append({'type': 'scatter', 'mode': 'lines', 'x': [change['t_s'], until], 'y': [code, code],
                         'line': {'width': 16, 'color': STATE_COLORS.get(change['status'], '#607d8b')},
                         'name': change['status'], 'legendgroup': change['status'], 'showlegend': False,
                         'hovertemplate': f'{code} {change["status"]} %{{x:.3f}} s<extra></extra>'})
    return data


def _fault_rows(summary: dict[str, Any]) -> list[dict[str, Any]]:
    """The final fault table, each code with its count of confirmed, updated and cleared events."""
    counts: dict[str, dict[str, int]] = {}
    for event in summary['events']:
        counts.setdefault(event['fault_code'], {}).setdefault(event['event_type'], 0)
        counts[event['fault_code']][event['event_type']] += 1
    kinds = ('fault_confirmed', 'fault_updated', 'fault_cleared')
    return [{'code': f['fault_code'], 'severity': f['severity'], 'status': f['status'],
             'occurrences': f['occurrence_count'], 'first': f['first_occurred_s'], 'last': f['last_occurred_s'],
             'counts': [counts.get(f['fault_code'], {}).get(k, 0) for k in kinds]} for f in summary['faults']]


INF_COLOR, NAN_COLOR = '#ff00ff', '#000000'


def _held_columns(seen: np.ndarray, width: int) -> np.ndarray:
    """For each column of the grid, the index in `seen` of the image column it shows: its own, or the nearest
    one while the topic is not silent (a 10 Hz topic on a 15 Hz grid leaves every third column empty; a heatmap
    would widen its cells to the midpoints the same way); -1 in a silence (longer than three of the topic's
    usual steps)."""
    held = np.full(width, -1)
    if not seen.size:
        return held
    usual = float(np.median(np.diff(seen))) if seen.size > 1 else 1.0
    held[seen] = np.arange(seen.size)
    for number in range(seen.size - 1):
        left, right = int(seen[number]), int(seen[number + 1])
        if 1 < right - left <= 3 * usual:
            middle = (left + right) // 2
            held[left + 1:middle + 1] = number
            held[middle + 1:right] = number + 1
    return held


def _heatmap(image: ArrayImage, text: str, axis: str, windows: list[tuple[float, float, str]],
             scale: tuple[float, float]) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """An array field as element x time: a PNG on the time grid (Viridis, inf cells magenta and nan cells
    black, columns without messages transparent) and its colour bar; a page of several holds pictures, not
    hundreds of thousands of numbers."""
    span = image.span or 1.0
    columns = np.rint(image.times / span - 0.5).astype(int)
    first = int(columns.min()) if columns.size else 0
    width = int(columns.max()) - first + 1 if columns.size else 1
    grid = np.full((max(1, image.values.shape[0]), width), np.nan)  # an array that was always empty: one row
    inf, nan = (np.zeros(grid.shape, dtype=bool) for _ in range(2))
    held = _held_columns(columns - first, width)
    if image.values.size:
        grid[:], inf[:], nan[:] = image.values[:, held], image.inf[:, held], image.nan[:, held]
    grid[:, held < 0], inf[:, held < 0], nan[:, held < 0] = np.nan, False, False
    step = float(image.elements[1] - image.elements[0]) if image.elements.size > 1 else 1.0
    start = float(image.elements[0]) if image.elements.size else 0.0
    data: list[dict[str, Any]] = [
        {'type': 'image', 'source': png(paint(grid, scale, [(inf, INF_COLOR), (nan, NAN_COLOR)])),
         'x0': (first + 0.5) * span, 'dx': span, 'y0': start, 'dy': step, 'name': 'value',
         'hovertemplate': 't %{x:.2f} s, %{y:.1f}<extra></extra>'},
        {'type': 'heatmap', 'x': [(first + 0.5) * span] * 2, 'y': [start] * 2, 'z': [[scale[0], scale[1]]],
         'zmin': scale[0], 'zmax': scale[1], 'colorscale': colorscale(), 'opacity': 0, 'hoverinfo': 'skip',
         'colorbar': {'len': 0.8}, 'name': 'scale'}]
    layout = {'title': title(text), 'height': 300,
              'xaxis': {'title': {'text': 'bag time (s)'}},
              'yaxis': {'title': {'text': axis}, 'autorange': True, 'scaleanchor': False},  # not square pixels
              'shapes': shade(windows, outline=True), 'margin': {'t': 48}}
    return data, layout


def _fields(page: Page, report: dict[str, Any], plots: Sequence[FieldPlot]) -> None:
    if not plots:
        page.paragraph('No field was changed by an active fault.')
        return
    for plot in plots:
        windows = _windows(report, set(plot.faults))
        heading = f'{plot.field} on {plot.output_topic} ({", ".join(plot.faults)})'
        if plot.before_image is not None or plot.after_image is not None:
            _image_figures(page, plot, heading, windows)
        else:
            _series_figure(page, plot, heading, windows)


def _image_figures(page: Page, plot: FieldPlot, heading: str, windows: list[tuple[float, float, str]]) -> None:
    """An array field before and after as heatmaps on one colour scale."""
    images = [i for i in (plot.before_image, plot.after_image) if i is not None and i.values.size]
    finite = [i.values[np.isfinite(i.values)] for i in images]
    values = np.concatenate(finite) if finite else np.zeros(0)
    scale = (float(values.min()), float(values.max())) if values.size else (0.0, 1.0)
    for side, image, topic in (('before', plot.before_image, plot.input_topic),
                               ('after', plot.after_image, plot.output_topic)):
        if image is not None:
            page.figure(*_heatmap(image, f'{heading}: {side} ({topic}); inf magenta, nan black',
                                  plot.element_axis, windows, scale), timed=True,
                        name=f'image:{side}:{plot.output_topic}:{plot.field}')


def _series_figure(page: Page, plot: FieldPlot, heading: str, windows: list[tuple[float, float, str]]) -> None:
    """A scalar field before and after, and their difference below (angles on the circle)."""
    bx, by = (np.asarray(v, dtype=float) for v in plot.before)
    ax, ay = (np.asarray(v, dtype=float) for v in plot.after)
    difference = ay - _aligned(bx, by, ax) if bx.size and ax.size else np.zeros(0)
    angle = angle_of(plot.field)
    if angle is not None:  # degrees on a circle: 179 after -179 is 2 more, not 358 less
        difference = (difference + 180.0) % 360.0 - 180.0
    data = [{'type': 'scatter', 'mode': 'lines', 'name': name, **xy, **extra}
            for name, xy, extra in (
                (f'before: {plot.input_topic}', _xy(bx, by), {}),
                (f'after: {plot.output_topic}', _xy(ax, ay), {}),
                ('after - before', _xy(ax[: difference.size], difference),
                 {'xaxis': 'x', 'yaxis': 'y2', 'line': {'color': '#7f7f7f'}}))]
    shown = np.concatenate([by[np.isfinite(by)], ay[np.isfinite(ay)]])
    bounds = (float(shown.min()), float(shown.max())) if shown.size else (0.0, 0.0)
    data += [*_non_finite(bx, by, 'before', bounds), *_non_finite(ax, ay, 'after', bounds)]
    page.figure(data, {'title': title(heading), 'height': 380, 'margin': {'t': 56},
                       'xaxis': {'title': {'text': 'bag time (s)'}, 'anchor': 'y2'},
                       'yaxis': {'domain': [0.38, 1], 'title': {'text': plot.field if angle is None else
                                                                 f'{angle[1]} of {angle[0]} (deg)'}},
                       'yaxis2': {'domain': [0, 0.28], 'title': {'text': 'after - before'}},
                       'shapes': shade(windows), 'legend': LEGEND},
                timed=True, name=f'field:{plot.output_topic}:{plot.field}')


def _xy(x: np.ndarray, y: np.ndarray) -> dict[str, np.ndarray]:
    """A series decimated to min/max envelopes, as trace keys."""
    ex, ey = envelope(x, y)
    return {'x': ex, 'y': ey}


def _non_finite(x: np.ndarray, y: np.ndarray, side: str, bounds: tuple[float, float]) -> list[dict[str, Any]]:
    """Markers where a scalar is nan or +-inf (a line would only show a gap): nan and +inf at the top of the
    finite values, -inf at the bottom; at most one marker per envelope bucket."""
    traces = []
    for label, mask, level, symbol, color in (
            ('nan', np.isnan(y), bounds[1], 'x', '#000000'),
            ('+inf', np.isposinf(y), bounds[1], 'triangle-up', '#ff00ff'),
            ('-inf', np.isneginf(y), bounds[0], 'triangle-down', '#ff00ff')):
        times = buckets_hit(x[mask], x[0], x[-1]) if mask.any() else np.zeros(0)
        if times.size:
            traces.append({'type': 'scatter', 'mode': 'markers', 'x': times, 'y': np.full(times.size, level),
                           'name': f'{side}: {label}', 'marker': {'symbol': symbol, 'size': 7, 'color': color},
                           'hovertemplate': f'{side} {label} at %{{x:.3f}} s<extra></extra>'})
    return traces


def _aligned(bx: np.ndarray, by: np.ndarray, ax: np.ndarray) -> np.ndarray:
    """The before value of each after message: the k-th before message with the same time for the k-th after
    message at that time (bags repeat receive times), else interpolated (a delayed message)."""
    same: dict[tuple[float, int], float] = {}
    seen: dict[float, int] = {}
    for t, v in zip(bx.tolist(), by.tolist(), strict=True):
        seen[t] = seen.get(t, -1) + 1
        same[(t, seen[t])] = v
    seen.clear()
    out = np.asarray(np.interp(ax, bx, by), dtype=float)
    for number, t in enumerate(ax.tolist()):
        seen[t] = seen.get(t, -1) + 1
        out[number] = same.get((t, seen[t]), out[number])
    return out


def _media(page: Page, report: dict[str, Any], media: Sequence[MediaPlot]) -> None:
    for item in media:
        windows = _windows(report, set(item.faults))
        heading = f'{item.output_topic} at the fault start ({item.start_s:.3f} s, {", ".join(item.faults)})'
        if item.msgtype.endswith('PointCloud2'):
            page.figure([{'type': 'scatter', 'mode': 'lines', 'x': item.counts_before[0],
                          'y': item.counts_before[1], 'name': f'before: {item.input_topic}'},
                         {'type': 'scatter', 'mode': 'lines', 'x': item.counts_after[0], 'y': item.counts_after[1],
                          'name': f'after: {item.output_topic}'}],
                        {'title': title(f'{item.output_topic} points per cloud'), 'legend': LEGEND,
                         'height': 260, 'xaxis': {'title': {'text': 'bag time (s)'}},
                         'yaxis': {'title': {'text': 'points'}}, 'shapes': shade(windows)},
                        timed=True, name=f'cloud_counts:{item.output_topic}')
            data = []
            for number, (side, snap) in enumerate((('before', item.snapshot_before), ('after', item.snapshot_after))):
                if snap is not None:
                    suffix = '' if number == 0 else '2'
                    data.append({'type': 'scatter', 'mode': 'markers', 'x': snap[0], 'y': snap[1], 'name': side,
                                 'marker': {'size': 2}, 'xaxis': f'x{suffix}', 'yaxis': f'y{suffix}'})
            page.figure(data, {'title': title(f"bird's-eye view of {heading}"),
                               'height': 380, 'grid': {'rows': 1, 'columns': 2, 'pattern': 'independent'},
                               'yaxis': {'scaleanchor': 'x'}, 'yaxis2': {'scaleanchor': 'x2'}},
                        name=f'cloud_birdseye:{item.output_topic}')
        else:
            data = []
            for number, (side, snap) in enumerate((('before', item.snapshot_before), ('after', item.snapshot_after))):
                if snap is not None:
                    suffix = '' if number == 0 else '2'
                    data.append({'type': 'image', 'z': snap, 'name': side, 'xaxis': f'x{suffix}',
                                 'yaxis': f'y{suffix}'})
            if data:
                page.figure(data, {'title': title(f'{heading}: before | after'),
                                   'height': 300, 'grid': {'rows': 1, 'columns': 2, 'pattern': 'independent'}},
                            name=f'thumbnails:{item.output_topic}')


def _broken_at(x: np.ndarray, y: np.ndarray, gaps: list[tuple[float, float]]) -> tuple[np.ndarray, np.ndarray]:
    """The series with a nan in the middle of each gap, so no line is drawn across a silence."""
    if not gaps:
        return x, y
    middles = np.array([(a + b) / 2 for a, b in gaps])
    at = np.searchsorted(x, middles)
    return np.insert(x, at, middles), np.insert(y, at, np.nan)


def _rates(page: Page, report: dict[str, Any], rates: RateTracker | None, topics: Sequence[str]) -> None:
    """Small multiples on one shared time axis: each topic's rate over a window matched to its nominal rate,
    fault windows shaded, gaps marked."""
    if rates is None:
        page.paragraph('Rates were not collected.')
        return
    shown = [t for t in topics if t in rates.times and not rates.is_event_topic(t)]
    if not shown:
        page.paragraph('No topic has enough messages for a rate.')
        return
    rows = len(shown)
    data: list[dict[str, Any]] = []
    layout: dict[str, Any] = {'height': 60 + ROW_PX * rows, 'showlegend': False, 'annotations': [],
                              'shapes': shade(_windows(report)), 'margin': {'l': 60, 'r': 20, 't': 24, 'b': 36}}
    for number, topic in enumerate(shown, start=1):
        data += _rate_row(layout, number, rows, topic, rates.series(topic), _duration(report))
    page.figure(data, layout, timed=True, name='rates')


def _rate_row(layout: dict[str, Any], number: int, rows: int, topic: str, series: RateSeries,
              duration: float) -> list[dict[str, Any]]:
    """Row `number` of `rows` (from 1, top down): its axes and title into `layout`, its traces returned (the rate,
    and its gaps as markers)."""
    gap = 0.3 / rows
    x, y = envelope(*_broken_at(series.times, series.rates, series.gaps))
    top = 1 - (number - 1) / rows
    axis = '' if number == 1 else str(number)
    layout[f'yaxis{axis}'] = {'domain': [max(0.0, top - 1 / rows + gap), top], 'rangemode': 'tozero',
                              'tickfont': {'size': 9}}
    layout[f'xaxis{axis}'] = {'anchor': f'y{axis}', 'showticklabels': number == rows,
                              **({'range': [0, duration]} if number == 1 else {'matches': 'x'}),
                              **({'title': {'text': 'bag time (s)'}} if number == rows else {})}
    data: list[dict[str, Any]] = [
        {'type': 'scatter', 'mode': 'lines', 'x': x, 'y': y, 'name': topic, 'xaxis': f'x{axis}',
         'yaxis': f'y{axis}', 'line': {'width': 1.2},
         'hovertemplate': f'{topic} %{{y:.2f}} Hz at %{{x:.3f}} s<extra></extra>'}]
    if series.gaps:
        data.append({'type': 'scatter', 'mode': 'markers', 'x': [a for a, _ in series.gaps],
                     'y': [0.0] * len(series.gaps), 'name': f'{topic} gaps', 'xaxis': f'x{axis}',
                     'yaxis': f'y{axis}', 'marker': {'symbol': 'x', 'color': '#c62828', 'size': 8},
                     'customdata': [b - a for a, b in series.gaps],
                     'hovertemplate': 'gap of %{customdata:.3f} s from %{x:.3f} s<extra></extra>'})
    layout['annotations'].append({'text': f'{topic}  ~{series.nominal_hz:.3g} Hz, window {series.window} msg',
                                  'xref': 'paper', 'yref': f'y{axis} domain', 'x': 0, 'y': 1.02,
                                  'xanchor': 'left', 'yanchor': 'bottom', 'showarrow': False,
                                  'font': {'size': 11}})
    return data


def render(
    report: dict[str, Any],
    rates: RateTracker | None = None,
    plots: Sequence[FieldPlot] = (),
    media: Sequence[MediaPlot] = (),
) -> str:
    """Whole HTML document."""
    name = report['scenario']['name']
    page = Page(f'bagfault report: {name}')
    page.html(macros().run_header(name, report['verdict'], report['assertion_counts'], report['mode'],
                                  report['inputs'], str(report['output']), report['seed'],
                                  report['time']['duration_s'], report['tool']['version']))
    page.section('Timeline')
    _timeline(page, report, rates)
    page.section('Assertions')
    _assertions(page, report)
    if 'fault_manager' in report:
        page.section('Fault manager')
        _fault_manager(page, report, report['fault_manager'])
    page.section('Before and after')
    _fields(page, report, plots)
    _media(page, report, media)
    topics = sorted(report['messages']['per_topic_written'])
    page.section('Topic rates')
    _rates(page, report, rates, topics)
    page.section('Messages written')
    page.html(macros().messages(report['messages']['per_topic_written'].items()))
    if report['notes']:
        page.section('Notes')
        page.html(macros().notes(report['notes']))
    return page.render()
