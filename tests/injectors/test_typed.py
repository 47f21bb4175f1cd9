"""Built-in typed injectors: each anchor key with its exact meaning."""

from __future__ import annotations

import math

import numpy as np
import pytest
from support.helpers import rpy

from bagfault.demo import synthetic
from bagfault.injectors.imu import ImuInjector
from bagfault.injectors.joint_state import JointStateInjector
from bagfault.injectors.odom import OdomInjector
from bagfault.injectors.scan import ScanInjector
from bagfault.injectors.tf import TfInjector

ODOM, SCAN, JOINT, IMU, TF = (
    'nav_msgs/msg/Odometry', 'sensor_msgs/msg/LaserScan', 'sensor_msgs/msg/JointState',
    'sensor_msgs/msg/Imu', 'tf2_msgs/msg/TFMessage',
)


def yaw_of(q) -> float:
    return rpy(q)[2]


def test_odom_biases_add_up_and_yaw_bias_is_in_degrees(harness):
    msg = synthetic.odometry(harness.ts, 0, 2.0)
    active = harness.faults({'x_bias': 1.0, 'y_bias': -0.25, 'yaw_bias_deg': 10.0}, {'x_bias': 0.5})
    [(_, out)], _ = harness.run(OdomInjector, ODOM, [msg], active)
    assert out.pose.pose.position.x - msg.pose.pose.position.x == 1.5
    assert out.pose.pose.position.y - msg.pose.pose.position.y == -0.25
    assert yaw_of(out.pose.pose.orientation) == pytest.approx(0.2 + math.radians(10.0), abs=1e-12)
    q = out.pose.pose.orientation
    assert math.hypot(q.x, q.y, q.z, q.w) == pytest.approx(1.0)


def test_a_yaw_bias_on_the_zero_quaternion_gives_nan_as_tf2_does(harness):
    """ros2_fault_injection odom_fault_injector.cpp:112-130 (tf_fault_injector.cpp:166-179 likewise): getRPY of
    tf2::Matrix3x3(q), bias, setRPY, normalize. tf2's Matrix3x3::setRotation scales by s = 2 / |q|^2, which is
    inf for the zero quaternion, and 0 * inf is NaN: every angle, and so every component out, is NaN."""
    msg = synthetic.odometry(harness.ts, 0, 2.0)
    q = msg.pose.pose.orientation
    q.x = q.y = q.z = q.w = 0.0
    [(_, out)], _ = harness.run(OdomInjector, ODOM, [msg], harness.faults({'yaw_bias_deg': 10.0}))
    o = out.pose.pose.orientation
    assert all(math.isnan(v) for v in (o.x, o.y, o.z, o.w))
    tf = synthetic.tf_message(harness.ts, 0, 0.0)
    r = tf.transforms[1].transform.rotation
    r.x = r.y = r.z = r.w = 0.0
    [(_, moved)], _ = harness.run(TfInjector, TF, [tf], harness.faults(
        {'parent_frame': 'base_link', 'child_frame': 'laser', 'yaw_bias_deg': 10.0}))
    m = moved.transforms[1].transform.rotation
    assert all(math.isnan(v) for v in (m.x, m.y, m.z, m.w))
    untouched = moved.transforms[0].transform.rotation  # another frame pair: no fault, no change
    assert not math.isnan(untouched.w)


def test_odom_covariance_is_max_of_scaled_and_floor(harness):
    msg = synthetic.odometry(harness.ts, 0, 1.0)
    active = harness.faults({'pose_covariance_scale': 10.0, 'pose_covariance_floor': 0.05,
                             'twist_covariance_scale': 3.0})
    [(_, out)], _ = harness.run(OdomInjector, ODOM, [msg], active)
    expected_pose = np.maximum(np.asarray(msg.pose.covariance) * 10.0, 0.05)
    assert np.array_equal(out.pose.covariance, expected_pose)
    assert out.pose.covariance[0] == pytest.approx(0.1) and out.pose.covariance[1] == 0.05
    assert np.array_equal(out.twist.covariance, np.asarray(msg.twist.covariance) * 3.0)


def test_odom_noise_uses_the_largest_stddev_and_is_gaussian(harness):
    msgs = [synthetic.odometry(harness.ts, 0, 1.0) for _ in range(4000)]
    active = harness.faults({'x_noise_stddev': 0.05}, {'x_noise_stddev': 0.2})
    outs, _ = harness.run(OdomInjector, ODOM, msgs, active, batch=True)
    dx = np.array([o.pose.pose.position.x - msgs[0].pose.pose.position.x for _, o in outs])
    assert abs(dx.mean()) < 0.02
    assert dx.std() == pytest.approx(0.2, rel=0.05)
    dy = np.array([o.pose.pose.position.y - msgs[0].pose.pose.position.y for _, o in outs])
    assert np.all(dy == 0.0)


