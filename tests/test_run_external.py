"""`run` on real bags recorded by other tools; outputs read back with mcap and rosbags."""

from __future__ import annotations

import math
import textwrap
from collections import Counter

import numpy as np
import pytest
from mcap.reader import make_reader
from support.helpers import FIXTURES, NS, counts, decoded, rosbags_counts, rpy, third_party
from support.io_cases import ROSBAG2_DIRS, metadata_counts

from bagfault import api
from bagfault.errors import EngineError
from bagfault.scenario import parse_scenario

PASS_THROUGH = parse_scenario('injectors: []\n')
TURTLEBOT = 'Turtlebot_Walker_Algorithm_ROS2/walker_bag_topics_list'


@pytest.mark.parametrize('relative', third_party(ROSBAG2_DIRS))
def test_every_readable_rosbag2_dir_runs_through(tmp_path, external, relative):
    bag = external / relative
    out = tmp_path / 'out.mcap'
    result = api.run(PASS_THROUGH, [bag], out)
    expected = metadata_counts(bag)
    assert result.stats.input_messages == sum(expected.values())
    assert +counts(out) == expected
    if relative not in ROSBAGS_CANNOT_READ:
        assert rosbags_counts(out) == expected


# rosbags' AnyReader cannot parse rosbag2's service-event schemas ('req --- resp'),
# in the input as in the output, which copies them verbatim.
ROSBAGS_CANNOT_READ = {
    'rosbag2/rosbag2_tests/resources/mcap/bag_with_topics_and_service_events',
    'rosbag2/rosbag2_tests/resources/sqlite3/bag_with_topics_and_service_events',
}


@pytest.mark.parametrize('relative', third_party([
    'rosbag2/rosbag2_tests/resources/sqlite3/wrong_rmw_test',
    'rosbag2/rosbag2_tests/resources/mcap/wrong_rmw_test',
    'rosbag2-dashing/rosbag2_tests/resources/wrong_rmw_test',
]))
def test_non_cdr_bags_are_refused(tmp_path, external, relative):
    with pytest.raises(EngineError, match="serialization format 'wrong_format' is not CDR"):
        api.run(PASS_THROUGH, [external / relative], tmp_path / 'out.mcap')
    assert not list(tmp_path.iterdir())


TURTLEBOT_SCENARIO = textwrap.dedent("""
    injectors:
      - {id: imu, type: imu, input_topic: /imu, output_topic: /imu}
      - {id: odom, type: odom, input_topic: /odom, output_topic: /odom}
      - {id: scan, type: scan, input_topic: /scan, output_topic: /scan}
      - {id: joints, type: joint_state, input_topic: /joint_states, output_topic: /joint_states}
      - {id: tf, type: tf, input_topic: /tf, output_topic: /tf}
    faults:
      - {id: imu_bias, injector_id: imu, start: 2.0, duration: 5.0, config: {angular_velocity_z_bias: 0.5}}
      - {id: odom_bias, injector_id: odom, active_on_startup: true, config: {x_bias: 1.0, yaw_bias_deg: 10}}
      - id: blind
        injector_id: scan
        start: 1.0
        config: {sector_min_deg: -20.5, sector_max_deg: 20.5, sector_value: nan}
      - {id: wheel, injector_id: joints, start: 0.5, config: {velocity_bias: 0.1}}
      - id: tf_bias
        injector_id: tf
        active_on_startup: true
        config: {parent_frame: odom, child_frame: base_footprint, y_bias: 0.25}
""")


@pytest.fixture(scope='module')
def turtlebot(tmp_path_factory, external):
    bag = external / TURTLEBOT
    out = tmp_path_factory.mktemp('tb') / 'out.mcap'
    result = api.run(parse_scenario(TURTLEBOT_SCENARIO), [bag], out)
    return bag, out, result


def test_turtlebot_counts_unchanged(turtlebot):
    bag, out, _ = turtlebot
    got = counts(out)
    expected = metadata_counts(bag)
    expected['/fault_injection/events'] = 6
    assert +got == expected


