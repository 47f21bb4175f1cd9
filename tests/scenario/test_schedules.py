"""Intermittent and chained schedules, seen in the output data."""

from __future__ import annotations

import pytest
from support.helpers import NS, make_bag, raw_messages, run_inline

from bagfault.demo import synthetic

START = synthetic.DEFAULT_START


@pytest.fixture(scope='module')
def bag(tmp_path_factory):
    return make_bag(tmp_path_factory.mktemp('bag') / 'in.mcap', [('/imu', 'sensor_msgs/msg/Imu', 50.0)], 10.0)


def seconds(time):
    return (time - START) / NS


def test_repeat_blacks_out_half_a_second_every_two(tmp_path, bag):
    out, result = run_inline(tmp_path, """
        injector: {id: t, type: topic, input_topic: /imu, output_topic: /imu_out}
        faults:
          - {id: flicker, injector_id: t, start: 1.0, duration: 6.0, repeat: {period: 2.0, on: 0.5},
             config: {blackout: true}}
    """, bag)
    kept = {round(seconds(t), 2) for t, _, _ in raw_messages(out)['/imu_out']}
    every = {round(k / 50, 2) for k in range(500)}
    silent = {x for x in every if any(s <= x < s + 0.5 for s in (1.0, 3.0, 5.0))}
    assert kept == every - silent
    assert [(round(seconds(e.time), 3), e.state) for e in result.stats.events] == [
        (1.0, 'active'), (1.5, 'inactive'), (3.0, 'active'), (3.5, 'inactive'), (5.0, 'active'), (5.5, 'inactive')]


def test_random_activations_hold_and_are_seeded(tmp_path, bag):
    text = """
        injector: {id: t, type: topic, input_topic: /imu, output_topic: /imu_out}
        faults:
          - {id: glitch, injector_id: t, probability_per_second: 0.5, hold: 0.2, config: {blackout: true}}
    """
    out, result = run_inline(tmp_path, text, bag, seed=3)
    events = [(e.time, e.state) for e in result.stats.events]
    assert events and all(state == ('active' if i % 2 == 0 else 'inactive') for i, (_, state) in enumerate(events))
    spans = list(zip(events[::2], events[1::2], strict=True))
    assert all(off - on == 200_000_000 for (on, _), (off, _) in spans)
    kept = [t for t, _, _ in raw_messages(out)['/imu_out']]
    assert all(not on <= t < off for t in kept for (on, _), (off, _) in spans)
    _, again = run_inline(tmp_path, text, bag, seed=3)
    assert [(e.time, e.state) for e in again.stats.events] == events


def test_after_chains_a_fault_to_another(tmp_path, bag):
    out, result = run_inline(tmp_path, """
        injector: {id: i, type: imu, input_topic: /imu, output_topic: /imu_out}
        faults:
          - {id: trigger, injector_id: i, start: 2.0, duration: 1.0, config: {angular_velocity_z_bias: 1.0}}
          - {id: follow, injector_id: i, after: {fault: trigger, delay: 0.5}, duration: 2.0,
             config: {angular_velocity_z_bias: 10.0}}
    """, bag)
    assert [(e.fault_id, e.state, seconds(e.time)) for e in result.stats.events] == [
        ('trigger', 'active', 2.0), ('follow', 'active', 2.5), ('trigger', 'inactive', 3.0),
        ('follow', 'inactive', 4.5)]
