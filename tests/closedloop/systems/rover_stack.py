"""A system of two rclpy processes for the process and clock fault tests, started as a launch file starts them.

    python rover_stack.py [--ros-args ...]      the launcher: starts planner and controller, stops them on SIGINT
    python rover_stack.py planner               /planner: each /odom -> /cmd_vel (geometry_msgs/Twist, numbered
                                                in linear.y)
    python rover_stack.py controller            /controller: each /cmd_vel -> /controller/output (Twist, x2);
                                                a 10 Hz sim-time timer -> /controller/tick (std_msgs/Header, now())

Both nodes use sim time. Each prints '<name> up' on stderr once its endpoints exist.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import time


def launcher() -> int:
    children = [subprocess.Popen([sys.executable, __file__, role, '--ros-args', '-p', 'use_sim_time:=true'])
                for role in ('planner', 'controller')]
    stopping = []
    signal.signal(signal.SIGINT, lambda *_: stopping.append(1))
    signal.signal(signal.SIGTERM, lambda *_: stopping.append(1))
    while not stopping:
        time.sleep(0.05)
    for child in children:
        if child.poll() is None:
            child.send_signal(signal.SIGINT)
    for child in children:
        try:
            child.wait(timeout=10)
        except subprocess.TimeoutExpired:
            child.kill()
    return 0


def node(role: str) -> None:
    import rclpy
    from geometry_msgs.msg import Twist
    from nav_msgs.msg import Odometry
    from rclpy.executors import ExternalShutdownException
    from std_msgs.msg import Header

    rclpy.init(args=sys.argv)
    node = rclpy.create_node(role)
    if role == 'planner':
        publisher = node.create_publisher(Twist, '/cmd_vel', 10)
        sent = [0]

        def plan(odom: Odometry) -> None:
            command = Twist()
            command.linear.x = odom.twist.twist.linear.x
            command.linear.y = float(sent[0])  # a number per command, kept by the controller: pairs them up
            command.angular.z = odom.twist.twist.angular.z
            publisher.publish(command)
            sent[0] += 1

        node.create_subscription(Odometry, '/odom', plan, 10)
    else:
        output = node.create_publisher(Twist, '/controller/output', 10)
        ticks = node.create_publisher(Header, '/controller/tick', 10)

        def control(command: Twist) -> None:
            command.linear.x *= 2.0
            output.publish(command)

        def tick() -> None:
            header = Header()
            header.stamp = node.get_clock().now().to_msg()
            ticks.publish(header)

        node.create_subscription(Twist, '/cmd_vel', control, 10)
        node.create_timer(0.1, tick)
    print(f'{role} up', file=sys.stderr, flush=True)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        rclpy.try_shutdown()


if __name__ == '__main__':
    if len(sys.argv) > 1 and sys.argv[1] in ('planner', 'controller'):
        node(sys.argv[1])
    else:
        sys.exit(launcher())