def test_turtlebot_values(turtlebot):
    bag, out, result = turtlebot
    origin = result.stats.origin
    before = decoded(bag, ['/imu', '/odom', '/scan', '/joint_states', '/tf'])
    after = decoded(out, ['/imu', '/odom', '/scan', '/joint_states', '/tf'])
    for (t, a), (_, b) in zip(before['/imu'], after['/imu'], strict=True):
        expected = 0.5 if 2 * NS <= t - origin < 7 * NS else 0.0
        assert b.angular_velocity.z - a.angular_velocity.z == pytest.approx(expected, abs=1e-12)
        la, lb = a.linear_acceleration, b.linear_acceleration
        assert (lb.x, lb.y, lb.z) == (la.x, la.y, la.z)
    for (_, a), (_, b) in zip(before['/odom'], after['/odom'], strict=True):
        assert b.pose.pose.position.x - a.pose.pose.position.x == pytest.approx(1.0, abs=1e-12)
        qa, qb = a.pose.pose.orientation, b.pose.pose.orientation
        dyaw = rpy(qb)[2] - rpy(qa)[2]
        assert math.remainder(dyaw, 2 * math.pi) == pytest.approx(math.radians(10), abs=1e-9)
    for (t, a), (_, b) in zip(before['/scan'], after['/scan'], strict=True):
        angles = np.degrees(a.angle_min + np.arange(len(a.ranges)) * np.float64(a.angle_increment))
        angles = (angles + 180.0) % 360.0 - 180.0  # this lidar scans 0..360 degrees; the sector wraps
        inside = (angles >= -20.5) & (angles <= 20.5)
        if t - origin >= NS:
            assert np.isnan(b.ranges[inside]).all() and inside.any()
            assert np.array_equal(b.ranges[~inside], a.ranges[~inside])
        else:
            assert np.array_equal(b.ranges, a.ranges)
    for (t, a), (_, b) in zip(before['/joint_states'], after['/joint_states'], strict=True):
        expected = 0.1 if t - origin >= NS // 2 else 0.0
        assert np.allclose(b.velocity - a.velocity, expected, atol=1e-12)
    matched = 0
    for (_, a), (_, b) in zip(before['/tf'], after['/tf'], strict=True):
        for ta, tb in zip(a.transforms, b.transforms, strict=True):
            hit = ta.header.frame_id == 'odom' and ta.child_frame_id == 'base_footprint'
            matched += hit
            dy = tb.transform.translation.y - ta.transform.translation.y
            assert dy == pytest.approx(0.25 if hit else 0.0, abs=1e-12)
    assert matched > 100


def test_turtlebot_undecodable_type_passes_through(turtlebot):
    from support.helpers import raw_messages

    bag, out, _ = turtlebot
    from bagfault.io.sources import open_source

    source = open_source(bag)
    original = [bytes(d) for c, _, _, d in source.messages() if source.channels[c].topic == '/performance_metrics']
    source.close()
    copied = [d for _, _, d in raw_messages(out)['/performance_metrics']]
    assert copied == original and len(copied) == 131


def test_nav2_mcap_with_odom_bias(tmp_path, external):
    bag = external / 'evo/test/data/nav2_turtlebot.mcap'
    scenario = parse_scenario(textwrap.dedent("""
        injector: {id: odom, type: odom, input_topic: /odom, output_topic: /odom}
        faults:
          - {id: b, injector_id: odom, start: 10.0, duration: 20.0, config: {x_bias: 2.0}}
    """))
    out = tmp_path / 'nav2.mcap'
    result = api.run(scenario, [bag], out)
    assert +counts(out) == Counter({'/odom': 2639, '/tf': 5422, '/tf_static': 1, '/amcl_pose': 135,
                                    '/fault_injection/events': 2})
    before, after = decoded(bag, ['/odom']), decoded(out, ['/odom'])
    origin = result.stats.origin
    shifted = 0
    for (t, a), (_, b) in zip(before['/odom'], after['/odom'], strict=True):
        inside = 10 * NS <= t - origin < 30 * NS
        shifted += inside
        assert b.pose.pose.position.x - a.pose.pose.position.x == pytest.approx(2.0 if inside else 0.0, abs=1e-12)
    assert shifted > 100


