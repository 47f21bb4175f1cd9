"""Faulted PointCloud2 and Image topics in the HTML report: point counts, the bird's-eye view and thumbnails at
the fault start, compared with the synthetic generator's own points and pixels."""

from __future__ import annotations

import numpy as np
import pytest
from support.html_check import figures, report_of

from bagfault.demo import synthetic


def test_cloud_and_image_at_the_fault_start(tmp_path):
    page = report_of(tmp_path, [('/cloud', 'sensor_msgs/msg/PointCloud2', 5.0),
                                ('/camera', 'sensor_msgs/msg/Image', 5.0)], 6.0, """
        injectors:
          - {id: lidar, type: pointcloud2, input_topic: /cloud, output_topic: /cloud_out}
          - {id: camera, type: image, input_topic: /camera, output_topic: /camera_out}
        faults:
          - {id: thin, injector_id: lidar, start: 2.0, duration: 2.0, config: {dropout_probability: 0.5}}
          - {id: dark, injector_id: camera, start: 2.0, duration: 2.0, config: {black_frame: true}}
    """)
    drawn = figures(page)
    counts = {t['name']: t for t in drawn['cloud_counts:/cloud_out']['data']}
    before, after = counts['before: /cloud'], counts['after: /cloud_out']
    assert set(before['y']) == {2000.0}
    inside = [n for t, n in zip(after['x'], after['y'], strict=True) if 2.0 <= t < 4.0]
    outside = [n for t, n in zip(after['x'], after['y'], strict=True) if t < 2.0 or t >= 4.0]
    assert len(inside) == 10 and all(800 < n < 1200 for n in inside) and set(outside) == {2000.0}
    # the first cloud at or after 2.0 s is the one at 2.0 s: its points as the generator makes them
    view = {t['name']: t for t in drawn['cloud_birdseye:/cloud_out']['data']}
    points = synthetic.cloud_points(2.0, 2000)
    assert np.allclose(view['before']['x'], points[:, 0].astype(np.float32), atol=1e-6)
    assert np.allclose(view['before']['y'], points[:, 1].astype(np.float32), atol=1e-6)
    assert 800 < len(view['after']['x']) < 1200
    thumbs = {t['name']: np.array(t['z']) for t in drawn['thumbnails:/camera_out']['data']}
    assert np.array_equal(thumbs['before'], synthetic.image_pixels(2.0, 64, 48))
    assert thumbs['after'].shape == (48, 64, 3) and not thumbs['after'].any()


def test_array_images_keep_short_arrays_element_by_element_and_bin_long_ones():
    from bagfault.report.fields import ROWS, _ImageBuilder

    short = _ImageBuilder(10.0)
    short.add(1.0, np.array([1.0, np.inf, 3.0, np.nan]))
    image = short.image(0.0, 1.0)
    assert image.elements.tolist() == [0.0, 1.0, 2.0, 3.0]
    assert image.values[:, 0].tolist()[::2] == [1.0, 3.0] and np.isnan(image.values[1, 0])
    assert image.inf[:, 0].tolist() == [False, True, False, False]
    assert image.nan[:, 0].tolist() == [False, False, False, True]
    long = _ImageBuilder(10.0)
    ranges = np.arange(2 * ROWS, dtype=float)         # 720 beams at 0.5 degree from -180
    long.add(5.0, ranges)
    image = long.image(-180.0, 0.5)
    assert image.values.shape == (ROWS, 1) and image.values[:3, 0].tolist() == [0.0, 2.0, 4.0]   # minimum per bin
    assert image.elements[:3].tolist() == [-180.0, -179.0, -178.0]


def test_non_finite_scalars_are_marked_where_they_are(tmp_path):
    """A `nan` operation on odometry x from 1 s to 3 s and +inf on y from 4 s: the line would only show gaps, so
    the field figures mark every such message, on the after side only (times from the 10 Hz generator)."""
    page = report_of(tmp_path, [('/odom', 'nav_msgs/msg/Odometry', 10.0)], 6.0, """
        injectors:
          - {id: f, type: field, input_topic: /odom, output_topic: /odom_out}
        faults:
          - {id: blank, injector_id: f, start: 1.0, duration: 2.0,
             config: {operations: [{op: nan, path: pose.pose.position.x}]}}
          - {id: huge, injector_id: f, start: 4.0,
             config: {operations: [{op: set, path: pose.pose.position.y, value: .inf}]}}
    """)
    drawn = figures(page)
    x = {t['name']: t for t in drawn['field:/odom_out:pose.pose.position.x']['data']}
    y = {t['name']: t for t in drawn['field:/odom_out:pose.pose.position.y']['data']}
    assert x['after: nan']['x'] == pytest.approx([1.0 + 0.1 * k for k in range(20)])
    assert y['after: +inf']['x'] == pytest.approx([4.0 + 0.1 * k for k in range(20)])
    assert not {'before: nan', 'before: +inf', 'after: -inf', 'after: +inf'} & set(x)
    assert not {'before: nan', 'before: +inf', 'after: nan'} & set(y)
    finite_top = max(v for t in ('before: /odom', 'after: /odom_out') for v in x[t]['y'] if v is not None)
    assert set(x['after: nan']['y']) == {finite_top}


def test_envelopes_keep_every_extreme_of_a_long_series():
    """An hour at 200 Hz (720,000 samples) with one spike and one dip among small noise: the decimated series is
    at most two points per bucket and still holds the spike and the dip at their own times."""
    from bagfault.report.page import buckets_hit, envelope

    rng = np.random.default_rng(7)
    x = np.arange(720_000) / 200.0
    y = rng.normal(0.0, 0.01, x.size)
    y[123_457], y[600_001] = 5.0, -3.0
    y[300_000] = np.nan                                 # a break in the line (a gap, a nan value)
    ex, ey = envelope(x, y)
    assert ex.size <= 1600 + 1 and np.all(np.diff(ex) >= 0)
    assert ex[np.isnan(ey)].tolist() == [x[300_000]]    # kept, between the bucket's extremes where it was
    assert (np.nanmax(ey), ex[np.nanargmax(ey)]) == (5.0, x[123_457])
    assert (np.nanmin(ey), ex[np.nanargmin(ey)]) == (-3.0, x[600_001])
    # a bucket of 4.5 s (3600 s / 800) never reduces to more than its min and max: no point dropped blindly
    bucket = (ex[np.isfinite(ey)] // 4.5).astype(int)
    assert np.bincount(bucket).max() <= 2
    # markers: one per bucket that holds any, the first of them
    marks = buckets_hit(x[::7], 0.0, x[-1])
    assert marks.size == 800 and marks[0] == 0.0
