"""`run` on the generated rover bag with the anchor's multi-injector scenario."""

from __future__ import annotations

import json
import math
import shutil

import blake3
import numpy as np
import pytest
from mcap.reader import make_reader
from support.helpers import FIXTURES, NS, counts, decoded, raw_messages, rpy, sha256

from bagfault import api
from bagfault.demo import synthetic

START = synthetic.DEFAULT_START


@pytest.fixture(scope='module')
def multi(tmp_path_factory, request):
    scenarios = request.getfixturevalue('scenarios')
    out = tmp_path_factory.mktemp('multi') / 'out.mcap'
    result = api.run(scenarios / 'rover_multi.yaml', [FIXTURES / 'rover_20s.mcap'], out, seed=3)
    return result, out


def seconds(time: int) -> float:
    return (time - START) / NS


def pairs(out, raw_topic, topic):
    data = decoded(out, [raw_topic, topic])
    assert [t for t, _ in data[raw_topic]] == [t for t, _ in data[topic]]
    return [(t, a, b) for (t, a), (_, b) in zip(data[raw_topic], data[topic], strict=True)]


def test_odom_bias_exactly_inside_its_window(multi):
    _, out = multi
    rows = pairs(out, '/odom_raw', '/odom')
    assert len(rows) == 1000
    for time, raw, mutated in rows:
        inside = 5.0 <= seconds(time) < 15.0
        dx = mutated.pose.pose.position.x - raw.pose.pose.position.x
        dy = mutated.pose.pose.position.y - raw.pose.pose.position.y
        assert dx == pytest.approx(1.0 if inside else 0.0, abs=1e-12), seconds(time)
        assert dy == pytest.approx(-0.25 if inside else 0.0, abs=1e-12)
        if not inside:
            assert dx == 0.0 and dy == 0.0
        q_in, q_out = raw.pose.pose.orientation, mutated.pose.pose.orientation
        yaw_in = rpy(q_in)[2]
        yaw_out = rpy(q_out)[2]
        dyaw = math.remainder(yaw_out - yaw_in, 2 * math.pi)
        assert dyaw == pytest.approx(math.radians(10.0) if inside else 0.0, abs=1e-9)


def test_odom_covariance_follows_scale_and_floor(multi):
    _, out = multi
    for time, raw, mutated in pairs(out, '/odom_raw', '/odom'):
        if 3.0 <= seconds(time) < 18.0:
            expected = np.maximum(np.asarray(raw.pose.covariance) * 10.0, 0.05)
            expected_twist = np.maximum(np.asarray(raw.twist.covariance) * 10.0, 0.05)
        else:
            expected, expected_twist = raw.pose.covariance, raw.twist.covariance
        assert np.array_equal(mutated.pose.covariance, expected)
        assert np.array_equal(mutated.twist.covariance, expected_twist)


def test_events_at_exact_scheduled_bag_times(multi):
    result, out = multi
    events = decoded(out, ['/fault_injection/events'])['/fault_injection/events']
    got = [(t, e.fault_id, e.state, e.source) for t, e in events]
    expected = [
        (3.0, 'odom_covariance_inflation', 'active'),
        (5.0, 'odom_position_bias', 'active'),
        (5.0, 'odom_yaw_bias', 'active'),
        (5.0, 'enable_motors_forced_failure', 'active'),
        (8.0, 'scan_range_noise', 'active'),
        (12.0, 'motor_velocity_bias', 'active'),
        (15.0, 'odom_position_bias', 'inactive'),
        (15.0, 'odom_yaw_bias', 'inactive'),
        (15.0, 'enable_motors_forced_failure', 'inactive'),
        (18.0, 'odom_covariance_inflation', 'inactive'),
    ]
    assert [(t, f, s) for t, f, s, _ in got] == [(START + round(s * NS), f, st) for s, f, st in expected]
    for time, event in events:
        assert event.stamp.sec * NS + event.stamp.nanosec == time
        assert event.source == 'scheduled'
    assert events[1][1].details == 'config={x_bias=1.0, y_bias=-0.25}'
    assert events[1][1].injector_id == 'odom'


def test_counts_unchanged_and_both_topics_present(multi):
    _, out = multi
    got = counts(out)
    for raw, topic, n in [('/odom_raw', '/odom', 1000), ('/scan_raw', '/scan', 200),
                          ('/platform/motors/feedback_raw', '/platform/motors/feedback', 1000),
                          ('/sensors/imu_raw', '/sensors/imu', 2000), ('/tf_raw', '/tf', 1000)]:
        assert got[raw] == n and got[topic] == n


def test_untouched_streams_are_byte_identical(multi):
    _, out = multi
    raw = raw_messages(out)
    source = raw_messages(FIXTURES / 'rover_20s.mcap')
    assert raw['/sensors/imu_raw'] == source['/sensors/imu_raw']
    # manual-only faults stay inactive offline: these outputs equal their inputs byte for byte
    assert [d for _, _, d in raw['/sensors/imu']] == [d for _, _, d in source['/sensors/imu_raw']]
    assert [d for _, _, d in raw['/tf']] == [d for _, _, d in source['/tf_raw']]


