"""Live proxy benchmark: throughput, added latency and losses of `bagfault proxy` at 1 kHz.

    python bench/live_proxy.py [--rate 1000] [--seconds 10] [--json bench/results/live-proxy.json]

Three processes on a private ROS domain over the loopback profile: a
publisher of sensor_msgs/Imu at --rate on /bench/imu_raw (header.stamp = send
time), `bagfault proxy` (imu injector to /bench/imu, faults defined, none
active: the raw pass-through path) and a subscriber on both topics that
measures receive time - stamp. The direct topic gives the DDS baseline; the
difference is what the proxy adds. Not a test: numbers depend on the machine.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from datetime import date
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
SCENARIO = """
injector: {id: imu, type: imu, input_topic: /bench/imu_raw, output_topic: /bench/imu, qos_depth: 100}
faults:
  - {id: bias, injector_id: imu, config: {angular_velocity_z_bias: 0.05}}
"""


def publisher(rate: float, seconds: float) -> None:
    """Publish Imu at `rate` with the send time in the stamp; print how many were sent."""
    import rclpy
    from rclpy.qos import QoSProfile
    from sensor_msgs.msg import Imu

    rclpy.init()
    node = rclpy.create_node('bench_publisher')
    pub = node.create_publisher(Imu, '/bench/imu_raw', QoSProfile(depth=100))
    time.sleep(2.0)  # discovery
    message = Imu()
    period = 1.0 / rate
    start = time.monotonic()
    sent = 0
    while time.monotonic() - start < seconds:
        now = time.time_ns()
        message.header.stamp.sec, message.header.stamp.nanosec = divmod(now, 1_000_000_000)
        pub.publish(message)
        sent += 1
        delay = start + sent * period - time.monotonic()
        if delay > 0:
            time.sleep(delay)
    print(json.dumps({'sent': sent, 'seconds': time.monotonic() - start}), flush=True)
    time.sleep(1.0)
    rclpy.shutdown()


def subscriber(seconds: float) -> None:
    """Receive both topics; print latencies (ms) per topic."""
    import rclpy
    from rclpy.qos import QoSProfile
    from sensor_msgs.msg import Imu

    rclpy.init()
    node = rclpy.create_node('bench_subscriber')
    latencies: dict[str, list[float]] = {'/bench/imu_raw': [], '/bench/imu': []}

    def receiver(topic: str):
        def received(message: Imu) -> None:
            stamp = message.header.stamp.sec * 1_000_000_000 + message.header.stamp.nanosec
            latencies[topic].append((time.time_ns() - stamp) / 1e6)
        return received

    for topic in latencies:
        node.create_subscription(Imu, topic, receiver(topic), QoSProfile(depth=1000))
    print('ready', file=sys.stderr, flush=True)
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.05)
    print(json.dumps(latencies), flush=True)
    rclpy.shutdown()


def percentile(values: list[float], share: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(share * len(ordered)))] if ordered else float('nan')


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--rate', type=float, default=1000.0)
    parser.add_argument('--seconds', type=float, default=10.0)
    parser.add_argument('--json', type=Path, default=None)
    parser.add_argument('--role', choices=['publisher', 'subscriber'], help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.role == 'publisher':
        publisher(args.rate, args.seconds)
        return 0
    if args.role == 'subscriber':
        subscriber(args.seconds)
        return 0

    sys.path.insert(0, str(ROOT))
    import bagfault.live

    env = {**os.environ, 'ROS_DOMAIN_ID': os.environ.get('BENCH_DOMAIN_ID', '77'),
           'FASTRTPS_DEFAULT_PROFILES_FILE': str(bagfault.live.LOOPBACK_PROFILE)}
    with tempfile.TemporaryDirectory() as tmp:
        scenario = Path(tmp) / 'bench.yaml'
        scenario.write_text(SCENARIO)
        proxy = subprocess.Popen([sys.executable, '-m', 'bagfault.cli', 'proxy', str(scenario)], env=env, cwd=ROOT,
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        listen = args.seconds + 6.0
        sub = subprocess.Popen([sys.executable, __file__, '--role', 'subscriber', '--seconds', str(listen)], env=env,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        sub.stderr.readline()
        pub = subprocess.run([sys.executable, __file__, '--role', 'publisher', '--rate', str(args.rate),
                              '--seconds', str(args.seconds)], env=env, capture_output=True, text=True, check=True)
        out, _ = sub.communicate(timeout=listen + 30)
        proxy.send_signal(2)
        proxy_out, _ = proxy.communicate(timeout=30)
    sent = json.loads(pub.stdout.splitlines()[-1])
    latencies = json.loads(out.splitlines()[-1])
    direct, proxied = latencies['/bench/imu_raw'], latencies['/bench/imu']
    report = {
        'date': date.today().isoformat(), 'rate_hz': args.rate, 'seconds': args.seconds, 'sent': sent['sent'],
        'publish_rate_hz': sent['sent'] / sent['seconds'],
        'received_direct': len(direct), 'received_through_proxy': len(proxied),
        'lost_through_proxy': sent['sent'] - len(proxied), 'lost_direct': sent['sent'] - len(direct),
        'proxy_throughput_msg_s': len(proxied) / sent['seconds'],
        'latency_ms': {name: {'p50': percentile(values, 0.5), 'p95': percentile(values, 0.95),
                              'p99': percentile(values, 0.99), 'mean': statistics.fmean(values) if values else None}
                       for name, values in (('direct', direct), ('through_proxy', proxied))},
        'proxy_summary': proxy_out.strip().splitlines()[-1] if proxy_out.strip() else '',
    }
    report['added_latency_ms'] = {k: report['latency_ms']['through_proxy'][k] - report['latency_ms']['direct'][k]
                                  for k in ('p50', 'p95', 'p99')}
    print(f'sent {report["sent"]} at {report["publish_rate_hz"]:.0f} Hz; received direct {len(direct)}, '
          f'through the proxy {len(proxied)} (lost {report["lost_through_proxy"]})')
    for name in ('direct', 'through_proxy'):
        entry = report['latency_ms'][name]
        print(f'  {name:<14} latency p50 {entry["p50"]:.3f} ms  p95 {entry["p95"]:.3f} ms  p99 {entry["p99"]:.3f} ms')
    added = report['added_latency_ms']
    print(f'  added by the proxy: p50 {added["p50"]:.3f} ms  p95 {added["p95"]:.3f} ms  p99 {added["p99"]:.3f} ms')
    from bench.run import RESULTS, save

    save(report, args.json or RESULTS / f'live-proxy-{report["date"]}.json')
    return 0


if __name__ == '__main__':
    sys.exit(main())
