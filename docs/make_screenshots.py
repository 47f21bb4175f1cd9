"""Regenerate the report screenshots shown in the README (needs ../shared and Chromium).

Run: .venv/bin/python docs/make_screenshots.py
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
BAGS = ROOT.parent / 'shared' / 'external_bags'
RUNS = {
    'report-turtlebot.png': ('turtlebot_report.yaml',
                             BAGS / 'Turtlebot_Walker_Algorithm_ROS2' / 'walker_bag_topics_list', '1200,3900'),
    'report-nav2.png': ('nav2_report.yaml', BAGS / 'evo' / 'test' / 'data' / 'nav2_turtlebot.mcap', '1200,2500'),
}


def main() -> int:
    chromium = shutil.which('chromium') or shutil.which('chromium-browser') or shutil.which('google-chrome')
    if chromium is None:
        print('needs chromium', file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory() as temp:
        folder = Path(temp)
        for picture, (scenario, bag, size) in RUNS.items():
            page = folder / f'{picture}.html'
            subprocess.run([sys.executable, '-m', 'bagfault.cli', 'run', str(ROOT / 'tests' / 'fixtures' / 'scenarios' /
                                                                         scenario), str(bag), '-o',
                            str(folder / f'{picture}.mcap'), '--html', str(page)], check=True, capture_output=True)
            subprocess.run([chromium, '--headless', '--no-sandbox', '--disable-gpu', '--hide-scrollbars',
                            f'--user-data-dir={folder / "profile"}', '--virtual-time-budget=20000',
                            f'--window-size={size}', f'--screenshot={ROOT / "docs" / picture}', page.as_uri()],
                           check=True, capture_output=True)
            print(f'docs/{picture}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
