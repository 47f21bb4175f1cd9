"""Faults switched and reconfigured from outside a running pass take effect from the next message, as manual events."""

from __future__ import annotations

import textwrap
from pathlib import Path

import pytest
from support.helpers import make_bag

from bagfault.demo import synthetic
from bagfault.engine.control import FaultControl
from bagfault.engine.offline import replay
from bagfault.engine.run import NullSink
from bagfault.errors import FieldValueError
from bagfault.io.sources import InputSet
from bagfault.io.types import TypeCatalog
from bagfault.scenario import parse_scenario

IMU = 'sensor_msgs/msg/Imu'
SCENARIO = textwrap.dedent("""
    injector: {id: imu, type: imu, input_topic: /imu, output_topic: /imu_out}
    faults:
      - {id: bias, injector_id: imu, config: {angular_velocity_z_bias: 0.5}}
""")


class AskingSink(NullSink):
    """Records what goes out on /imu_out; asks for changes when given output counts are reached."""

    def __init__(self, control: FaultControl, asks: dict[int, tuple[str, str | None, object]]) -> None:
        super().__init__()
        self.control = control
        self.asks = asks
        self.topics: dict[int, str] = {}
        self.z: list[float] = []
        self.store = synthetic.store()

    def add_channel(self, topic: str, msgtype: str, schema_encoding: str, schema_text: str,
                    message_encoding: str = 'cdr', metadata: dict[str, str] | None = None) -> int:
        channel = super().add_channel(topic, msgtype, schema_encoding, schema_text)
        self.topics[channel] = topic
        return channel

    def write(self, channel_id: int, log_time: int, publish_time: int, data: bytes | memoryview) -> None:
        if self.topics[channel_id] != '/imu_out':
            return
        self.z.append(self.store.deserialize_cdr(bytes(data), IMU).angular_velocity.z)
        ask = self.asks.get(len(self.z))
        if ask is not None:
            self.control.ask(*ask)


def run_with(tmp_path: Path, asks: dict[int, tuple[str, str | None, object]]) -> tuple[AskingSink, list]:
    bag = make_bag(tmp_path / 'imu.mcap', [('/imu', IMU, 100.0)], 1.0)
    scenario = parse_scenario(SCENARIO)
    control = FaultControl(scenario)
    sink = AskingSink(control, asks)
    inputs = InputSet([bag])
    try:
        catalog = TypeCatalog(inputs.channels, inputs.ros_distro)
        run, _ = replay(inputs, scenario, catalog, sink, seed=0, control=control)
    finally:
        inputs.close()
    return sink, run.stats.events


def test_a_switch_and_a_new_value_apply_from_the_next_message(tmp_path: Path) -> None:
    sink, events = run_with(tmp_path, {10: ('bias', None, True), 50: ('bias', 'angular_velocity_z_bias', 2),
                                       80: ('bias', None, False)})
    raw = synthetic.imu_values(0.0)[0]  # the synthetic yaw rate, 0.1 rad/s throughout
    expected = [raw] * 10 + [raw + 0.5] * 40 + [raw + 2.0] * 30 + [raw] * 20
    assert sink.z == pytest.approx(expected)
    assert [(e.state, e.source) for e in events] == [('active', 'manual'), ('config_updated', 'manual'),
                                                      ('inactive', 'manual')]
    assert [round((e.time - events[0].time) / 1e7) for e in events] == [0, 40, 70]  # 100 Hz: at messages 11, 51, 81
    assert events[1].details == 'config_update={angular_velocity_z_bias=2.0}'  # the anchor's describe_config_update


def test_changes_are_checked_when_asked() -> None:
    control = FaultControl(parse_scenario(SCENARIO))
    with pytest.raises(FieldValueError, match="no fault 'bais'"):
        control.ask('bais', None, True)
    with pytest.raises(FieldValueError, match='not a number'):
        control.ask('bias', 'angular_velocity_z_bias', 'fast')
    with pytest.raises(FieldValueError, match='is not true or false'):
        control.ask('bias', None, 'yes')
    assert control.take() == []


def test_changes_live_in_the_fault_state_and_never_in_the_loaded_scenario(tmp_path: Path) -> None:
    bag = make_bag(tmp_path / 'imu.mcap', [('/imu', IMU, 100.0)], 1.0)
    scenario = parse_scenario(SCENARIO)
    control = FaultControl(scenario)
    for passes in (1, 2):  # a play's second pass (a loop, a seek) keeps what was changed in the first
        sink = AskingSink(control, {10: ('bias', None, True), 20: ('bias', 'angular_velocity_z_bias', 1.5)}
                          if passes == 1 else {10: ('bias', None, True)})
        with InputSet([bag]) as inputs:
            replay(inputs, scenario, TypeCatalog(inputs.channels, inputs.ros_distro), sink, seed=0, control=control)
        raw = synthetic.imu_values(0.0)[0]
        assert sink.z[25] == pytest.approx(raw + 1.5)  # pass 2: the value set in pass 1, from the one fault state
    assert scenario.fault('bias').config == {'angular_velocity_z_bias': 0.5}  # as the file says
    assert scenario.fault('bias').config_text == {'angular_velocity_z_bias': '0.5'}
    assert control.state.fault('bias').config == {'angular_velocity_z_bias': 1.5}
    assert control.fault('bias').describe_config() == 'config={angular_velocity_z_bias=1.5}'


def test_the_live_session_changes_the_state_not_the_scenario() -> None:
    from bagfault.live.session import LiveSession

    scenario = parse_scenario(SCENARIO)
    catalog = TypeCatalog([], 'jazzy')
    session = LiveSession(scenario, catalog, {'imu': IMU}, lambda: 1_000_000_000, seed=0)
    session.start()
    session.set_config('bias', 'angular_velocity_z_bias', 2.0)
    assert scenario.fault('bias').config == {'angular_velocity_z_bias': 0.5}
    assert session.state.fault('bias').config == {'angular_velocity_z_bias': 2.0}
    assert [f.config for f in session.faults()] == [{'angular_velocity_z_bias': 2.0}]
    reloaded = parse_scenario(SCENARIO.replace('0.5', '0.5, linear_acceleration_x_bias: 0.1'))
    _, kept = session.reload(reloaded)
    assert kept == ['bias.angular_velocity_z_bias=2.0']  # the file did not change that key: the run's value stays
    assert session.state.fault('bias').config == {'angular_velocity_z_bias': 2.0, 'linear_acceleration_x_bias': 0.1}
    assert reloaded.fault('bias').config == {'angular_velocity_z_bias': 0.5, 'linear_acceleration_x_bias': 0.1}
