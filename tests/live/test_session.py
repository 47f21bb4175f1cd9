"""LiveSession without a ROS graph: switches, config updates, reload rules, delays, malformed input, recording."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from support.helpers import NS, decoded

from bagfault.demo import synthetic
from bagfault.errors import FieldValueError, ReloadError
from bagfault.io.mcap_sink import McapSink
from bagfault.io.types import TypeCatalog
from bagfault.live.session import LiveSession
from bagfault.scenario import parse_scenario

STORE = synthetic.store()
IMU = 'sensor_msgs/msg/Imu'
SCENARIO = """
injector: {id: imu, type: imu, input_topic: /imu_raw, output_topic: /imu, qos_depth: 10}
faults:
  - {id: bias, injector_id: imu, config: {angular_velocity_z_bias: 0.5}}
  - {id: late, injector_id: imu, config: {delay_ms: 250}}
  - {id: scheduled, injector_id: imu, start: 2.0, duration: 1.0, config: {linear_acceleration_x_bias: 3.0}}
"""


class Clock:
    """A hand-driven ROS clock (ns)."""

    def __init__(self) -> None:
        self.now = 100 * NS

    def __call__(self) -> int:
        return self.now


def imu(z: float, x: float = 0.0) -> bytes:
    message = synthetic.BUILDERS[IMU](STORE, 0, 0.0)
    message.angular_velocity.z = z
    message.linear_acceleration.x = x
    return bytes(STORE.serialize_cdr(message, IMU))


def value(data: bytes | memoryview, path: str) -> float:
    message = STORE.deserialize_cdr(bytes(data), IMU)
    for part in path.split('.'):
        message = getattr(message, part)
    return message


def session_for(text: str, clock: Clock, recording: McapSink | None = None) -> LiveSession:
    session = LiveSession(parse_scenario(text), TypeCatalog([], 'jazzy'), {'imu': IMU}, clock, seed=1, sink=recording)
    session.start()
    return session


def test_untouched_messages_pass_as_the_same_bytes_until_a_fault_is_switched_on() -> None:
    clock = Clock()
    session = session_for(SCENARIO, clock)
    topic = session.topics[0]
    data = imu(0.25)
    (out,) = session.receive(topic, data)
    assert out.data is data
    session.set_active('bias', True)
    (out,) = session.receive(topic, imu(0.25))
    assert value(out.data, 'angular_velocity.z') == 0.25 + 0.5
    session.set_active('bias', False)
    (out,) = session.receive(topic, imu(0.25))
    assert value(out.data, 'angular_velocity.z') == 0.25
    assert [(e.fault_id, e.state, e.source) for e in session.stats.events] == [
        ('bias', 'active', 'manual'), ('bias', 'inactive', 'manual')]


def test_delayed_messages_come_back_with_their_due_time() -> None:
    clock = Clock()
    session = session_for(SCENARIO, clock)
    session.set_active('late', True)
    (out,) = session.receive(session.topics[0], imu(1.0))
    assert out.log_time == clock.now + 250_000_000


def test_schedule_follows_the_clock_from_the_session_start() -> None:
    clock = Clock()
    session = session_for(SCENARIO, clock)
    topic = session.topics[0]
    clock.now += 1_999_000_000
    (out,) = session.receive(topic, imu(0.0, 1.0))
    assert value(out.data, 'linear_acceleration.x') == 1.0
    clock.now += 1_000_000
    (out,) = session.receive(topic, imu(0.0, 1.0))  # exactly at start=2.0 s
    assert value(out.data, 'linear_acceleration.x') == 4.0
    clock.now += NS
    session.advance()
    assert [e.state for e in session.stats.events if e.fault_id == 'scheduled'] == ['active', 'inactive']
    assert [e.time - 100 * NS for e in session.stats.events] == [2 * NS, 3 * NS]


def test_config_changes_are_checked_by_the_schema_and_take_effect() -> None:
    clock = Clock()
    session = session_for(SCENARIO, clock)
    session.set_active('bias', True)
    with pytest.raises(FieldValueError, match='is not a number'):
        session.check_config('bias', 'angular_velocity_z_bias', 'fast')
    with pytest.raises(FieldValueError, match=re.escape('above the maximum 1.0')):
        session.check_config('late', 'drop_probability', 1.5)
    with pytest.raises(FieldValueError, match='not a config key'):
        session.check_config('bias', 'range_bias', 1.0)
    session.set_config('bias', 'angular_velocity_z_bias', 2.0)
    (out,) = session.receive(session.topics[0], imu(0.25))
    assert value(out.data, 'angular_velocity.z') == 2.25
    event = session.stats.events[-1]
    assert (event.state, event.source, event.details) == ('config_updated', 'manual',
                                                          'config_update={angular_velocity_z_bias=2.0}')


def test_reload_takes_new_faults_but_refuses_a_new_layout() -> None:
    clock = Clock()
    session = session_for(SCENARIO, clock)
    changed_layout = SCENARIO.replace('/imu_raw', '/imu_other')
    with pytest.raises(ReloadError, match='injector ids, types, endpoints'):
        session.reload(parse_scenario(changed_layout))
    assert session.scenario.injectors[0].input_topic == '/imu_raw'
    new = SCENARIO.replace('config: {angular_velocity_z_bias: 0.5}', 'active_on_startup: true, config: {angular_velocity_z_bias: 0.125}')
    session.reload(parse_scenario(new))
    (out,) = session.receive(session.topics[0], imu(0.25))
    assert value(out.data, 'angular_velocity.z') == 0.375
    states = [(e.fault_id, e.state, e.source) for e in session.stats.events]
    assert ('bias', 'config_updated', 'reload') in states and ('bias', 'active', 'reload') in states


def test_malformed_messages_are_counted_and_forwarded_or_dropped() -> None:
    clock = Clock()
    bad = b'\x00\x01\x00\x00\xff'
    session = session_for(SCENARIO, clock)
    session.set_active('bias', True)
    (out,) = session.receive(session.topics[0], bad)
    assert bytes(out.data) == bad and session.topics[0].malformed == 1 and session.topics[0].last_error
    dropping = session_for(SCENARIO.replace('qos_depth: 10', 'qos_depth: 10, on_malformed: drop'), clock)
    dropping.set_active('bias', True)
    assert dropping.receive(dropping.topics[0], bad) == []
    assert dropping.topics[0].malformed == 1
    (out,) = dropping.receive(dropping.topics[0], imu(0.0))  # and it keeps working
    assert value(out.data, 'angular_velocity.z') == 0.5


def test_recording_holds_raw_and_faulty_topics_and_the_events(tmp_path: Path) -> None:
    clock = Clock()
    recording = McapSink(tmp_path / 'live.mcap')
    session = session_for(SCENARIO, clock, recording)
    topic = session.topics[0]
    for k in range(4):
        clock.now += 10_000_000
        if k == 2:
            session.set_active('bias', True)
        for out in session.receive(topic, imu(float(k))):
            session.sent(topic, out.data)
    assert not (tmp_path / 'live.mcap').exists()  # only complete files carry the name
    session.finish()
    recording.finish()
    raw = decoded(tmp_path / 'live.mcap', ['/imu_raw', '/imu', '/fault_injection/events'])
    assert [m.angular_velocity.z for _, m in raw['/imu_raw']] == [0.0, 1.0, 2.0, 3.0]
    assert [m.angular_velocity.z for _, m in raw['/imu']] == [0.0, 1.0, 2.5, 3.5]
    (time, event), = raw['/fault_injection/events']
    assert (event.fault_id, event.state, event.source) == ('bias', 'active', 'manual')
    assert time == 100 * NS + 30_000_000


def test_reload_keeps_what_was_set_at_run_time_unless_the_file_changed_it() -> None:
    clock = Clock()
    session = session_for(SCENARIO, clock)
    session.set_active('bias', True)  # by a parameter
    session.set_config('bias', 'angular_velocity_z_bias', 2.0)
    session.set_config('late', 'delay_ms', 100)
    # the file now changes late.delay_ms (its new value wins) and nothing about bias
    held, kept = session.reload(parse_scenario(SCENARIO.replace('delay_ms: 250', 'delay_ms: 400')))
    assert held == []
    assert kept == ['bias.angular_velocity_z_bias=2.0', 'bias.active=true']
    assert session.scenario.fault('late').config == {'delay_ms': 400}
    (out,) = session.receive(session.topics[0], imu(0.25))
    assert value(out.data, 'angular_velocity.z') == 2.25  # still active, with the run-time value
    assert not [e for e in session.stats.events if e.fault_id == 'bias' and e.source == 'reload']
    # a state the schedule has switched since is not brought back
    session.set_active('bias', False)
    session.set_active('scheduled', True)  # by hand at 0 s; the schedule ends it at 3 s
    clock.now += 4 * NS
    session.advance()
    _, kept = session.reload(parse_scenario(SCENARIO))
    assert kept == ['bias.angular_velocity_z_bias=2.0', 'bias.active=false']
    assert not session.state.active()
