"""The plugin is found through its entry point and biases the battery voltage."""

from __future__ import annotations

import textwrap

import pytest
from mcap.reader import make_reader
from rosbags.typesys import Stores, get_typestore

from bagfault import api
from bagfault.demo import synthetic
from bagfault.injectors.registry import injector_types
from bagfault.scenario import parse_scenario

SCENARIO = textwrap.dedent("""
    injectors:
      - id: battery
        type: battery_state
        topic:
          input_topic: /battery_state_raw
          output_topic: /battery_state
          qos_depth: 10
    faults:
      - id: battery_voltage_bias
        injector_id: battery
        active_on_startup: true
        config:
          voltage_bias: -1.5
""")


def test_type_is_registered():
    assert 'battery_state' in injector_types()


def test_voltage_bias_applied(tmp_path):
    bag = tmp_path / 'battery.mcap'
    stream = synthetic.Stream('/battery_state_raw', 'sensor_msgs/msg/BatteryState', 1.0)
    synthetic.write_mcap(bag, synthetic.messages([stream], 5.0))
    api.run(parse_scenario(SCENARIO), [bag], tmp_path / 'out.mcap')
    store = get_typestore(Stores.ROS2_HUMBLE)
    with (tmp_path / 'out.mcap').open('rb') as handle:
        rows = [(c.topic, m.log_time, store.deserialize_cdr(m.data, s.name))
                for s, c, m in make_reader(handle).iter_messages(topics=['/battery_state'])]
    assert len(rows) == 5
    for _, time, message in rows:
        t = (time - synthetic.DEFAULT_START) / 1e9
        assert message.voltage == pytest.approx(synthetic.battery_values(t)[0] - 1.5, abs=1e-5)
