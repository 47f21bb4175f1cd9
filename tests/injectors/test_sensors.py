"""pointcloud2, image and compressed_image injectors: exact, vectorised effects."""

from __future__ import annotations

import math

import numpy as np
import pytest
from support.helpers import NS, decoded, image_pixels, make_bag, raw_messages, run_inline

from bagfault.demo import synthetic

START = synthetic.DEFAULT_START


@pytest.fixture(scope='module')
def bag(tmp_path_factory):
    return make_bag(tmp_path_factory.mktemp('bag') / 'in.mcap',
                    [('/cloud', 'sensor_msgs/msg/PointCloud2', 5.0), ('/camera', 'sensor_msgs/msg/Image', 5.0),
                     ('/camera/compressed', 'sensor_msgs/msg/CompressedImage', 5.0)], 4.0)


def run_one(tmp_path, bag, kind, topic, config, **kw):
    text = f"""
        injector: {{id: s, type: {kind}, input_topic: {topic}, output_topic: {topic}_out}}
        faults:
          - {{id: f, injector_id: s, start: 1.0, duration: 2.0, config: {config}}}
    """
    out, _ = run_inline(tmp_path, text, bag, **kw)
    data = decoded(out, [topic, f'{topic}_out'])
    return list(zip(data[topic], data[f'{topic}_out'], strict=True))


def inside(time):
    return 1.0 <= (time - START) / NS < 3.0


def xyz(message):
    points = np.frombuffer(bytes(message.data), dtype=np.float32).reshape(-1, 4)
    return points[:, :3].astype(np.float64)


def test_cloud_bias_and_noise(tmp_path, bag):
    rows = run_one(tmp_path, bag, 'pointcloud2', '/cloud', '{x_bias: 1.0, z_bias: -0.5, xyz_noise_stddev: 0.02}')
    for (time, a), (_, b) in rows:
        delta = xyz(b) - xyz(a)
        if inside(time):
            assert np.mean(delta, axis=0) == pytest.approx([1.0, 0.0, -0.5], abs=0.003)
            assert np.std(delta, axis=0) == pytest.approx([0.02] * 3, rel=0.1)
            intensity = np.frombuffer(bytes(b.data), dtype=np.float32).reshape(-1, 4)[:, 3]
            assert np.all(intensity == 100.0)
        else:
            assert bytes(b.data) == bytes(a.data)


def test_cloud_dropout_nan_and_sector(tmp_path, bag):
    rows = run_one(tmp_path, bag, 'pointcloud2', '/cloud',
                   '{dropout_probability: 0.3, sector_min_deg: -45, sector_max_deg: 45, sector_max_range: 5.0}')
    for (time, a), (_, b) in rows:
        if not inside(time):
            assert b.width == a.width
            continue
        before, after = xyz(a), xyz(b)
        azimuth = np.degrees(np.arctan2(before[:, 1], before[:, 0]))
        blind = (np.abs(azimuth) <= 45) & (np.linalg.norm(before, axis=1) <= 5.0)
        kept = {tuple(p) for p in after.round(5)}
        assert not any(tuple(p) in kept for p in before[blind].round(5))
        survivors = (~blind).sum()
        assert b.width == len(after) < survivors and b.width == pytest.approx(0.7 * survivors, rel=0.1)
        assert b.row_step == b.width * 16 and b.height == 1
    rows = run_one(tmp_path, bag, 'pointcloud2', '/cloud', '{nan_probability: 0.5}')
    for (time, a), (_, b) in rows:
        if inside(time):
            invalid = np.isnan(xyz(b)).all(axis=1)
            assert b.width == a.width and invalid.mean() == pytest.approx(0.5, abs=0.05) and not b.is_dense


def test_image_faults(tmp_path, bag):
    rows = run_one(tmp_path, bag, 'image', '/camera', '{brightness_scale: 0.5, dead_pixel_fraction: 0.1}')
    dead_sets = set()
    for (time, a), (_, b) in rows:
        pa, pb = image_pixels(a).astype(int), image_pixels(b).astype(int)
        if inside(time):
            dead = (pb == 0).all(axis=2) & (pa > 1).any(axis=2)
            dead_sets.add(dead.tobytes())
            alive = ~((pb == 0).all(axis=2))
            assert np.array_equal(pb[alive], np.rint(pa[alive] * 0.5).astype(int))
            assert dead.mean() == pytest.approx(0.1, abs=0.03)
        else:
            assert np.array_equal(pa, pb)
    assert len(dead_sets) == 1  # the same pixels stay dead for the whole fault