@pytest.mark.parametrize('batch', [False, True])
def test_a_nan_noise_level_adds_no_noise_as_the_anchors_max_keeps_the_other_level(harness, batch):
    """ros2_fault_injection folds levels with std::max(level, value) from 0.0 (fault_injector_base.cpp:143-156,
    active_max_double): std::max(0.0, nan) is 0.0, so a nan stddev alone adds nothing, and beside 0.2 the
    noise is 0.2 -- never nan in the output."""
    msgs = [synthetic.odometry(harness.ts, 0, 1.0) for _ in range(4000)]
    alone, _ = harness.run(OdomInjector, ODOM, msgs, harness.faults({'x_noise_stddev': math.nan}), batch=batch)
    assert all(o.pose.pose.position.x == m.pose.pose.position.x for (_, o), m in zip(alone, msgs, strict=True))
    both, _ = harness.run(OdomInjector, ODOM, msgs, harness.faults({'x_noise_stddev': math.nan},
                                                                 {'x_noise_stddev': 0.2}), batch=batch)
    dx = np.array([o.pose.pose.position.x - m.pose.pose.position.x for (_, o), m in zip(both, msgs, strict=True)])
    assert np.all(np.isfinite(dx)) and dx.std() == pytest.approx(0.2, rel=0.05)


def test_drop_probability_uses_the_strongest_fault(harness):
    msgs = [synthetic.imu(harness.ts, 0, 0.0) for _ in range(5000)]
    active = harness.faults({'drop_probability': 0.1}, {'drop_probability': 0.6})
    outs, _ = harness.run(ImuInjector, IMU, msgs, active)
    assert len(outs) / 5000 == pytest.approx(0.4, abs=0.03)


def test_delay_retimes_log_and_publish_time_but_not_header(harness):
    msg = synthetic.imu(harness.ts, 123, 0.0)
    active = harness.faults({'delay_ms': 100}, {'delay_ms': 250})
    [(time, out)], raws = harness.run(ImuInjector, IMU, [msg], active)
    assert (raws[0].log_time, raws[0].publish_time) == (250_000_000, 250_000_000)
    assert (out.header.stamp.sec, out.header.stamp.nanosec) == (0, 123)


def test_delay_only_faults_do_not_decode(harness):
    injector = harness.injector(ImuInjector, IMU)
    injector.codec = None  # any decode attempt would fail
    from bagfault.injectors.base import RawMessage

    out = injector.process(RawMessage(5, 5, b'\x00\x01\x00\x00raw'), harness.faults({'delay_ms': 1}))
    assert out[0].data == b'\x00\x01\x00\x00raw' and out[0].log_time == 1_000_005


def test_imu_biases_and_noise_axes(harness):
    msg = synthetic.imu(harness.ts, 0, 1.0)
    active = harness.faults({'angular_velocity_z_bias': 0.05, 'linear_acceleration_x_bias': 0.1,
                             'linear_acceleration_y_bias': -0.05, 'linear_acceleration_z_bias': 0.2},
                            {'angular_velocity_z_bias': 0.05})
    [(_, out)], _ = harness.run(ImuInjector, IMU, [msg], active)
    assert out.angular_velocity.z - msg.angular_velocity.z == pytest.approx(0.1, abs=1e-15)
    assert out.linear_acceleration.x - msg.linear_acceleration.x == pytest.approx(0.1, abs=1e-15)
    assert out.linear_acceleration.y - msg.linear_acceleration.y == pytest.approx(-0.05, abs=1e-15)
    assert out.linear_acceleration.z - msg.linear_acceleration.z == pytest.approx(0.2, abs=1e-15)
    assert out.angular_velocity.x == msg.angular_velocity.x


def test_joint_state_bias_and_noise_on_every_velocity(harness):
    msg = synthetic.joint_state(harness.ts, 0, 0.0)
    [(_, out)], _ = harness.run(JointStateInjector, JOINT, [msg], harness.faults({'velocity_bias': 0.1}))
    assert np.allclose(out.velocity - msg.velocity, 0.1, atol=1e-15)
    assert np.array_equal(out.position, msg.position)
    [(_, noisy)], _ = harness.run(JointStateInjector, JOINT, [msg], harness.faults({'velocity_noise_stddev': 0.5}))
    assert np.all(noisy.velocity != msg.velocity)


