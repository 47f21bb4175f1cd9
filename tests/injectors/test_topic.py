"""`topic` injector: every stream fault with an exact expectation."""

from __future__ import annotations

import struct
from collections import Counter

import pytest
from support.helpers import NS, make_bag, raw_messages, run_inline

from bagfault.demo import synthetic

START = synthetic.DEFAULT_START
IMU = 'sensor_msgs/msg/Imu'


@pytest.fixture(scope='module')
def bag(tmp_path_factory):
    """/imu at 50 Hz and /cloud at 10 Hz for 10 s."""
    return make_bag(tmp_path_factory.mktemp('bag') / 'in.mcap',
                    [('/imu', IMU, 50.0), ('/cloud', 'sensor_msgs/msg/PointCloud2', 10.0)], 10.0)


def scenario(config: str, start: float = 2.0, duration: float = 5.0) -> str:
    return f"""
        injector: {{id: t, type: topic, input_topic: /imu, output_topic: /imu_out}}
        faults:
          - {{id: f, injector_id: t, start: {start}, duration: {duration}, config: {config}}}
    """


def t(time: int) -> float:
    return (time - START) / NS


def streams(tmp_path, bag, config, **kw):
    out, result = run_inline(tmp_path, scenario(config), bag, **kw)
    raw = raw_messages(out)
    return raw['/imu'], raw.get('/imu_out', []), result


def test_throttle_gives_the_rate_in_every_full_second(tmp_path, bag):
    _, out, _ = streams(tmp_path, bag, '{throttle_hz: 5}')
    per_second = Counter(int(t(time)) for time, _, _ in out)
    for second in range(2, 7):
        assert per_second[second] == pytest.approx(5, abs=0.1)
    assert per_second[0] == per_second[1] == per_second[8] == 50


def test_freeze_repeats_the_last_good_payload_at_original_times(tmp_path, bag):
    raw, out, _ = streams(tmp_path, bag, '{freeze: true}')
    assert [time for time, _, _ in out] == [time for time, _, _ in raw]
    frozen_payload = next(data for time, _, data in raw if t(time) == pytest.approx(1.98))
    for (time, _, data), (_, _, original) in zip(out, raw, strict=True):
        expected = frozen_payload if 2.0 <= t(time) < 7.0 else original
        assert data == expected


def test_corrupt_probability_one_changes_every_payload_never_the_cdr_header(tmp_path, bag):
    raw, out, _ = streams(tmp_path, bag, '{corrupt_probability: 1.0, corrupt_bits: 8}')
    for (time, _, data), (_, _, original) in zip(out, raw, strict=True):
        assert data[:4] == original[:4] and len(data) == len(original)
        flipped = sum(bin(a ^ b).count('1') for a, b in zip(data, original, strict=True))
        assert flipped == (8 if 2.0 <= t(time) < 7.0 else 0)


def test_blackout_and_burst_drop(tmp_path, bag):
    _, out, _ = streams(tmp_path, bag, '{blackout: true}')
    assert not [1 for time, _, _ in out if 2.0 <= t(time) < 7.0] and len(out) == 500 - 250
    _, out, _ = streams(tmp_path, bag, '{burst_drop: 3, burst_period: 10}')
    inside = [round((t(time) - 2.0) * 50) for time, _, _ in out if 2.0 <= t(time) < 7.0]
    assert inside == [k for k in range(250) if k % 10 >= 3]


def test_drop_probability(tmp_path, bag):
    _, out, _ = streams(tmp_path, bag, '{drop_probability: 0.5}', seed=4)
    inside = sum(1 for time, _, _ in out if 2.0 <= t(time) < 7.0)
    assert 250 * 0.4 < inside < 250 * 0.6


def test_delay_with_jitter(tmp_path, bag):
    raw, out, _ = streams(tmp_path, bag, '{delay_ms: 100, jitter_ms: 20}', seed=1)
    by_payload = {data: time for time, _, data in raw}
    shifts = [(time - by_payload[data]) / 1e6 for time, _, data in out if 2.0 <= t(by_payload[data]) < 7.0]
    assert len(shifts) == 250 and min(shifts) >= 100 and max(shifts) <= 120 and len(set(shifts)) > 200
    assert [time for time, _, _ in out] == sorted(time for time, _, _ in out)
    again = streams(tmp_path, bag, '{delay_ms: 100, jitter_ms: 20}', seed=1)[1]
    assert again == out


def test_duplicates(tmp_path, bag):
    raw, out, _ = streams(tmp_path, bag, '{duplicate_probability: 1.0}')
    assert len(out) == 500 + 250
    counts = Counter(data for _, _, data in out)
    assert all(counts[data] == (2 if 2.0 <= t(time) < 7.0 else 1) for time, _, data in raw)


def test_reorder_window_shuffles_within_groups(tmp_path, bag):
    raw, out, _ = streams(tmp_path, bag, '{reorder_window: 5}', seed=2)
    assert sorted(data for _, _, data in out) == sorted(data for _, _, data in raw)
    times = [time for time, _, _ in out]
    assert times == sorted(times)
    position = {data: i for i, (_, _, data) in enumerate(raw)}
    order = [position[data] for _, _, data in out]
    inside = [i for i in order if 100 <= i < 350]
    groups = [sorted(inside[g:g + 5]) for g in range(0, 250, 5)]
    assert groups == [list(range(100 + g, 105 + g)) for g in range(0, 250, 5)]
    assert inside != sorted(inside)
    assert order[:100] == list(range(100)) and order[350:] == list(range(350, 500))


def test_stamp_offset_changes_only_the_header_stamp(tmp_path, bag):
    raw, out, _ = streams(tmp_path, bag, '{stamp_offset_ms: -1500}')
    for (time, _, data), (_, _, original) in zip(out, raw, strict=True):
        sec, nsec = struct.unpack_from('<iI', data, 4)
        sec0, nsec0 = struct.unpack_from('<iI', original, 4)
        shift = -1_500_000_000 if 2.0 <= t(time) < 7.0 else 0
        assert (sec * NS + nsec) - (sec0 * NS + nsec0) == shift
        assert data[12:] == original[12:]


def test_stamp_offset_needs_a_header(tmp_path, bag):
    from bagfault.errors import EngineError

    text = scenario('{stamp_offset_ms: 5}').replace('/imu,', '/cloud,')
    out, _ = run_inline(tmp_path, text, bag)  # PointCloud2 has a header: fine
    bad = make_bag(tmp_path / 'twist.mcap', [('/imu', 'sensor_msgs/msg/JointState', 10.0)], 1.0)
    run_inline(tmp_path, scenario('{stamp_offset_ms: 5}'), bad)  # JointState has a header too
    plain = tmp_path / 'plain.mcap'
    synthetic.write_mcap(plain, [(synthetic.Stream('/imu', 'std_msgs/msg/Float64', 1.0), START,
                                  synthetic.store().types['std_msgs/msg/Float64'](data=1.0))])
    with pytest.raises(EngineError, match='stamp_offset_ms needs a message with a header, and std_msgs/msg/Float64'):
        run_inline(tmp_path, scenario('{stamp_offset_ms: 5}'), plain)


def test_batch_and_per_message_paths_agree(tmp_path, bag):
    config = '{drop_probability: 0.3, delay_ms: 40, jitter_ms: 10, reorder_window: 3, duplicate_probability: 0.2}'
    fast = streams(tmp_path, bag, config, seed=9)[1]
    slow = streams(tmp_path, bag, config, seed=9, batch=False)[1]
    assert fast == slow
