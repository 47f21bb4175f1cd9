"""A custom message type, known only from the bag, handled by the plugin's injector."""

from __future__ import annotations

import textwrap

import numpy as np
import pytest
from bagfault_rover_plugins import WHEEL_ENCODERS_MSG
from mcap.reader import make_reader
from mcap.writer import Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from bagfault import api
from bagfault.injectors.registry import injector_types
from bagfault.scenario import parse_scenario

TYPE = 'rover_msgs/msg/WheelEncoders'
NS = 1_000_000_000
START = 1_700_000_000 * NS


def store():
    typestore = get_typestore(Stores.EMPTY)
    typestore.register(get_types_from_msg(WHEEL_ENCODERS_MSG, TYPE))
    return typestore


def write_bag(path, typestore):
    """20 Hz for 4 s; ticks grow by 10 per message, speeds 1.0 .. 4.0, status 0."""
    T = typestore.types
    with path.open('wb') as stream:
        writer = Writer(stream)
        writer.start(profile='ros2')
        schema = writer.register_schema(TYPE, 'ros2msg', WHEEL_ENCODERS_MSG.encode())
        channel = writer.register_channel('/wheels', 'cdr', schema)
        for k in range(80):
            time = START + k * NS // 20
            message = T[TYPE](
                header=T['std_msgs/msg/Header'](stamp=T['builtin_interfaces/msg/Time'](sec=time // NS,
                                                                                       nanosec=time % NS),
                                                frame_id='base'),
                ticks=np.array([10 * k, 10 * k + 1, 10 * k + 2, 10 * k + 3], dtype=np.int32),
                speeds=np.array([1.0, 2.0, 3.0, 4.0]), status=0)
            writer.add_message(channel, time, bytes(typestore.serialize_cdr(message, TYPE)), time)
        writer.finish()


def test_type_is_registered():
    assert 'wheel_encoders' in injector_types()


def test_custom_type_faults(tmp_path):
    typestore = store()
    write_bag(tmp_path / 'in.mcap', typestore)
    scenario = parse_scenario(textwrap.dedent("""
        injector: {id: wheels, type: wheel_encoders, input_topic: /wheels, output_topic: /wheels_faulty}
        faults:
          - {id: encoder_stuck, injector_id: wheels, start: 1.0, duration: 2.0,
             config: {ticks_stuck: true, speed_scale: 0.5, status_override: 3}}
    """))
    api.run(scenario, [tmp_path / 'in.mcap'], tmp_path / 'out.mcap')
    with (tmp_path / 'out.mcap').open('rb') as handle:
        rows = [(m.log_time, typestore.deserialize_cdr(m.data, TYPE))
                for _, _, m in make_reader(handle).iter_messages(topics=['/wheels_faulty'])]
    assert len(rows) == 80
    for k, (time, message) in enumerate(rows):
        if 1.0 <= (time - START) / NS < 3.0:
            assert list(message.ticks) == [200, 201, 202, 203]  # held from the message at 1.0 s (k = 20)
            assert list(message.speeds) == pytest.approx([0.5, 1.0, 1.5, 2.0])
            assert message.status == 3
        else:
            assert list(message.ticks) == [10 * k, 10 * k + 1, 10 * k + 2, 10 * k + 3]
            assert message.status == 0
