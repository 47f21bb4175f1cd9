"""Pipeline behaviour on a generated bag: drop, delay, ordering, bounded buffer."""

from __future__ import annotations

from mcap.reader import NonSeekingReader
from support.helpers import FIXTURES, NS, ROOT, decoded, raw_messages

from bagfault import api
from bagfault.demo import synthetic
from bagfault.scenario import load_scenario

START = synthetic.DEFAULT_START
SCENARIO = ROOT / 'scenarios' / 'rover_drift.yaml'


def t(time: int) -> float:
    return (time - START) / NS


def test_delay_retimes_messages_and_keeps_the_file_sorted(tmp_path):
    out = tmp_path / 'out.mcap'
    result = api.run(SCENARIO, [FIXTURES / 'rover_20s.mcap'], out)
    raw_in = raw_messages(FIXTURES / 'rover_20s.mcap')['/sensors/imu_raw']
    raw_out = raw_messages(out)['/sensors/imu']
    assert len(raw_out) == len(raw_in) == 2000
    shift = 250_000_000
    by_payload = {data: (t_in, p_in) for t_in, p_in, data in raw_in}  # headers differ, so payloads are unique
    for t_out, p_out, data in raw_out:
        t_in, p_in = by_payload[data]
        expected = shift if 12.0 <= t(t_in) < 16.0 else 0
        assert (t_out - t_in, p_out - p_in) == (expected, expected)
    for time, message in decoded(out, ['/sensors/imu'])['/sensors/imu']:
        stamp = message.header.stamp.sec * NS + message.header.stamp.nanosec
        assert time - stamp == (shift if 12.0 <= t(stamp) < 16.0 else 0)  # header unchanged
    with out.open('rb') as stream:
        times = [m.log_time for _, _, m in NonSeekingReader(stream).iter_messages()]
    assert times == sorted(times)
    # only the delayed IMU messages wait in the buffer: 100 Hz x 0.25 s
    assert 0 < result.stats.max_buffered <= 26


def test_drop_removes_messages_only_while_active(tmp_path):
    out = tmp_path / 'out.mcap'
    api.run(SCENARIO, [FIXTURES / 'rover_20s.mcap'], out, activate=['imu_dropout@2+3'], seed=1)
    source = {time: data for time, _, data in raw_messages(FIXTURES / 'rover_20s.mcap')['/sensors/imu_raw']}
    kept = raw_messages(out)['/sensors/imu']
    inside = [time for time, _, _ in kept if 2.0 <= t(time) < 5.0]
    outside = [time for time, _, _ in kept if not 2.0 <= t(time) < 5.0 and t(time) < 12.0]
    assert 300 * 0.7 < len(inside) < 300 * 0.9
    assert len(outside) == 1200 - 300
    assert all(source[time] == data for time, _, data in kept if t(time) < 12.0)


def test_example_scenarios_validate():
    for path in sorted((ROOT / 'scenarios').glob('*.yaml')):
        assert load_scenario(path).faults, path
