"""One self-contained HTML page of Plotly figures: the run report and the campaign report both build on it.

Plotly was chosen by measurement (bench/report_libraries.py, README): for a
one-hour bag with 50 topics it drew in 4.2 s against Bokeh's 7.8 s in
headless Chromium. The page inlines plotly.js's cartesian bundle (1.5 MB,
vendored from npm's plotly.js-cartesian-dist-min at the version the plotly
package bundles; the full bundle is 4.8 MB and parses for ~1 s more), so the
file opens offline from a CI artifact; figures use only its trace types
(scatter, heatmap, histogram, image: no WebGL traces). Every figure's JSON sits in a
`<script type="application/json">` block (tests read the data from there);
figures marked `timed` share one time axis: zooming one zooms them all, and
an element with `data-zoom="t0,t1"` zooms them all when clicked.
"""

from __future__ import annotations

import base64
import json
import struct
import zlib
from dataclasses import dataclass, field
from functools import cache
from importlib import resources
from typing import Any

import numpy as np

STYLE = """
body{font-family:system-ui,sans-serif;margin:24px;color:#222;max-width:1100px}
h1{font-size:20px} h2{font-size:16px;margin-top:28px;border-bottom:1px solid #ddd}
table{border-collapse:collapse;font-size:12px;width:100%} td,th{border:1px solid #ddd;padding:3px 6px;text-align:left}
.pass{color:#2a7d2a;font-weight:bold} .fail{color:#c62828;font-weight:bold} .verdict{font-size:18px}
tr[data-zoom]{cursor:pointer} tr[data-zoom]:hover{background:#f3f7ff} code{font-size:11px}
.figure{margin:6px 0} .muted{color:#777}
"""

SCRIPT = """
window.bagfaultErrors = [];
window.addEventListener('error', function (e) { window.bagfaultErrors.push(String(e.message)); });
(function () {
  var original = console.error;
  console.error = function () { window.bagfaultErrors.push(Array.prototype.join.call(arguments, ' '));
                                return original.apply(console, arguments); };
})();
window.addEventListener('load', function () {
  var timed = [], syncing = false;
  document.querySelectorAll('script[type="application/json"][data-figure]').forEach(function (block) {
    try {
      var spec = JSON.parse(block.textContent), div = document.getElementById(block.dataset.figure);
      Plotly.newPlot(div, spec.data, spec.layout, {responsive: true, displaylogo: false});
      if (block.dataset.timed === '1') { timed.push(div); }
    } catch (e) { window.bagfaultErrors.push(String(e)); }
  });
  function zoom(range, except) {
    syncing = true;
    var update = range ? {'xaxis.range': range} : {'xaxis.autorange': true};
    Promise.all(timed.filter(function (d) { return d !== except; }).map(function (d) {
      return Plotly.relayout(d, update);
    })).then(function () { syncing = false; }, function () { syncing = false; });
  }
  timed.forEach(function (div) {
    div.on('plotly_relayout', function (e) {
      if (syncing) { return; }
      var keys = Object.keys(e), low = keys.filter(function (k) { return /^xaxis\\d*\\.range\\[0\\]$/.test(k); });
      if (low.length) { zoom([e[low[0]], e[low[0].replace('[0]', '[1]')]], div); }
      else if (keys.some(function (k) { return /^xaxis\\d*\\.autorange$/.test(k); })) { zoom(null, div); }
    });
  });
  document.querySelectorAll('[data-zoom]').forEach(function (row) {
    row.addEventListener('click', function () { zoom(row.dataset.zoom.split(',').map(Number), null); });
  });
  document.body.dataset.figures = document.querySelectorAll('.js-plotly-plot').length;
  document.body.dataset.errors = window.bagfaultErrors.length;
});
"""

SHADE = 'rgba(214, 39, 40, 0.13)'
VIRIDIS = ('#440154', '#482878', '#3e4989', '#31688e', '#26828e', '#1f9e89', '#35b779', '#6ece58', '#b5de2b',
           '#fde725')  # plotly's sequential.Viridis


