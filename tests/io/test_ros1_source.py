"""ROS 1 bags in: converted to ROS 2 on the way, faults applied, ROS 2 MCAP out."""

from __future__ import annotations

import textwrap
from collections import Counter

import pytest
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore
from support.helpers import NS, counts, decoded, third_party

from bagfault import api
from bagfault.io.sources import open_source
from bagfault.scenario import parse_scenario

SCENARIO = textwrap.dedent("""
    injectors:
      - {id: imu, type: imu, input_topic: /imu/data, output_topic: /imu/data}
      - {id: odom, type: odom, input_topic: /husky_velocity_controller/odom, output_topic: /odom_faulty}
    faults:
      - {id: gyro, injector_id: imu, start: 10.0, duration: 20.0, config: {angular_velocity_z_bias: 0.25}}
      - {id: slip, injector_id: odom, active_on_startup: true, config: {x_bias: 2.0}}
""")


def ros1_messages(path, topic):
    with AnyReader([path]) as reader:
        connections = [c for c in reader.connections if c.topic == topic]
        return [(t, reader.deserialize(raw, c.msgtype)) for c, t, raw in reader.messages(connections=connections)]


def test_robot_localization_bag_with_imu_and_odom_faults(tmp_path, external):
    bag = external / 'robot_localization/test/test1.bag'
    out = tmp_path / 'out.mcap'
    result = api.run(parse_scenario(SCENARIO), [bag], out)
    assert +counts(out) == Counter({'/imu/data': 11865, '/husky_velocity_controller/odom': 3952, '/odom_faulty': 3952,
                                    '/fix': 989, '/fault_injection/events': 3})
    with AnyReader([out], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
        assert reader.is2
        types = {c.topic: c.msgtype for c in reader.connections}
    assert types['/imu/data'] == 'sensor_msgs/msg/Imu' and types['/odom_faulty'] == 'nav_msgs/msg/Odometry'
    after = decoded(out, ['/imu/data', '/odom_faulty'])
    assert not hasattr(after['/imu/data'][0][1].header, 'seq')
    before = ros1_messages(bag, '/imu/data')
    origin = result.stats.origin
    biased = 0
    for (t, a), (t2, b) in zip(before, after['/imu/data'], strict=True):
        assert t == t2
        inside = 10 * NS <= t - origin < 30 * NS
        biased += inside
        assert b.angular_velocity.z - a.angular_velocity.z == pytest.approx(0.25 if inside else 0.0, abs=1e-12)
        assert (b.header.stamp.sec, b.header.stamp.nanosec) == (a.header.stamp.sec, a.header.stamp.nanosec)
    assert biased > 500
    odom_before = ros1_messages(bag, '/husky_velocity_controller/odom')
    for (_, a), (_, b) in zip(odom_before, after['/odom_faulty'], strict=True):
        assert b.pose.pose.position.x - a.pose.pose.position.x == pytest.approx(2.0, abs=1e-12)


@pytest.mark.parametrize('name', third_party(['example.bag', 'example-lz4.bag', 'example-bz2.bag']))
def test_chunk_compressions_give_the_same_messages(external, name):
    source = open_source(external / 'rosbag.js/fixtures' / name)
    try:
        got = Counter(source.channels[c].topic for c, _, _, _ in source.messages())
        assert sum(got.values()) == 8647
        assert {c.msgtype for c in source.channels if c.topic == '/tf'} == {'tf2_msgs/msg/TFMessage'}
    finally:
        source.close()


def test_unsorted_chunks_come_out_sorted(external):
    source = open_source(external / 'rosbag.js/fixtures/example-unsorted-chunks.bag')
    try:
        times = [t for _, t, _, _ in source.messages()]
        assert len(times) == 3 and times == sorted(times)
    finally:
        source.close()
