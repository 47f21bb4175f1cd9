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
