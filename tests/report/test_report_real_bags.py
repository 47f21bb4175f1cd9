"""The HTML report of runs on real bags (the Gazebo TurtleBot rosbag2 recording and the Nav2 MCAP), opened in
headless Chromium, judged on the data of its figures: expected values come from the bags, read with rosbags, and
from the scenarios' fault windows."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore
from support.helpers import FIXTURES, SHARED, need
from support.html_check import click_first_assertion, figures, image_cells, rendered

from bagfault.cli import main

TURTLEBOT = SHARED / 'external_bags' / 'Turtlebot_Walker_Algorithm_ROS2' / 'walker_bag_topics_list'
NAV2 = SHARED / 'external_bags' / 'evo' / 'test' / 'data' / 'nav2_turtlebot.mcap'


@pytest.fixture(scope='module')
def turtlebot(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp('turtlebot')
    assert main(['run', str(FIXTURES / 'scenarios' / 'turtlebot_report.yaml'), str(need(TURTLEBOT)),
                 '-o', str(folder / 'out.mcap'), '--html', str(folder / 'r.html')]) == 0
    return folder / 'r.html'


@pytest.fixture(scope='module')
def nav2(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp('nav2')
    assert main(['run', str(FIXTURES / 'scenarios' / 'nav2_report.yaml'), str(need(NAV2)),
                 '-o', str(folder / 'out.mcap'), '--html', str(folder / 'r.html')]) == 0
    return folder / 'r.html'


def topic_seconds(bag: Path, topic: str) -> np.ndarray:
    """Receive times of a topic from time zero (the bag's first message), read with rosbags."""
    with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
        start = reader.start_time
        return np.array([t - start for _, t, _ in reader.messages([c for c in reader.connections
                                                                    if c.topic == topic])]) / 1e9


def test_the_report_opens_in_chromium_with_every_figure_and_no_error(nav2, tmp_path):
    """(The TurtleBot page is opened by the click test below.)"""
    page = nav2
    body = rendered(page, tmp_path / 'profile')
    assert body['errors'] == '0' and int(body['figures']) == len(figures(page))


def trace(figure: dict, name: str) -> dict:
    return next(t for t in figure['data'] if t.get('name') == name)


def test_a_10_hz_topic_reads_10_hz_outside_faults(turtlebot):
    """/clock is published at 10 Hz; the bag's own start-up stall (1.6 s to 7 s, intervals up to 0.43 s) is
    real and shown as such; after it, outside the fault windows, the plotted rate stays within 10 +- 1 Hz."""
    rates = figures(turtlebot)['rates']
    clock = trace(rates, '/clock')
    x, y = np.array(clock['x'], dtype=float), np.array(clock['y'], dtype=float)
    windows = [(s['x0'], s['x1']) for s in rates['layout']['shapes']]
    assert sorted(windows) == [(10.0, 16.0), (18.0, 22.0)]
    outside = np.ones(x.size, dtype=bool)
    for start, end in windows:
        outside &= (x < start) | (x > end + 2.0)  # the 2 s window reaches past a fault's end
    settled = outside & (x > 7.5) & np.isfinite(y)
    assert settled.sum() > 50 and np.all(np.abs(y[settled] - 10.0) <= 1.0)
    raw = topic_seconds(TURTLEBOT, '/clock')
    stall = ((raw > 2.0) & (raw <= 7.0)).sum() / 5.0   # messages per second over the stall, from rosbags
    assert stall < 9.0 and np.nanmin(y[(x > 2.0) & (x < 7.0)]) < 9.0
    intervals = np.diff(raw)
    long = intervals > 3 * np.median(intervals)   # gaps: intervals over three nominal periods, from rosbags
    gaps = trace(rates, '/clock gaps')
    assert gaps['x'] == pytest.approx(raw[:-1][long].tolist(), abs=1e-6)
    assert gaps['customdata'] == pytest.approx(intervals[long].tolist(), abs=1e-6)
    for start, end in zip(raw[:-1][long], raw[1:][long], strict=True):   # no line drawn across a silence
        between = (x > start) & (x < end)
        assert between.any() and np.isnan(y[between]).all()
    event_rows = {t['y'][0] for t in figures(turtlebot)['timeline']['data'] if t['y']}
    assert {'/fault_manager/events', '/rosout', '/tf_static'} <= event_rows   # markers, not rates
    assert not any(t.get('name') in ('/rosout', '/tf_static', '/fault_manager/events') for t in rates['data'])


def test_the_blind_sector_shows_inf_inside_its_window_only(turtlebot):
    """scan_blind writes inf over -30..30 degrees from 10 s to 16 s: in the after image every sector cell is inf
    inside the window, and outside it the after image's inf cells are the input's."""
    drawn = figures(turtlebot)
    times, angles, after = image_cells(drawn['image:after:/scan:ranges[*]'])
    before_times, _, before = image_cells(drawn['image:before:/scan:ranges[*]'])
    magenta = np.array([255, 0, 255, 255])
    inf_after, inf_before = ((pixels == magenta).all(axis=2) for pixels in (after, before))
    sector = (angles <= 30.0) | (angles >= 330.0)      # the scan runs 0..360 degrees
    # a pixel column shows the scan nearest to it: inside, both scans around it are in the window (rosbags' times)
    scans = topic_seconds(TURTLEBOT, '/scan')
    after_index = np.searchsorted(scans, times)
    previous = scans[np.clip(after_index - 1, 0, scans.size - 1)]
    following = scans[np.clip(after_index, 0, scans.size - 1)]
    inside = (previous >= 10.0) & (following < 16.0) & (after_index > 0)
    outside = (times < 9.9) | (times > 16.1)
    assert inside.sum() > 50 and inf_after[np.ix_(sector, inside)].all()
    assert np.array_equal(before_times, times)
    assert np.array_equal(inf_after[:, outside], inf_before[:, outside])
    assert not inf_after[np.ix_(~sector, inside)].any() or inf_before[np.ix_(~sector, inside)].any()


def test_the_fault_manager_timeline_has_one_band_row_per_code(turtlebot, nav2):
    for page, codes in ((turtlebot, {'LIDAR_BLIND', 'IMU_DRIFT'}), (nav2, {'ODOM_JUMP', 'ODOM_LATE'})):
        states = figures(page)['fault_manager_states']
        bands = [t for t in states['data'] if t.get('mode') == 'lines' and t['x'][0] is not None]
        assert {b['y'][0] for b in bands} == codes
        for code in codes:
            mine = sorted((b['x'][0], b['x'][1], b['name']) for b in bands if b['y'][0] == code)
            assert all(a[1] == b[0] for a, b in itertools.pairwise(mine))   # contiguous, one row
            assert [m[2] for m in mine][-1] == 'HEALED' and 'CONFIRMED' in [m[2] for m in mine]
        stars = trace(states, 'confirmed (FaultEvent)')
        assert set(stars['y']) == codes


def test_scalar_fields_show_after_minus_before(nav2):
    """odom_jump adds 0.5 m to x from 30 s to 45 s: the difference trace is 0.5 there and 0 before it."""
    field = figures(nav2)['field:/odom:pose.pose.position.x']
    difference = trace(field, 'after - before')
    x, y = np.array(difference['x'], dtype=float), np.array(difference['y'], dtype=float)
    assert np.allclose(y[(x > 30.5) & (x < 44.5)], 0.5) and np.allclose(y[x < 29.5], 0.0)



def test_clicking_an_assertion_zooms_every_time_plot_to_it(turtlebot, tmp_path):
    """blind_confirmed was decided at 10.5 s; its row zooms all timed figures to 10.5 s +- max(1 s, 5% of the
    27.8 s bag)."""
    clicked, ranges, body = click_first_assertion(turtlebot, tmp_path / 'profile')
    assert body['errors'] == '0' and int(body['figures']) == len(figures(turtlebot))
    span = max(1.0, 0.05 * 27.782512332)
    assert clicked == pytest.approx([10.5 - span, 10.5 + span], abs=1e-3)
    assert len(ranges) == turtlebot.read_text().count('data-timed="1"') >= 5
    assert ranges and all(r == pytest.approx(clicked, abs=1e-3) for r in ranges)
