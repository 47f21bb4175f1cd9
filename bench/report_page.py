"""The demo's HTML report: its size and the time headless Chromium takes until every figure is drawn.

    python bench/report_page.py [--repeat 5] [--json bench/results/report-page.json]

`bagfault demo` writes the page; it is timed as written (the cartesian
plotly.js bundle, array images as PNG) and, for comparison, with the full
plotly.js bundle of the plotly package inlined instead (what pages held
before). Drawn time is performance.now() when the page has drawn every
figure (bench/report_libraries.py's probe), median of `--repeat` loads, each
with a fresh browser profile.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
from datetime import date
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
from bench.report_libraries import PROBE, load_ms  # noqa: E402


def main() -> int:
    """Write the demo, time its page both ways, print and save the figures."""
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--repeat', type=int, default=5)
    parser.add_argument('--json', type=Path, default=None)
    args = parser.parse_args()
    chromium = shutil.which('chromium') or shutil.which('chromium-browser') or shutil.which('google-chrome')
    if chromium is None:
        print('needs chromium', file=sys.stderr)
        return 2
    from plotly.offline import get_plotlyjs

    results = {}
    with tempfile.TemporaryDirectory() as folder:
        subprocess.run([str(Path(sys.executable).parent / 'bagfault'), 'demo', '-o', folder], check=True,
                       stdout=subprocess.DEVNULL)
        page = Path(folder) / 'demo_report.html'
        html = page.read_text()
        probe = PROBE.format(done='return document.body.dataset.figures !== undefined;')
        bundle = r'<script>/\*\*\n\* plotly\.js \(cartesian.*?</script>'
        full = re.sub(bundle, lambda _: f'<script>{get_plotlyjs()}</script>', html, count=1, flags=re.S)
        for name, text in (('as written', html), ('full plotly.js bundle', full)):
            timed = Path(folder) / f'{name.replace(" ", "-")}.html'
            timed.write_text(text.replace('</body>', probe + '</body>'))
            times = [load_ms(timed, chromium, Path(folder) / f'profile-{name}-{i}') for i in range(args.repeat)]
            results[name] = {'bytes': len(text.encode()), 'drawn_ms_median': statistics.median(times),
                             'drawn_ms': times}
    report = {'date': date.today().isoformat(), 'load': os.getloadavg()[0], 'results': results}
    print(json.dumps(report, indent=1))
    path = args.json or HERE / 'results' / f'report-page-{report["date"]}.json'
    path.write_text(json.dumps(report, indent=1, sort_keys=True) + '\n')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