def test_scan_bias_and_noise_touch_finite_ranges_and_clamp(harness):
    msg = synthetic.laser_scan(harness.ts, 0, 0.0)
    [(_, out)], _ = harness.run(ScanInjector, SCAN, [msg], harness.faults({'range_bias': 0.2}))
    finite = np.isfinite(msg.ranges)
    assert np.allclose(out.ranges[finite], msg.ranges[finite] + np.float32(0.2), atol=1e-6)
    assert np.all(np.isinf(out.ranges[~finite]))
    [(_, clamped)], _ = harness.run(ScanInjector, SCAN, [msg], harness.faults({'range_bias': 50.0}))
    assert np.all(clamped.ranges[finite] == np.float32(10.0))
    [(_, low)], _ = harness.run(ScanInjector, SCAN, [msg], harness.faults({'range_bias': -50.0}))
    assert np.all(low.ranges[finite] == np.float32(0.1))


@pytest.mark.parametrize(('value', 'check'), [
    (math.inf, np.isposinf), (-math.inf, np.isneginf), (math.nan, np.isnan), (0.5, lambda r: r == np.float32(0.5)),
])
def test_scan_sector_replaces_only_beams_inside(harness, value, check):
    msg = synthetic.laser_scan(harness.ts, 0, 0.0)
    active = harness.faults({'sector_min_deg': -20.5, 'sector_max_deg': 20.5, 'sector_value': value})
    [(_, out)], _ = harness.run(ScanInjector, SCAN, [msg], active)
    angles = np.arange(360) - 180  # beam i points at i - 180 degrees
    inside = (angles >= -20) & (angles <= 20)
    assert inside.sum() == 41
    assert np.all(check(out.ranges[inside]))
    assert np.array_equal(out.ranges[~inside], msg.ranges[~inside])


def test_scan_sector_wraps_through_180(harness):
    msg = synthetic.laser_scan(harness.ts, 0, 0.0)
    active = harness.faults({'sector_min_deg': 170.5, 'sector_max_deg': -170.5, 'sector_value': 1.0})
    [(_, out)], _ = harness.run(ScanInjector, SCAN, [msg], active)
    angles = np.arange(360) - 180
    inside = (angles >= 171) | (angles <= -171)
    assert np.all(out.ranges[inside] == 1.0) and np.array_equal(out.ranges[~inside], msg.ranges[~inside])


def test_tf_changes_only_the_matching_transform(harness):
    msg = synthetic.tf_message(harness.ts, 0, 3.0)
    active = harness.faults({'parent_frame': 'odom', 'child_frame': 'base_link', 'x_bias': 0.25,
                             'y_bias': -0.1, 'z_bias': 0.05, 'yaw_bias_deg': 10.0})
    [(_, out)], _ = harness.run(TfInjector, TF, [msg], active)
    moved, fixed = out.transforms
    t_in = msg.transforms[0].transform.translation
    assert (moved.transform.translation.x - t_in.x, moved.transform.translation.y - t_in.y,
            moved.transform.translation.z - t_in.z) == pytest.approx((0.25, -0.1, 0.05), abs=1e-15)
    assert yaw_of(moved.transform.rotation) == pytest.approx(0.3 + math.radians(10), abs=1e-12)
    assert fixed == msg.transforms[1]


def test_tf_roll_pitch_yaw_bias_add_to_the_angles(harness):
    msg = synthetic.tf_message(harness.ts, 0, 0.0)
    active = harness.faults({'parent_frame': 'base_link', 'child_frame': 'laser', 'roll_bias_deg': 5.0,
                             'pitch_bias_deg': 5.0, 'yaw_bias_deg': 10.0})
    [(_, out)], _ = harness.run(TfInjector, TF, [msg], active)
    q = out.transforms[1].transform.rotation
    assert rpy(q) == pytest.approx(
        (math.radians(5), math.radians(5), math.radians(10)), abs=1e-12)


def test_tf_drop_removes_matching_transform_only_and_delay_moves_whole_message(harness):
    msg = synthetic.tf_message(harness.ts, 0, 0.0)
    active = harness.faults({'parent_frame': 'odom', 'child_frame': 'base_link', 'drop_probability': 1.0},
                            {'parent_frame': 'a', 'child_frame': 'b', 'delay_ms': 250})
    [(time, out)], _ = harness.run(TfInjector, TF, [msg], active)
    assert [t.child_frame_id for t in out.transforms] == ['laser']
    assert time == 250_000_000