def test_empty_bag_gives_channels_only(tmp_path, external):
    out = tmp_path / 'o.mcap'
    result = api.run(PASS_THROUGH, [external / 'rosbag2/ros2bag/test/resources/empty_bag'], out)
    assert result.stats.input_messages == 0 and 'no messages' in result.notes[-1]
    assert sum(counts(out).values()) == 0


def test_missing_topic_and_wrong_type_name_what_the_bag_has(tmp_path, external):
    bag = external / 'evo/test/data/nav2_turtlebot.mcap'
    missing = parse_scenario('injector: {id: imu, type: imu, input_topic: /imu, output_topic: /imu_out}\n')
    result = api.run(missing, [bag], tmp_path / 'missing.mcap')  # the anchor runs the rest: a warning
    [warning] = result.warnings
    assert 'input topic /imu is not in the bag, so its faults have no effect' in warning
    assert '/odom (nav_msgs/msg/Odometry)' in warning
    assert counts(tmp_path / 'missing.mcap')['/odom'] == 2639
    (tmp_path / 'missing.mcap').unlink()
    wrong = parse_scenario('injector: {id: imu, type: imu, input_topic: /odom, output_topic: /imu_out}\n')
    with pytest.raises(EngineError, match='needs sensor_msgs/msg/Imu but topic /odom in the bag carries nav_msgs/msg/Odometry'):
        api.run(wrong, [bag], tmp_path / 'o.mcap')
    expected = parse_scenario('injector: {id: any, type: topic, input_topic: /odom, output_topic: /odom_out, '
                              'message_type: sensor_msgs/msg/Imu}\n')
    with pytest.raises(EngineError, match='expects message_type sensor_msgs/msg/Imu but topic /odom in the bag '
                                          'carries nav_msgs/msg/Odometry'):
        api.run(expected, [bag], tmp_path / 'o.mcap')
    assert not list(tmp_path.iterdir())


def test_recorded_output_topic_is_replaced(tmp_path, rover_bag):
    scenario = parse_scenario('injector: {id: i, type: imu, input_topic: /sensors/imu_raw, output_topic: /odom_raw}\n')
    result = api.run(scenario, [rover_bag], tmp_path / 'o.mcap')
    assert counts(tmp_path / 'o.mcap')['/odom_raw'] == 2000
    assert any('/odom_raw is replaced' in n for n in result.notes)



def test_turtlebot_and_nav2_outputs_pass_every_readers_checks(tmp_path, external):
    """mcap with CRC validation, mcap-ros2-support decoding every message, rosbags; a definition for every schema."""
    from support.readers import verify

    turtlebot = tmp_path / 'turtlebot.mcap'
    api.run(parse_scenario(TURTLEBOT_SCENARIO), [external / TURTLEBOT], turtlebot,
            msg_paths=[FIXTURES / 'msg'])  # gazebo_msgs is in no standard type store
    nav2 = tmp_path / 'nav2.mcap'
    api.run(parse_scenario('injector: {id: odom, type: odom, input_topic: /odom, output_topic: /odom}\n'
                           'faults: [{id: b, injector_id: odom, start: 10.0, config: {x_bias: 2.0}}]\n'),
            [external / 'evo/test/data/nav2_turtlebot.mcap'], nav2)
    for out in (turtlebot, nav2):
        assert verify(out) == sum(counts(out).values())
        with out.open('rb') as stream:
            summary = make_reader(stream).get_summary()
        assert all(schema.data and schema.encoding == 'ros2msg' for schema in summary.schemas.values())
