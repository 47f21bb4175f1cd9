"""Which plotting library the HTML report uses: page size and load time in headless Chromium.

A one-hour bag with 50 topics: one rate plot per topic, decimated to 1000
min/max buckets (2000 points each), all sharing one time axis, drawn by each
candidate as one self-contained file; then bagfault's own report page for
such an hour (50 topics of 1 to 50 Hz, 4.6 million message times). Load time is performance.now() when
every plot has drawn (polled in the page), read back from the DOM, median of
three runs. Needs Bokeh besides bagfault's own plotly (`pip install bokeh`).
Run: .venv/bin/python bench/report_libraries.py
"""

from __future__ import annotations

import json
import shutil
import statistics
import subprocess
import sys
import tempfile
from array import array
from pathlib import Path

import numpy as np

TOPICS, SECONDS, BUCKETS = 50, 3600, 1000

PROBE = """<script>
(function () {{
  var start = performance.now();
  function done() {{ {done} }}
  function poll() {{
    if (done()) {{ document.body.setAttribute('data-drawn-ms', String(performance.now())); return; }}
    setTimeout(poll, 5);
  }}
  window.addEventListener('load', poll);
}})();
</script>"""


def series() -> list[tuple[str, np.ndarray, np.ndarray]]:
    """Per topic: bucket times and a min/max envelope of a noisy rate."""
    rng = np.random.default_rng(0)
    out = []
    for number in range(TOPICS):
        rate = 10.0 * (1 + number % 5)
        x = np.repeat(np.linspace(0, SECONDS, BUCKETS), 2)
        y = rate + rng.normal(0, rate * 0.02, x.size)
        out.append((f'/topic_{number:02d}', x, y))
    return out


def plotly_page(data: list[tuple[str, np.ndarray, np.ndarray]]) -> str:
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots

    figure = make_subplots(rows=TOPICS, cols=1, shared_xaxes=True, vertical_spacing=0.002,
                           subplot_titles=[name for name, _, _ in data])
    for row, (name, x, y) in enumerate(data, start=1):
        figure.add_trace(go.Scatter(x=x, y=y, name=name, mode='lines'), row=row, col=1)
    figure.update_layout(height=180 * TOPICS, showlegend=False)
    html = figure.to_html(include_plotlyjs=True, full_html=True)
    probe = PROBE.format(done="return document.querySelectorAll('.main-svg').length >= 1;")
    return html.replace('</body>', probe + '</body>')


def bokeh_page(data: list[tuple[str, np.ndarray, np.ndarray]]) -> str:
    from bokeh.embed import file_html
    from bokeh.layouts import column
    from bokeh.models import Range1d
    from bokeh.plotting import figure
    from bokeh.resources import INLINE

    shared = Range1d(0, SECONDS)
    plots = []
    for name, x, y in data:
        plot = figure(title=name, height=160, width=800, x_range=shared,
                      tools='xpan,xwheel_zoom,box_zoom,reset,hover')
        plot.line(x, y)
        plots.append(plot)
    html = file_html(column(*plots), INLINE, 'bench')
    probe = PROBE.format(done='return !!(window.Bokeh && Bokeh.index && Object.keys(Bokeh.index).length);')
    return html.replace('</body>', probe + '</body>')


def bagfault_page(data: list[tuple[str, np.ndarray, np.ndarray]]) -> str:
    """bagfault's own report page for the same hour: 50 topics of 1 to 50 Hz, every message time kept."""
    from bagfault.report.html import render
    from bagfault.report.rates import RateTracker

    tracker = RateTracker()
    rng = np.random.default_rng(1)
    for number, (name, _, _) in enumerate(data):
        rate = 1.0 + number
        times = np.arange(0, SECONDS, 1.0 / rate) + rng.normal(0, 0.002 / rate, int(np.ceil(SECONDS * rate)))
        tracker.times[name] = array('q', (np.sort(times) * 1e9).astype(np.int64).tolist())
    report = {'scenario': {'name': 'bench'}, 'verdict': 'passed', 'assertion_counts': {'passed': 0, 'failed': 0},
              'mode': 'run', 'inputs': ['bench.mcap'], 'output': 'out.mcap', 'seed': 0,
              'time': {'duration_s': float(SECONDS)}, 'tool': {'version': 'bench'}, 'fault_windows': [],
              'fault_events': [], 'assertions': [], 'injectors': [], 'notes': [],
              'messages': {'per_topic_written': {name: 1 for name, _, _ in data}}}
    html = render(report, tracker)
    probe = PROBE.format(done='return document.body.dataset.figures !== undefined;')
    return html.replace('</body>', probe + '</body>')


def load_ms(page: Path, chromium: str, profile: Path) -> float:
    dom = subprocess.run(
        [chromium, '--headless', '--no-sandbox', '--disable-gpu', '--no-first-run', '--disable-sync',
         f'--user-data-dir={profile}', '--virtual-time-budget=30000', '--dump-dom', page.as_uri()],
        capture_output=True, text=True, timeout=300, check=True).stdout
    marker = 'data-drawn-ms="'
    if marker not in dom:
        return float('nan')
    return float(dom.split(marker)[1].split('"')[0])


def main() -> int:
    chromium = shutil.which('chromium') or shutil.which('chromium-browser') or shutil.which('google-chrome')
    if chromium is None:
        print('needs chromium', file=sys.stderr)
        return 2
    data = series()
    results = {}
    with tempfile.TemporaryDirectory() as folder:
        for name, build in (('plotly', plotly_page), ('bokeh', bokeh_page), ('bagfault report', bagfault_page)):
            page = Path(folder) / f'{name}.html'
            page.write_text(build(data))
            times = [load_ms(page, chromium, Path(folder) / f'profile-{name}-{i}') for i in range(3)]
            results[name] = {'bytes': page.stat().st_size, 'drawn_ms_median': statistics.median(times),
                             'drawn_ms': times}
    print(json.dumps(results, indent=1))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
