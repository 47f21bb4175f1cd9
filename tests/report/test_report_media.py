"""Faulted PointCloud2 and Image topics in the HTML report: point counts, the bird's-eye view and thumbnails at
the fault start, compared with the synthetic generator's own points and pixels."""

from __future__ import annotations

import textwrap

import numpy as np
from helpers import make_bag
from html_check import figures

from bagfault.cli import main
from bagfault.demo import synthetic


def test_cloud_and_image_at_the_fault_start(tmp_path):
    bag = make_bag(tmp_path / 'in.mcap', [('/cloud', 'sensor_msgs/msg/PointCloud2', 5.0),
                                          ('/camera', 'sensor_msgs/msg/Image', 5.0)], 6.0)
    scenario = tmp_path / 's.yaml'
    scenario.write_text(textwrap.dedent("""
        injectors:
          - {id: lidar, type: pointcloud2, input_topic: /cloud, output_topic: /cloud_out}
          - {id: camera, type: image, input_topic: /camera, output_topic: /camera_out}
        faults:
          - {id: thin, injector_id: lidar, start: 2.0, duration: 2.0, config: {dropout_probability: 0.5}}
          - {id: dark, injector_id: camera, start: 2.0, duration: 2.0, config: {black_frame: true}}
    """))
    page = tmp_path / 'r.html'
    assert main(['run', str(scenario), str(bag), '-o', str(tmp_path / 'out.mcap'), '--html', str(page)]) == 0
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
