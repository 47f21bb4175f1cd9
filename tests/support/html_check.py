"""Open a report in headless Chromium and read back what it drew; read the figures' data from the file."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from pathlib import Path
from typing import Any

import pytest


def chromium() -> str:
    path = shutil.which('chromium') or shutil.which('chromium-browser') or shutil.which('google-chrome')
    if path is None:
        pytest.skip('headless Chromium not installed (the README test command installs it where apt is usable)')
    return path


def browser_args(profile: Path) -> list[str]:
    return [chromium(), '--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
            '--disable-background-networking', '--disable-component-update', '--disable-sync',
            f'--user-data-dir={profile}']


def rendered(page: Path, profile: Path) -> dict[str, str]:
    """The <body> attributes after load: `figures` drawn and `errors` (page errors and console.error calls)."""
    dom = subprocess.run([*browser_args(profile), '--virtual-time-budget=20000', '--dump-dom', page.as_uri()],
                         capture_output=True, text=True, timeout=180, check=True).stdout
    start = dom.index('<body')
    body = dom[start:dom.index('>', start)]
    return dict(re.findall(r'data-([a-z-]+)="([^"]*)"', body))


def figures(page: Path) -> dict[str, dict[str, Any]]:
    """Every figure's JSON by its name."""
    text = page.read_text()
    out = {}
    for name, spec in re.findall(r'<script type="application/json" data-figure="[^"]+" data-timed="\d" '
                                 r'data-name="([^"]*)">(.*?)</script>', text, re.S):
        out[name] = json.loads(spec.replace('<\\/', '</'))
    return out


def screenshot(page: Path, target: Path, profile: Path, size: str = '1200,2400') -> None:
    subprocess.run([*browser_args(profile), '--virtual-time-budget=20000', '--hide-scrollbars',
                    f'--window-size={size}', f'--screenshot={target}', page.as_uri()],
                   capture_output=True, timeout=180, check=True)


CLICK = """<script>
window.addEventListener('load', function () {
  setTimeout(function () {
    var row = document.querySelector('tr[data-zoom]');
    row.click();
    setTimeout(function () {
      var ranges = [];
      document.querySelectorAll('script[data-timed="1"]').forEach(function (block) {
        ranges.push(document.getElementById(block.dataset.figure).layout.xaxis.range);
      });
      document.body.dataset.clicked = row.dataset.zoom;
      document.body.dataset.ranges = JSON.stringify(ranges);
    }, 1000);
  }, 200);
});
</script>"""


def click_first_assertion(page: Path, profile: Path) -> tuple[list[float], list[list[float]], dict[str, str]]:
    """Open a copy of the page, click the first assertion row; (its zoom, every timed figure's x range, the body's
    attributes as `rendered` gives them)."""
    copy = profile.parent / f'clicked-{page.name}'
    copy.write_text(page.read_text().replace('</body>', CLICK + '</body>'))
    body = rendered(copy, profile)
    clicked = [float(v) for v in body['clicked'].split(',')]
    return clicked, json.loads(body['ranges'].replace('&quot;', '"')), body


def png_pixels(source: str) -> Any:
    """The pixels (height x width x channels, rows top to bottom) of a PNG data URI, decoded by the PNG
    specification (8-bit RGB or RGBA, any of the five row filters), to read back what a report's image holds."""
    import base64
    import struct
    import zlib

    import numpy as np

    data = base64.b64decode(source.split(',', 1)[1])
    assert data[:8] == b'\x89PNG\r\n\x1a\n'
    position, compressed, header = 8, b'', None
    while position < len(data):
        (length,), kind = struct.unpack_from('>I', data, position), data[position + 4:position + 8]
        body = data[position + 8:position + 8 + length]
        assert zlib.crc32(kind + body) == struct.unpack_from('>I', data, position + 8 + length)[0]
        if kind == b'IHDR':
            header = struct.unpack('>IIBBBBB', body)
        elif kind == b'IDAT':
            compressed += body
        position += 12 + length
    assert header is not None
    width, height, depth, color, _, _, interlace = header
    assert depth == 8 and color in (2, 6) and interlace == 0
    channels = 4 if color == 6 else 3
    raw = zlib.decompress(compressed)
    stride = width * channels
    out = np.zeros((height, stride), dtype=np.int32)
    for row in range(height):
        kind = raw[row * (stride + 1)]
        line = np.frombuffer(raw, np.uint8, stride, row * (stride + 1) + 1).astype(np.int32)
        above = out[row - 1] if row else np.zeros(stride, dtype=np.int32)
        for i in range(stride):
            left = out[row, i - channels] if i >= channels else 0
            corner = above[i - channels] if i >= channels else 0
            if kind == 0:
                predicted = 0
            elif kind == 1:
                predicted = left
            elif kind == 2:
                predicted = above[i]
            elif kind == 3:
                predicted = (left + above[i]) // 2
            else:
                p = left + above[i] - corner
                pa, pb, pc = abs(p - left), abs(p - above[i]), abs(p - corner)
                predicted = left if pa <= pb and pa <= pc else above[i] if pb <= pc else corner
            out[row, i] = (line[i] + predicted) & 0xFF
    return out.reshape(height, width, channels).astype(np.uint8)


def image_cells(figure: dict[str, Any]) -> tuple[Any, Any, Any]:
    """(times, elements, pixels) of a report's array image: the centre of each pixel column and row on the
    figure's axes (x0/dx, y0/dy), and the RGBA pixels with rows in element order."""
    import numpy as np

    image = next(t for t in figure['data'] if t['type'] == 'image')
    pixels = png_pixels(image['source'])
    times = image['x0'] + image['dx'] * np.arange(pixels.shape[1])
    elements = image['y0'] + image['dy'] * np.arange(pixels.shape[0])
    return times, elements, pixels


def report_of(folder: Path, streams: list[tuple[str, str, float]], seconds: float, scenario: str) -> Path:
    """`bagfault run --html` of a scenario (YAML text) on a synthetic bag of these (topic, type, rate) streams:
    the report page."""
    import textwrap

    from bagfault.cli import main
    from support.helpers import make_bag

    bag = make_bag(folder / 'in.mcap', streams, seconds)
    path = folder / 's.yaml'
    path.write_text(textwrap.dedent(scenario))
    page = folder / 'r.html'
    assert main(['run', str(path), str(bag), '-o', str(folder / 'out.mcap'), '--html', str(page)]) == 0
    return page
