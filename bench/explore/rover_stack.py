#!/usr/bin/env python3
"""A rover controller with eight planted bugs of known minimal trigger: the benchmark of `bagfault explore`.

It takes /imu (50 Hz) and /odom (25 Hz) of rover_bench.mcap (make_bag.py) and
publishes /cmd_vel (TwistStamped) and /estimate (Odometry), each on a 20 Hz
timer of ROS time (sim time under `bagfault test`). Every bug is decided by
the header stamps and values of one topic in the order they arrive, or by
intervals of stamps of two topics compared once both are known: never by the
clock at arrival, never by how two topics interleave. So load cannot move a
threshold; it can only delay when a latched bug shows, and every bug stays
latched until the end. The bugs (thresholds derived in bugs.yaml):

  B1 gyro_saturation   |yaw rate - 0.1| > 0.3 rad/s on consecutive IMU samples spanning
                       more than 1.5 s: the heading filter divides by zero, /cmd_vel
                       angular.z is NaN from then on                      (strength + duration)
  B2 odom_silence      a gap of more than 0.8 s between odometry stamps: the watchdog
                       latches a stop and /cmd_vel is never published again (duration)
  B3 stale_odom        an odometry stamp older by more than 0.2 s than the newest one
                       seen: a negative dt, /cmd_vel linear.x = 2.0        (delay threshold)
  B4 dead_reckoning    an IMU gap and an odometry gap (stamps, > 0.1 s each) overlapping
                       by more than 0.3 s: /cmd_vel linear.x = -1.0         (two faults at once)
  B5 impact_crash      linear_acceleration.z above 15 m/s^2 on 10 consecutive IMU
                       samples: the impact handler crashes the process      (crash)
  B6 docking_gain      between 6 s and 8 s of the mission (odometry stamps) the heading gain
                       is 8 instead of 0.8: |0.1 - 8 x yaw error| > 1 rad/s (phase window)
  B7 sensor_conflict   IMU yaw rate off by more than 0.15 rad/s and odometry yaw off the
                       plan by more than 5 degrees, over stamp intervals overlapping
                       by more than 0.5 s: /estimate x is NaN                (two faults at once)
  B8 odom_teleport     consecutive odometry x more than 1.0 m apart: /estimate x = 100 (strength)

Without faults: /cmd_vel linear.x 0.2, angular.z 0.1, /estimate x = odometry x.
Margins lead to some bugs: linear.x is 0.2 + the largest stamp step back so far
- the largest gap overlap so far, angular.z follows the yaw error, /cmd_vel is
not published while no odometry arrives (its gap follows an odometry drop).

    python3 rover_stack.py [--ros-args ...]
"""

from __future__ import annotations

import math
import os
import sys

import rclpy
from geometry_msgs.msg import TwistStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Imu

NS = 1_000_000_000
MISSION_START = 1_700_000_000 * NS  # the bag's first stamp: the plan's time zero
PLAN_YAW_RATE = 0.1  # rad/s: the mission turns at this rate, so yaw(t) = 0.1 t
DOCKING = (6 * NS, 8 * NS)  # the docking phase, from the mission start
GAP = NS // 10  # stamps further apart than this are a gap (B4)


def wrap(angle: float) -> float:
    """An angle in [-pi, pi)."""
    return (angle + math.pi) % (2 * math.pi) - math.pi


def overlap(a: tuple[int, int], b: tuple[int, int]) -> int:
    """How long two stamp intervals share, in ns (0 when apart)."""
    return max(0, min(a[1], b[1]) - max(a[0], b[0]))


class Intervals:
    """Runs of consecutive samples (in arrival order) for which a condition held: [first stamp, last stamp]."""

    def __init__(self) -> None:
        self.closed: list[tuple[int, int]] = []
        self.open: tuple[int, int] | None = None

    def add(self, stamp: int, holds: bool) -> None:
        if holds:
            self.open = (self.open[0], max(self.open[1], stamp)) if self.open else (stamp, stamp)
        elif self.open is not None:
            self.closed.append(self.open)
            self.open = None

    def all(self) -> list[tuple[int, int]]:
        return [*self.closed, *([self.open] if self.open else [])]


