"""A closed-loop search finds a threshold known by construction, and identical campaigns agree on it."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from support.loop import EXAMPLE, rclpy_available

pytestmark = [pytest.mark.live, pytest.mark.closed_loop, pytest.mark.campaign]

SCENARIO = """
name: watchdog_threshold
seed: 3
system_under_test:
  command: ['{python}', monitor.py, --timeout, '0.5']
  cwd: .
  ready:
    - {subscribes: played, timeout: 30}
    - {topic: /diagnostics, publisher: true}
  stop_timeout: 10
injectors:
  - {id: odom, type: odom, input_topic: /odom, output_topic: /odom}
faults:
  - {id: odom_blackout, injector_id: odom, start: 1.0, duration: 0.3, config: {drop_probability: 1.0}}
fault_manager:
  diagnostics: {codes: {'odom_watchdog: timeout': ODOM_TIMEOUT}}
assertions:
  - {id: odom_blackout_detected, type: fault_status, code: ODOM_TIMEOUT, status: CONFIRMED, after: odom_blackout,
     within: 1.5}
"""


@pytest.mark.skipif(not rclpy_available(), reason="rclpy not installed (pip install '.[live]')")
def test_identical_closed_loop_searches_bracket_the_watchdogs_threshold(tmp_path: Path) -> None:
    import sys

    from bagfault import api

    sys.path.insert(0, str(EXAMPLE))
    try:
        import make_bag
    finally:
        sys.path.remove(str(EXAMPLE))
    make_bag.write(tmp_path / 'rover.mcap', 2.5)
    shutil.copy(EXAMPLE / 'monitor.py', tmp_path / 'monitor.py')
    (tmp_path / 'watchdog.yaml').write_text(SCENARIO)
    (tmp_path / 'campaign.yaml').write_text("""
campaign: watchdog
scenario: watchdog.yaml
mode: test
bags: [rover.mcap]
search:
  parameter: faults.odom_blackout.duration
  low: 0.1
  high: 0.9
  tolerance: 0.4
  repeat: 2
  until: {assertion: odom_blackout_detected, state: passed}
keep: none
""")
    # By construction (monitor.py): odometry at 50 Hz, so a blackout of d seconds leaves a gap of d + 0.02 s; the
    # watchdog looks every 0.2 s of ROS time and alarms once the gap exceeds 0.5 s. A gap above 0.7 s is always
    # seen, one below 0.5 s never; between, it depends on where the looks fall. So d in (0.48, 0.68] is where
    # the outcome can change: every interval found must touch it, and the two campaigns' must overlap. (Values
    # run: 0.1 and 0.9, then 0.5, where a gap of 0.52 s is seen only if a look falls in its last 0.02 s.)
    intervals = []
    for name in ('first', 'second'):
        result = api.campaign(tmp_path / 'campaign.yaml', tmp_path / name, workers=2)
        (point,) = result.breaking_points
        assert point.value is not None and point.below is not None, point.note
        assert point.below < 0.68 and point.value > 0.48, point.describe()
        assert point.value - point.below <= 0.4
        # every value was run twice, and the rule is all-or-not-holding: the top held 2 of 2, the bottom did not
        samples = {s.value: s for s in point.samples}
        assert all(s.runs == 2 for s in samples.values())
        assert samples[point.value].held == 2 and samples[point.below].held < 2
        assert samples[0.1].held == 0 and samples[0.9].held == 2  # far from the threshold, every run agrees
        recorded = json.loads((tmp_path / name / 'campaign.json').read_text())['breaking_points']
        assert recorded == [point.describe()]
        assert len([r for r in result.table.rows if r['kind'] == 'search']) == 2 * len(samples) == point.jobs
        intervals.append((point.below, point.value))
    (low1, high1), (low2, high2) = intervals
    assert max(low1, low2) <= min(high1, high2), intervals