def test_image_stuck_black_and_noise(tmp_path, bag):
    rows = run_one(tmp_path, bag, 'image', '/camera', '{stuck_frame: true}')
    frames = [bytes(b.data) for (time, a), (_, b) in rows if inside(time)]
    first = next(bytes(a.data) for (time, a), _ in rows if inside(time))
    assert frames and set(frames) == {first}
    rows = run_one(tmp_path, bag, 'image', '/camera', '{black_frame: true}')
    assert all(not image_pixels(b).any() for (time, _), (_, b) in rows if inside(time))
    rows = run_one(tmp_path, bag, 'image', '/camera', '{noise_stddev: 5.0}')
    for (time, a), (_, b) in rows:
        if inside(time):
            diff = image_pixels(b).astype(float) - image_pixels(a).astype(float)
            middle = (image_pixels(a) > 20) & (image_pixels(a) < 235)
            assert np.std(diff[middle]) == pytest.approx(5.0, rel=0.1)
            assert image_pixels(b).dtype == np.uint8


@pytest.mark.parametrize('encoding', ['mono8', 'mono16', '32FC1', 'bgr8'])
def test_image_encodings(tmp_path, encoding):
    ts = synthetic.store()
    kind, channels = {'mono8': ('u1', 1), 'mono16': ('>u2', 1), '32FC1': ('<f4', 1), 'bgr8': ('u1', 3)}[encoding]
    values = (np.arange(12 * 8 * channels).reshape(8, 12, channels) % 200 + 10).astype(kind)
    step = 12 * channels * values.dtype.itemsize + 4  # padded rows
    rows = np.zeros((8, step), dtype=np.uint8)
    rows[:, :12 * channels * values.dtype.itemsize] = values.view(np.uint8).reshape(8, -1)
    message = ts.types['sensor_msgs/msg/Image'](
        header=ts.types['std_msgs/msg/Header'](stamp=ts.types['builtin_interfaces/msg/Time'](sec=0, nanosec=0),
                                               frame_id='c'),
        height=8, width=12, encoding=encoding, is_bigendian=1 if encoding == 'mono16' else 0, step=step,
        data=rows.reshape(-1))
    bag = tmp_path / 'img.mcap'
    synthetic.write_mcap(bag, [(synthetic.Stream('/img', 'sensor_msgs/msg/Image', 1.0), START + i * NS, message)
                               for i in range(3)])
    out, _ = run_inline(tmp_path, """
        injector: {id: s, type: image, input_topic: /img, output_topic: /img_out}
        faults: [{id: f, injector_id: s, active_on_startup: true, config: {brightness_scale: 2.0}}]
    """, bag)
    [(_, result)] = decoded(out, ['/img_out'])['/img_out'][:1]
    limit = {'mono8': 255, 'bgr8': 255, 'mono16': 65535, '32FC1': np.inf}[encoding]
    assert np.array_equal(image_pixels(result), np.minimum(values.astype(float) * 2.0, limit))
    assert result.step == 12 * channels * values.dtype.itemsize


def test_compressed_image_stream_faults(tmp_path, bag):
    out, _ = run_inline(tmp_path, """
        injector: {id: c, type: compressed_image, input_topic: /camera/compressed, output_topic: /camera/compressed_out}
        faults: [{id: f, injector_id: c, start: 1.0, duration: 2.0, config: {freeze: true, delay_ms: 100}}]
    """, bag)
    raw = raw_messages(out)
    frozen = next(d for t, _, d in raw['/camera/compressed'] if (t - START) / NS == pytest.approx(0.8))
    for (t_in, _, d_in), (t_out, _, d_out) in zip(raw['/camera/compressed'], raw['/camera/compressed_out'], strict=True):
        if inside(t_in):
            assert (d_out, t_out - t_in) == (frozen, 100_000_000)
        else:
            assert (d_out, t_out) == (d_in, t_in)


def test_sensor_batch_equals_per_message(tmp_path, bag):
    config = '{xyz_noise_stddev: 0.05, dropout_probability: 0.2, nan_probability: 0.1}'
    fast = run_one(tmp_path, bag, 'pointcloud2', '/cloud', config)
    slow = run_one(tmp_path, bag, 'pointcloud2', '/cloud', config, batch=False)
    assert [bytes(b.data) for _, (_, b) in fast] == [bytes(b.data) for _, (_, b) in slow]
    _ = math