class Controller(Node):
    """The rover's controller and state estimate, with the bugs of the module's docstring."""

    def __init__(self) -> None:
        super().__init__('rover_controller')
        every = QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE)
        self.create_subscription(Imu, '/imu', self.on_imu, every)
        self.create_subscription(Odometry, '/odom', self.on_odom, every)
        self.cmd = self.create_publisher(TwistStamped, '/cmd_vel', 10)
        self.estimate = self.create_publisher(Odometry, '/estimate', 10)
        self.create_timer(0.05, self.publish_cmd)
        self.create_timer(0.05, self.publish_estimate)
        # IMU state
        self.saturated_since: int | None = None
        self.shocks = 0
        self.imu_newest: int | None = None
        self.imu_gaps: list[tuple[int, int]] = []
        self.gyro_off = Intervals()
        # odometry state
        self.odom_newest: int | None = None
        self.odom_gaps: list[tuple[int, int]] = []
        self.yaw_off = Intervals()
        self.last_x: float | None = None
        self.x = 0.0
        self.y = 0.0
        self.fresh = False
        self.turn: float | None = None  # the largest turn asked since the last command
        self.step_back = 0.0  # the largest step back of odometry stamps so far, s
        self.gap_overlap = 0.0  # the largest overlap of an IMU gap and an odometry gap so far, s
        # latched bugs
        self.nan_turn = False  # B1
        self.stopped = False  # B2
        self.speeding = False  # B3
        self.reversing = False  # B4
        self.conflict = False  # B7
        self.teleported = False  # B8

    def on_imu(self, message: Imu) -> None:
        stamp = message.header.stamp.sec * NS + message.header.stamp.nanosec
        residual = message.angular_velocity.z - PLAN_YAW_RATE
        if abs(residual) > 0.3:  # B1
            if self.saturated_since is None:
                self.saturated_since = stamp
            elif stamp - self.saturated_since > 1.5 * NS:
                self.nan_turn = True
        else:
            self.saturated_since = None
        self.shocks = self.shocks + 1 if message.linear_acceleration.z > 15.0 else 0
        if self.shocks >= 10:  # B5
            print('rover_controller: impact handler failed', file=sys.stderr, flush=True)
            os._exit(3)
        if self.imu_newest is not None and stamp - self.imu_newest > GAP:
            self.imu_gaps.append((self.imu_newest, stamp))
            self.check_gaps()
        self.imu_newest = stamp if self.imu_newest is None else max(self.imu_newest, stamp)
        self.gyro_off.add(stamp, abs(residual) > 0.15)
        self.check_conflict()

    def on_odom(self, message: Odometry) -> None:
        stamp = message.header.stamp.sec * NS + message.header.stamp.nanosec
        if self.odom_newest is not None:
            back = (self.odom_newest - stamp) / NS
            self.step_back = max(self.step_back, back)
            if back > 0.2:  # B3
                self.speeding = True
            if stamp - self.odom_newest > 0.8 * NS:  # B2
                self.stopped = True
            if stamp - self.odom_newest > GAP:
                self.odom_gaps.append((self.odom_newest, stamp))
                self.check_gaps()
        self.odom_newest = stamp if self.odom_newest is None else max(self.odom_newest, stamp)
        q = message.pose.pose.orientation
        yaw = math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))
        since = stamp - MISSION_START
        error = wrap(yaw - wrap(PLAN_YAW_RATE * since / NS))
        gain = 8.0 if DOCKING[0] <= since < DOCKING[1] else 0.8  # B6: the docking gain
        turn = PLAN_YAW_RATE - gain * error
        if self.turn is None or abs(turn) > abs(self.turn):
            self.turn = turn
        self.yaw_off.add(stamp, abs(error) > math.radians(5.0))
        self.check_conflict()
        x = message.pose.pose.position.x
        if self.last_x is not None and abs(x - self.last_x) > 1.0:  # B8
            self.teleported = True
        self.last_x, self.x, self.y = x, x, message.pose.pose.position.y
        self.fresh = True

    def check_gaps(self) -> None:
        for imu in self.imu_gaps:
            for odom in self.odom_gaps:
                shared = overlap(imu, odom) / NS
                self.gap_overlap = max(self.gap_overlap, shared)
                if shared > 0.3:  # B4
                    self.reversing = True

    def check_conflict(self) -> None:
        if any(overlap(a, b) > NS // 2 for a in self.gyro_off.all() for b in self.yaw_off.all()):  # B7
            self.conflict = True

    def publish_cmd(self) -> None:
        if self.stopped or not self.fresh:  # no new odometry: no command
            return
        self.fresh = False
        command = TwistStamped()
        command.header.stamp = self.get_clock().now().to_msg()
        command.header.frame_id = 'base_link'
        speed = 0.2 + self.step_back - self.gap_overlap
        if self.reversing:
            speed = -1.0
        elif self.speeding:
            speed = 2.0
        command.twist.linear.x = speed
        command.twist.angular.z = math.nan if self.nan_turn else (self.turn or 0.0)
        self.turn = None
        self.cmd.publish(command)

    def publish_estimate(self) -> None:
        if self.last_x is None:
            return
        estimate = Odometry()
        estimate.header.stamp = self.get_clock().now().to_msg()
        estimate.header.frame_id = 'odom'
        estimate.pose.pose.position.x = math.nan if self.conflict else 100.0 if self.teleported else self.x
        estimate.pose.pose.position.y = self.y
        self.estimate.publish(estimate)


def main() -> int:
    rclpy.init()
    node = Controller()
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, rclpy.executors.ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