PLOTLY_JS = 'vendor/plotly-cartesian.min.js'
TRACES = frozenset({'bar', 'box', 'contour', 'heatmap', 'histogram', 'histogram2d', 'histogram2dcontour',
                    'image', 'pie', 'scatter', 'violin'})  # what the cartesian bundle draws


@cache
def plotly_js() -> str:
    """The plotly.js cartesian bundle (inlined, so the page works offline)."""
    return (resources.files('bagfault.report') / PLOTLY_JS).read_text(encoding='utf-8')


def _plain(value: Any) -> Any:
    """numpy values as JSON: arrays as lists, non-finite floats as null."""
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, (float, np.floating)):
        return float(value) if np.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    return value


@dataclass
class Page:
    """Sections of HTML and figures, rendered as one document."""

    title: str
    parts: list[str] = field(default_factory=list)
    figures: int = 0

    def html(self, text: str) -> None:
        """HTML a template made (templates/page.html.j2, or the campaign report's)."""
        self.parts.append(str(text))

    def section(self, title: str) -> None:
        """A section heading."""
        self.html(macros().section(title))

    def paragraph(self, text: str) -> None:
        """A paragraph of plain text."""
        self.html(macros().paragraph(text))

    def figure(self, data: list[dict[str, Any]], layout: dict[str, Any], *, timed: bool = False,
               name: str = '') -> None:
        """A Plotly figure; `timed` ones share the bag-time x axis."""
        unknown = {str(trace.get('type', 'scatter')) for trace in data} - TRACES
        if unknown:
            raise ValueError(f'trace types the inlined plotly.js cannot draw: {sorted(unknown)}')
        self.figures += 1
        ident = f'figure-{self.figures}'
        spec = json.dumps(_plain({'data': data, 'layout': {'margin': {'l': 60, 'r': 20, 't': 36, 'b': 36},
                                                            **layout}}), separators=(',', ':'))
        spec = spec.replace('</', '<\\/')  # JSON inside <script>: no end tag can close it early
        self.html(macros().figure(ident, int(timed), name, spec))

    def render(self) -> str:
        """The whole document."""
        return str(macros().document(self.title, STYLE, plotly_js(), SCRIPT, self.parts))


@cache
def template(package: str, name: str) -> Any:
    """The macros of a package's Jinja2 template (its `templates/` folder), autoescaped."""
    import jinja2  # noqa: PLC0415

    environment = jinja2.Environment(loader=jinja2.PackageLoader(package, 'templates'), autoescape=True,
                                     trim_blocks=True, lstrip_blocks=True, keep_trailing_newline=True)
    return environment.get_template(name).module


def macros() -> Any:
    """The report pages' HTML (templates/page.html.j2)."""
    return template('bagfault.report', 'page.html.j2')


def shade(windows: list[tuple[float, float, str]], *, outline: bool = False) -> list[dict[str, Any]]:
    """Layout shapes marking fault windows over the whole plot height: shaded below the data, or outlined
    above it (over an image, where a shade would be hidden)."""
    look = ({'fillcolor': 'rgba(0,0,0,0)', 'line': {'width': 2, 'dash': 'dash', 'color': '#d62728'}, 'layer': 'above'}
            if outline else {'fillcolor': SHADE, 'line': {'width': 0}, 'layer': 'below'})
    return [{'type': 'rect', 'xref': 'x', 'yref': 'paper', 'x0': start, 'x1': end, 'y0': 0, 'y1': 1,
             'name': fault, **look} for start, end, fault in windows]


def title(text: str) -> dict[str, Any]:
    """A figure title at the top left (legends go top right)."""
    return {'text': text, 'font': {'size': 13}, 'x': 0.01, 'xanchor': 'left'}


LEGEND = {'orientation': 'h', 'x': 1, 'xanchor': 'right', 'y': 1.0, 'yanchor': 'bottom'}


