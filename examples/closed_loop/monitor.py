#!/usr/bin/env python3
"""A small system under test: an IMU drift monitor and an odometry watchdog, reporting on /diagnostics.

    imu_monitor: drift      ERROR while the mean of (IMU yaw rate - odometry yaw rate) over the
                            last second of ROS time exceeds --limit rad/s
    odom_watchdog: timeout  ERROR while no odometry arrived for more than --timeout s of ROS time

Both statuses go out on /diagnostics at 5 Hz of ROS time (sim time with
use_sim_time, as `bagfault test` starts it). --no-detection disables the
drift check (a system with a bug, for the failing case); --crash-after S
makes it die S seconds of ROS time after the first message (for
`system_alive`).

    python3 monitor.py [--limit 0.05] [--timeout 0.3] [--no-detection] [--crash-after S]
                       [--hardware-id ID] [--ros-args ...]
"""

from __future__ import annotations

import argparse
import os
import sys
from collections import deque

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rclpy.utilities import remove_ros_args
from sensor_msgs.msg import Imu

WINDOW_NS = 1_000_000_000


class SafetyMonitor(Node):
    """Compares the IMU yaw rate with odometry's and watches odometry's rate."""

    def __init__(self, limit: float, timeout: float, detection: bool, hardware_id: str,
                 crash_after: float | None) -> None:
        super().__init__('safety_monitor')
        self.limit = limit
        self.hardware_id = hardware_id
        self.crash_after = crash_after
        self.first: int | None = None
        self.timeout_ns = int(timeout * 1e9)
        self.detection = detection
        self.odom_rate = 0.0
        self.last_odom: int | None = None
        self.residuals: deque[tuple[int, float]] = deque()
        self.create_subscription(Imu, '/imu', self.on_imu, 50)
        self.create_subscription(Odometry, '/odom', self.on_odom, 50)
        self.publisher = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.create_timer(0.2, self.report)
        self.get_logger().info(f'monitoring /imu and /odom (limit {limit} rad/s, timeout {timeout} s)')

    def now(self) -> int:
        return self.get_clock().now().nanoseconds

    def on_odom(self, message: Odometry) -> None:
        self.odom_rate = message.twist.twist.angular.z
        self.last_odom = self.now()

    def on_imu(self, message: Imu) -> None:
        if self.last_odom is None:
            return  # nothing to compare with yet
        now = self.now()
        self.residuals.append((now, message.angular_velocity.z - self.odom_rate))
        while self.residuals and self.residuals[0][0] < now - WINDOW_NS:
            self.residuals.popleft()

    def report(self) -> None:
        now = self.now()
        if now == 0:
            return  # no /clock yet
        self.first = self.first or now
        if self.crash_after is not None and now - self.first > self.crash_after * 1e9:
            print(f'safety_monitor: crashing on purpose after {self.crash_after} s', file=sys.stderr, flush=True)
            os._exit(11)
        drift = sum(r for _, r in self.residuals) / len(self.residuals) if self.residuals else 0.0
        drifting = self.detection and abs(drift) > self.limit
        silent = self.last_odom is not None and now - self.last_odom > self.timeout_ns
        array = DiagnosticArray()
        array.header.stamp = self.get_clock().now().to_msg()
        array.status = [
            self.status('imu_monitor: drift', drifting, f'yaw rate residual {drift:+.3f} rad/s',
                        'residual', f'{drift:.4f}'),
            self.status('odom_watchdog: timeout', silent,
                        'odometry silent' if silent else 'odometry arriving', 'last_odom_ns', str(self.last_odom)),
        ]
        self.publisher.publish(array)

    def status(self, name: str, error: bool, message: str, key: str, value: str) -> DiagnosticStatus:
        return DiagnosticStatus(level=DiagnosticStatus.ERROR if error else DiagnosticStatus.OK, name=name,
                                message=message, hardware_id=self.hardware_id,
                                values=[KeyValue(key=key, value=value)])


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--limit', type=float, default=0.05, help='drift limit, rad/s')
    parser.add_argument('--timeout', type=float, default=0.3, help='odometry timeout, s')
    parser.add_argument('--no-detection', action='store_true', help='never report drift (a buggy system)')
    parser.add_argument('--crash-after', type=float, default=None, metavar='S', help='die after S s of ROS time')
    parser.add_argument('--hardware-id', default='rover', help='hardware_id of the statuses')
    args = parser.parse_args(remove_ros_args(sys.argv)[1:])
    rclpy.init()
    node = SafetyMonitor(args.limit, args.timeout, not args.no_detection, args.hardware_id, args.crash_after)
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