def test_scan_noise_and_motor_bias_windows(multi):
    _, out = multi
    for time, raw, mutated in pairs(out, '/scan_raw', '/scan'):
        finite = np.isfinite(raw.ranges)
        assert np.array_equal(np.isfinite(mutated.ranges), finite)
        changed = mutated.ranges[finite] != raw.ranges[finite]
        assert changed.all() if seconds(time) >= 8.0 else not changed.any()
    for time, raw, mutated in pairs(out, '/platform/motors/feedback_raw', '/platform/motors/feedback'):
        expected = 0.1 if seconds(time) >= 12.0 else 0.0
        assert np.allclose(mutated.velocity - raw.velocity, expected, atol=1e-12)


def test_output_file_conventions(multi, scenarios):
    result, out = multi
    with out.open('rb') as stream:
        reader = make_reader(stream)
        header = reader.get_header()
        summary = reader.get_summary()
        assert header.profile == 'ros2'
        assert {s.encoding for s in summary.schemas.values()} == {'ros2msg'}
        assert {c.message_encoding for c in summary.channels.values()} == {'cdr'}
        assert {c.compression for c in summary.chunk_indexes} == {'zstd'}
        [meta] = [m for m in reader.iter_metadata() if m.name == 'bagfault']
        [attachment] = list(reader.iter_attachments())
    assert meta.metadata['seed'] == '3'
    inputs = json.loads(meta.metadata['inputs'])
    rover = FIXTURES / 'rover_20s.mcap'
    assert inputs[0]['files'][0] == {'name': 'rover_20s.mcap', 'size': rover.stat().st_size,
                                     'blake3': blake3.blake3(rover.read_bytes()).hexdigest()}
    assert attachment.name == 'rover_multi.yaml'
    assert attachment.data == (scenarios / 'rover_multi.yaml').read_bytes()
    assert any('live mode only' in note for note in result.notes)


def test_same_run_twice_is_byte_identical(tmp_path, scenarios, rover_bag):
    scenario = scenarios / 'rover_multi.yaml'
    api.run(scenario, [rover_bag], tmp_path / 'a.mcap', seed=11, activate=['odom_position_noise'])
    api.run(scenario, [rover_bag], tmp_path / 'b.mcap', seed=11, activate=['odom_position_noise'])
    api.run(scenario, [rover_bag], tmp_path / 'c.mcap', seed=12, activate=['odom_position_noise'])
    assert sha256(tmp_path / 'a.mcap') == sha256(tmp_path / 'b.mcap')
    assert sha256(tmp_path / 'a.mcap') != sha256(tmp_path / 'c.mcap')


def test_unrelated_fault_does_not_change_noise(tmp_path, scenarios, rover_bag):
    scenario = scenarios / 'rover_multi.yaml'
    api.run(scenario, [rover_bag], tmp_path / 'a.mcap', seed=5)
    api.run(scenario, [rover_bag], tmp_path / 'b.mcap', seed=5, activate=['imu_linear_acceleration_noise'])
    a, b = raw_messages(tmp_path / 'a.mcap'), raw_messages(tmp_path / 'b.mcap')
    assert a['/scan'] == b['/scan']
    assert a['/sensors/imu'] != b['/sensors/imu']


def test_activate_switches_a_manual_fault_for_a_window(tmp_path, scenarios, rover_bag):
    out = tmp_path / 'out.mcap'
    result = api.run(scenarios / 'rover_multi.yaml', [rover_bag], out, activate=['odom_position_noise@2+3'])
    assert [(e.fault_id, e.state, e.source, seconds(e.time)) for e in result.stats.events
            if e.fault_id == 'odom_position_noise'] == [
        ('odom_position_noise', 'active', 'cli', 2.0), ('odom_position_noise', 'inactive', 'cli', 5.0)]
    for time, raw, mutated in pairs(out, '/odom_raw', '/odom'):
        noisy = mutated.pose.pose.position.x != raw.pose.pose.position.x + (1.0 if 5 <= seconds(time) < 15 else 0.0)
        assert noisy == (2.0 <= seconds(time) < 5.0)


def test_start_offset_moves_time_zero(tmp_path, scenarios, rover_bag):
    result = api.run(scenarios / 'rover_multi.yaml', [rover_bag], tmp_path / 'o.mcap', start_offset=1.5)
    first = result.stats.events[0]
    assert (first.fault_id, seconds(first.time)) == ('odom_covariance_inflation', 4.5)


@pytest.mark.parametrize('compression', ['none', 'lz4'])
def test_compression_choice(tmp_path, scenarios, rover_bag, compression):
    out = tmp_path / 'o.mcap'
    api.run(scenarios / 'rover_multi.yaml', [rover_bag], out, compression=compression)
    with out.open('rb') as stream:
        summary = make_reader(stream).get_summary()
    assert {c.compression for c in summary.chunk_indexes} == {'' if compression == 'none' else 'lz4'}
    assert counts(out)['/odom'] == 1000


def test_several_inputs_merge_in_time_order(tmp_path, scenarios, rover_bag, rover_sqlite):
    shifted = tmp_path / 'late.mcap'
    synthetic.write_mcap(shifted, synthetic.messages(synthetic.ROVER_STREAMS[:1], 2.0, START + NS // 100))
    scenario = scenarios / 'odom.yaml'
    out = tmp_path / 'o.mcap'
    shutil.copy(rover_bag, tmp_path / 'rover.mcap')
    api.run(scenario, [tmp_path / 'rover.mcap', shifted], out)
    times = [t for t, _, _ in raw_messages(out)['/odom_raw']]
    assert len(times) == 1000 + 100 and times == sorted(times)
