"""Closed-loop benchmark: what `bagfault test` delivers to a system under test, and how well its clock agrees.

    python bench/closed_loop.py [--seconds 30] [--rates 1 4] [--json bench/results/closed-loop.json]

A synthetic bag (/imu 100 Hz, /odom 50 Hz, /scan 10 Hz with 360 beams) is
played by `bagfault test` into an echo system (this file, `--echo`): for
every message it receives it publishes a copy on /echo/<topic> whose
header.frame_id holds its own ROS time at receipt (sim time from /clock).
From the recording alone: messages played vs received by the system (echoed
back), the system's clock error (its ROS time at receipt - the message's
bag time) and the loop time (the echo's arrival on bagfault's bag-time axis
- the message's bag time). Not a test: numbers depend on the machine.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import statistics
import subprocess
import sys
import tempfile
from datetime import date
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
NS = 1_000_000_000
STREAMS = [('/imu', 'sensor_msgs/msg/Imu', 100.0), ('/odom', 'nav_msgs/msg/Odometry', 50.0),
           ('/scan', 'sensor_msgs/msg/LaserScan', 10.0)]
SCENARIO = """
name: closed_loop_bench
injector: {id: imu, type: imu, input_topic: /imu, output_topic: /imu}
faults:
  - {id: bias, injector_id: imu, start: 5.0, duration: 5.0, config: {angular_velocity_z_bias: 0.05}}
system_under_test:
  command: ['{python}', '%s', '--echo']
  ready: [{subscribes: played}]
  record: all
"""


def echo() -> None:
    """The system under test: every message back on /echo/<topic>, frame_id = its ROS time at receipt."""
    import rclpy
    from nav_msgs.msg import Odometry
    from rclpy.node import Node
    from rclpy.utilities import remove_ros_args
    from sensor_msgs.msg import Imu, LaserScan

    rclpy.init(args=sys.argv)
    remove_ros_args(sys.argv)
    node = Node('echo_system')
    for topic, kind in (('/imu', Imu), ('/odom', Odometry), ('/scan', LaserScan)):
        publisher = node.create_publisher(kind, f'/echo{topic}', 100)

        def back(message: object, publisher: object = publisher) -> None:
            message.header.frame_id = str(node.get_clock().now().nanoseconds)  # type: ignore[attr-defined]
            publisher.publish(message)  # type: ignore[attr-defined]

        node.create_subscription(kind, topic, back, 100)
    with contextlib.suppress(KeyboardInterrupt, rclpy.executors.ExternalShutdownException):
        rclpy.spin(node)
    rclpy.try_shutdown()


def measure(recording: Path) -> dict[str, object]:
    """Counts, clock error and loop time from the recording."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    played: dict[str, int] = {}
    echoed: dict[str, int] = {}
    clock_ms: list[float] = []
    loop_ms: list[float] = []
    with recording.open('rb') as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for _, channel, message, value in reader.iter_decoded_messages():
            topic = channel.topic
            if topic in ('/imu', '/odom', '/scan'):
                played[topic] = played.get(topic, 0) + 1
            elif topic.startswith('/echo/'):
                echoed[topic[5:]] = echoed.get(topic[5:], 0) + 1
                sent = value.header.stamp.sec * NS + value.header.stamp.nanosec  # the bag time it was played at
                clock_ms.append((int(value.header.frame_id) - sent) / 1e6)
                loop_ms.append((message.log_time - sent) / 1e6)

    def spread(values: list[float]) -> dict[str, float]:
        ordered = sorted(values)
        return {'p50': round(statistics.median(ordered), 2),
                'p99': round(ordered[int(0.99 * (len(ordered) - 1))], 2),
                'min': round(ordered[0], 2), 'max': round(ordered[-1], 2)}

    return {'played': played, 'received_by_system': echoed,
            'lost': sum(played.values()) - sum(echoed.values()),
            'system_clock_error_ms': spread(clock_ms), 'loop_ms': spread(loop_ms)}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument('--echo', action='store_true', help=argparse.SUPPRESS)
    parser.add_argument('--seconds', type=float, default=30.0)
    parser.add_argument('--rates', type=float, nargs='+', default=[1.0, 4.0])
    parser.add_argument('--json', type=Path, default=None)
    args, _ = parser.parse_known_args()
    if args.echo:
        echo()
        return
    sys.path.insert(0, str(ROOT))
    from bagfault.demo import synthetic

    results = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        bag = folder / 'bench.mcap'
        synthetic.write_mcap(bag, synthetic.messages([synthetic.Stream(*s) for s in STREAMS], args.seconds))
        scenario = folder / 'bench.yaml'
        scenario.write_text(SCENARIO % Path(__file__).resolve())
        for rate in args.rates:
            out = folder / f'loop-{rate:g}.mcap'
            command = [sys.executable, '-m', 'bagfault.cli', 'test', str(scenario), str(bag), '-o', str(out),
                       '--rate', str(rate)]
            done = subprocess.run(command, capture_output=True, text=True, check=False, cwd=ROOT)
            if done.returncode != 0:
                raise SystemExit(f'bagfault test failed ({done.returncode}):\n{done.stdout}\n{done.stderr}')
            results.append({'rate': rate, 'seconds': args.seconds, **measure(out)})
            print(json.dumps(results[-1]))
    record = {'date': date.today().isoformat(), 'command': 'python bench/closed_loop.py ' + ' '.join(sys.argv[1:]),
              'results': results}
    if args.json is not None:
        args.json.write_text(json.dumps(record, indent=1) + '\n')


if __name__ == '__main__':
    main()
