"""Small inline SVG charts for self-contained HTML reports (no JavaScript, no plotting library)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from html import escape

COLORS = ('#1f77b4', '#d62728', '#2ca02c', '#ff7f0e', '#9467bd', '#8c564b', '#e377c2', '#17becf')
SHADE = 'rgba(214, 39, 40, 0.12)'


def _ticks(low: float, high: float, count: int = 5) -> list[float]:
    if not math.isfinite(low) or not math.isfinite(high) or high <= low:
        return [low]
    raw = (high - low) / count
    magnitude = 10 ** math.floor(math.log10(raw))
    step = min((m * magnitude for m in (1, 2, 2.5, 5, 10) if m * magnitude >= raw), default=raw)
    first = math.ceil(low / step) * step
    return [first + i * step for i in range(int((high - first) / step) + 1)]


def _fmt(value: float) -> str:
    return f'{value:.4g}'


class Frame:
    """Maps data coordinates into a plot area with margins."""

    def __init__(self, x: tuple[float, float], y: tuple[float, float], width: int, height: int) -> None:
        self.x0, self.x1 = x if x[1] > x[0] else (x[0], x[0] + 1.0)
        self.y0, self.y1 = y if y[1] > y[0] else (y[0] - 0.5, y[0] + 0.5)
        self.width, self.height = width, height
        self.left, self.right, self.top, self.bottom = 64, 12, 28, 36

    def px(self, x: float) -> float:
        """Data x to pixels."""
        return self.left + (x - self.x0) / (self.x1 - self.x0) * (self.width - self.left - self.right)

    def py(self, y: float) -> float:
        """Data y to pixels."""
        return self.height - self.bottom - (y - self.y0) / (self.y1 - self.y0) * (self.height - self.top - self.bottom)

    def axes(self, title: str, xlabel: str, ylabel: str) -> list[str]:
        """Frame, ticks, labels and title."""
        parts = [f'<rect x="{self.left}" y="{self.top}" width="{self.width - self.left - self.right}" '
                 f'height="{self.height - self.top - self.bottom}" fill="none" stroke="#999"/>']
        for tick in _ticks(self.x0, self.x1):
            parts.append(f'<text x="{self.px(tick):.1f}" y="{self.height - self.bottom + 14}" font-size="10" '
                         f'text-anchor="middle">{_fmt(tick)}</text>')
        for tick in _ticks(self.y0, self.y1):
            parts.append(f'<text x="{self.left - 4}" y="{self.py(tick) + 3:.1f}" font-size="10" '
                         f'text-anchor="end">{_fmt(tick)}</text>')
            parts.append(f'<line x1="{self.left}" x2="{self.width - self.right}" y1="{self.py(tick):.1f}" '
                         f'y2="{self.py(tick):.1f}" stroke="#eee"/>')
        parts.append(f'<text x="{self.width / 2}" y="16" font-size="13" text-anchor="middle" '
                     f'font-weight="bold">{escape(title)}</text>')
        parts.append(f'<text x="{self.width / 2}" y="{self.height - 4}" font-size="11" '
                     f'text-anchor="middle">{escape(xlabel)}</text>')
        parts.append(f'<text x="12" y="{self.height / 2}" font-size="11" text-anchor="middle" '
                     f'transform="rotate(-90 12 {self.height / 2})">{escape(ylabel)}</text>')
        return parts


def _svg(width: int, height: int, kind: str, body: list[str]) -> str:
    return (f'<svg class="plot" data-kind="{kind}" xmlns="http://www.w3.org/2000/svg" width="{width}" '
            f'height="{height}" viewBox="0 0 {width} {height}" role="img">' + ''.join(body) + '</svg>')


def line_chart(
    series: Sequence[tuple[str, Sequence[float], Sequence[float]]],
    *,
    title: str,
    xlabel: str = 'bag time (s)',
    ylabel: str = '',
    shaded: Sequence[tuple[float, float, str]] = (),
    width: int = 760,
    height: int = 240,
    step: bool = False,
    from_zero: bool = False,
) -> str:
    """Lines (label, xs, ys) with shaded x-intervals (start, end, label)."""
    xs = [x for _, sx, _ in series for x in sx]
    ys = [y for _, _, sy in series for y in sy if math.isfinite(y)]
    if not xs:
        return _svg(width, 60, 'empty', [f'<text x="10" y="30" font-size="12">{escape(title)}: no data</text>'])
    low = 0.0 if from_zero else min(ys, default=0.0)
    high = max(ys, default=1.0) * (1.1 if from_zero else 1.0)
    frame = Frame((min(xs), max(xs)), (low, high), width, height)
    body = []
    for start, end, label in shaded:
        x0, x1 = frame.px(max(start, frame.x0)), frame.px(min(end, frame.x1))
        if x1 > x0:
            body.append(f'<rect class="fault-window" x="{x0:.1f}" y="{frame.top}" width="{x1 - x0:.1f}" '
                        f'height="{height - frame.top - frame.bottom}" fill="{SHADE}"><title>{escape(label)}</title>'
                        '</rect>')
    body += frame.axes(title, xlabel, ylabel)
    for number, (label, sx, sy) in enumerate(series):
        color = COLORS[number % len(COLORS)]
        points: list[str] = []
        segments: list[list[str]] = []
        previous_y = None
        for x, y in zip(sx, sy, strict=True):
            if not math.isfinite(y):
                if points:
                    segments.append(points)
                points, previous_y = [], None
                continue
            if step and previous_y is not None:
                points.append(f'{frame.px(x):.1f},{frame.py(previous_y):.1f}')
            points.append(f'{frame.px(x):.1f},{frame.py(y):.1f}')
            previous_y = y
        if points:
            segments.append(points)
        for points in segments:
            body.append(f'<polyline fill="none" stroke="{color}" stroke-width="1.2" points="{" ".join(points)}"/>')
        body.append(f'<text x="{frame.left + 8}" y="{frame.top + 14 + 13 * number}" font-size="11" '
                    f'fill="{color}">{escape(label)}</text>')
    return _svg(width, height, 'line', body)


def timeline(
    rows: Sequence[tuple[str, Sequence[tuple[float, float | None]]]],
    *,
    title: str,
    end: float,
    width: int = 760,
) -> str:
    """One row per fault with its active intervals (end None = until the end of the bag)."""
    height = 40 + 22 * max(1, len(rows)) + 36
    frame = Frame((0.0, max(end, 1e-9)), (0.0, float(max(1, len(rows)))), width, height)
    frame.left = 180
    body = frame.axes(title, 'bag time (s)', '')
    body = [p for p in body if 'text-anchor="end"' not in p]
    for number, (label, spans) in enumerate(rows):
        y = frame.top + 6 + 22 * number
        body.append(f'<text x="{frame.left - 6}" y="{y + 12}" font-size="11" text-anchor="end">{escape(label)}</text>')
        for start, stop in spans:
            stop = end if stop is None else stop
            x0, x1 = frame.px(start), frame.px(stop)
            body.append(f'<rect class="fault-span" x="{x0:.1f}" y="{y}" width="{max(x1 - x0, 1.5):.1f}" height="16" '
                        f'fill="{COLORS[number % len(COLORS)]}"><title>{escape(label)}: {start:.3f}-{stop:.3f} s'
                        '</title></rect>')
    return _svg(width, height, 'timeline', body)


def histogram(values: Sequence[float], *, title: str, xlabel: str, bins: int = 40, width: int = 760,
              height: int = 240) -> str:
    """Bar histogram of finite values."""
    data = [v for v in values if math.isfinite(v)]
    if not data:
        return _svg(width, 60, 'empty', [f'<text x="10" y="30" font-size="12">{escape(title)}: no data</text>'])
    low, high = min(data), max(data)
    if high == low:
        high = low + 1.0
    size = (high - low) / bins
    counts = [0] * bins
    for value in data:
        counts[min(bins - 1, int((value - low) / size))] += 1
    frame = Frame((low, high), (0.0, float(max(counts))), width, height)
    body = frame.axes(title, xlabel, 'count')
    for number, count in enumerate(counts):
        x0, x1 = frame.px(low + number * size), frame.px(low + (number + 1) * size)
        y = frame.py(count)
        body.append(f'<rect x="{x0:.1f}" y="{y:.1f}" width="{max(x1 - x0 - 1, 1):.1f}" '
                    f'height="{frame.py(0) - y:.1f}" fill="{COLORS[0]}"/>')
    return _svg(width, height, 'histogram', body)