def envelope(x: np.ndarray, y: np.ndarray, buckets: int = 800) -> tuple[np.ndarray, np.ndarray]:
    """Decimate a series to min/max pairs per time bucket (extremes kept, unlike dropping points); a bucket
    holding a nan keeps one, so a break in the line (a gap, a nan value) stays a break."""
    if x.size <= 2 * buckets:
        return x, y
    index = _bucket_of(x, x[0], x[-1], buckets)
    starts = np.flatnonzero(np.r_[True, index[1:] != index[:-1]])
    out_x, out_y = [], []
    finite = np.where(np.isfinite(y), y, np.nan)
    for first, last in zip(starts, [*starts[1:], x.size], strict=True):
        chunk = finite[first:last]
        if np.all(np.isnan(chunk)):
            out_x += [x[first]]
            out_y += [np.nan]
            continue
        low, high = int(np.nanargmin(chunk)), int(np.nanargmax(chunk))
        holes = np.flatnonzero(np.isnan(chunk))
        for position in sorted({low, high, *holes[:1].tolist()}):
            out_x.append(x[first + position])
            out_y.append(chunk[position])
    return np.array(out_x), np.array(out_y)


def buckets_hit(times: np.ndarray, start: float, end: float, buckets: int = 800) -> np.ndarray:
    """The first of the given times in each of the envelope's time buckets that holds any (markers for
    events inside a decimated series: every bucket with one keeps one)."""
    if times.size <= 2 * buckets or end <= start:
        return times
    _, first = np.unique(_bucket_of(times, start, end, buckets), return_index=True)
    return times[first]


def _bucket_of(times: np.ndarray, start: float, end: float, buckets: int) -> np.ndarray:
    """The envelope bucket (0 .. buckets - 1, equal spans of start..end) of each time."""
    edges = np.linspace(start, end, buckets + 1)
    return np.clip(np.searchsorted(edges, times, side='right') - 1, 0, buckets - 1)


def colorscale(colors: tuple[str, ...] = VIRIDIS) -> list[list[Any]]:
    """Evenly spaced stops, as plotly takes them (the colour bar beside an image painted by `paint`)."""
    return [[number / (len(colors) - 1), color] for number, color in enumerate(colors)]


def paint(values: np.ndarray, scale: tuple[float, float], masks: list[tuple[np.ndarray, str]],
          colors: tuple[str, ...] = VIRIDIS) -> np.ndarray:
    """RGBA pixels of a 2-D array: finite values through the colour scale between scale[0] and scale[1], the
    cells of each mask in its colour (later masks on top), everything else transparent."""
    stops = np.array([[int(c[i:i + 2], 16) for i in (1, 3, 5)] for c in colors], dtype=float)
    positions = np.linspace(0.0, 1.0, len(colors))
    low, high = scale
    finite = np.isfinite(values)
    where = np.clip((np.where(finite, values, low) - low) / ((high - low) or 1.0), 0.0, 1.0)
    pixels = np.zeros((*values.shape, 4), dtype=np.uint8)
    for channel in range(3):
        pixels[..., channel] = np.rint(np.interp(where, positions, stops[:, channel]))
    pixels[..., 3] = np.where(finite, 255, 0)
    for mask, color in masks:
        pixels[mask] = [int(color[1:3], 16), int(color[3:5], 16), int(color[5:7], 16), 255]
    return pixels


def png(pixels: np.ndarray) -> str:
    """A data URI of an RGBA image (rows top to bottom): the HTML holds a compressed picture of an array
    (60 KB for a 360 x 300 scan image, against 2 MB of numbers in JSON)."""
    height, width = pixels.shape[:2]

    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack('>I', len(body)) + kind + body + struct.pack('>I', zlib.crc32(kind + body))

    rows = np.concatenate([np.zeros((height, 1), dtype=np.uint8), pixels.reshape(height, width * 4)], axis=1)
    data = (b'\x89PNG\r\n\x1a\n' + chunk(b'IHDR', struct.pack('>IIBBBBB', width, height, 8, 6, 0, 0, 0))
            + chunk(b'IDAT', zlib.compress(rows.tobytes(), 9)) + chunk(b'IEND', b''))
    return 'data:image/png;base64,' + base64.b64encode(data).decode()
