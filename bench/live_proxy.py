"""Live proxy benchmark: throughput, added latency, losses and CPU of `bagfault proxy` against a bare relay.

    python bench/live_proxy.py [--rates 1000 2000] [--seconds 10] [--depth 10] [--json F]

For each rate and each forwarder (`bagfault proxy`, and a bare rclpy relay:
one raw subscription republished as is, `rclpy.spin`), three processes on a
private ROS domain over the loopback profile: a publisher of sensor_msgs/Imu
at the rate on /bench/imu_raw (header.stamp = send time), the forwarder to
/bench/imu (the proxy with faults defined, none active: the raw pass-through
path; both with the subscription depth --depth, the anchor's default 10) and
a subscriber on both topics that measures receive time - stamp. The direct
topic gives the DDS baseline. The forwarder's CPU is read from /proc over
the run. Not a test: numbers depend on the machine.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import subprocess
import sys
import tempfile
import time
from datetime import date
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
SCENARIO = """
injector: {id: imu, type: imu, input_topic: /bench/imu_raw, output_topic: /bench/imu, qos_depth: %d}
faults:
  - {id: bias, injector_id: imu, config: {angular_velocity_z_bias: 0.05}}
"""


def publisher(rate: float, seconds: float) -> None:
    """Publish Imu at `rate` with the send time in the stamp; print how many were sent. Serialized once and
    stamped in place, sent by an events executor, so the publisher is never what limits the rate."""
    import struct

    import rclpy
    from rclpy.qos import QoSProfile
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import Imu

    rclpy.init()
    node = rclpy.create_node('bench_publisher')
    pub = node.create_publisher(Imu, '/bench/imu_raw', QoSProfile(depth=100))
    time.sleep(2.0)  # discovery
    data = bytearray(serialize_message(Imu()))
    period = 1.0 / rate
    start = time.monotonic()
    sent = 0
    while time.monotonic() - start < seconds:
        struct.pack_into('<iI', data, 4, *divmod(time.time_ns(), 1_000_000_000))  # header.stamp after the CDR head
        pub.publish(bytes(data))
        sent += 1
        delay = start + sent * period - time.monotonic()
        if delay > 0:
            time.sleep(delay)
    print(json.dumps({'sent': sent, 'seconds': time.monotonic() - start}), flush=True)
    time.sleep(1.0)
    rclpy.shutdown()


def subscriber(seconds: float) -> None:
    """Receive both topics raw (stamp read from the bytes) on an events executor; print latencies (ms)."""
    import struct

    import rclpy
    from rclpy.experimental import EventsExecutor
    from rclpy.qos import QoSProfile
    from sensor_msgs.msg import Imu

    rclpy.init()
    node = rclpy.create_node('bench_subscriber')
    latencies: dict[str, list[float]] = {'/bench/imu_raw': [], '/bench/imu': []}
    stamp = struct.Struct('<iI')

    def receiver(topic: str):
        values = latencies[topic]

        def received(data: bytes) -> None:
            sec, nanosec = stamp.unpack_from(data, 4)
            values.append((time.time_ns() - sec * 1_000_000_000 - nanosec) / 1e6)
        return received

    for topic in latencies:
        node.create_subscription(Imu, topic, receiver(topic), QoSProfile(depth=1000), raw=True)
    executor = EventsExecutor()
    executor.add_node(node)
    print('ready', file=sys.stderr, flush=True)
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        executor.spin_once(timeout_sec=0.05)
    print(json.dumps(latencies), flush=True)
    executor.shutdown()
    rclpy.shutdown()


def relay(depth: int) -> None:
    """The bare relay: what a hand-written rclpy forwarder does."""
    import rclpy
    from rclpy.qos import QoSProfile
    from sensor_msgs.msg import Imu

    rclpy.init()
    node = rclpy.create_node('bench_relay')
    out = node.create_publisher(Imu, '/bench/imu', QoSProfile(depth=depth))
    node.create_subscription(Imu, '/bench/imu_raw', out.publish, QoSProfile(depth=depth), raw=True)
    print('ready', file=sys.stderr, flush=True)
    with contextlib.suppress(KeyboardInterrupt, rclpy.executors.ExternalShutdownException):
        rclpy.spin(node)
    rclpy.try_shutdown()


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process so far."""
    fields = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def measure(forwarder: str, rate: float, seconds: float, depth: int, env: dict[str, str], tmp: Path) -> dict:
    """One run of one forwarder at one rate."""
    if forwarder == 'proxy':
        scenario = tmp / 'bench.yaml'
        scenario.write_text(SCENARIO % depth)
        command = [sys.executable, '-m', 'bagfault.cli', 'proxy', str(scenario)]
        ready = 'bagfault proxy ready'
    else:
        command = [sys.executable, __file__, '--role', 'relay', '--depth', str(depth)]
        ready = 'ready'
    process = subprocess.Popen(command, env=env, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True)
    while ready not in (process.stderr.readline() or ready):
        pass
    listen = seconds + 6.0
    sub = subprocess.Popen([sys.executable, __file__, '--role', 'subscriber', '--seconds', str(listen)], env=env,
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    sub.stderr.readline()
    cpu_before, wall_before = cpu_seconds(process.pid), time.monotonic()
    pub = subprocess.run([sys.executable, __file__, '--role', 'publisher', '--rate', str(rate),
                          '--seconds', str(seconds)], env=env, capture_output=True, text=True, check=True)
    cpu = (cpu_seconds(process.pid) - cpu_before) / (time.monotonic() - wall_before)
    out, _ = sub.communicate(timeout=listen + 30)
    process.send_signal(2)
    process.communicate(timeout=30)
    sent = json.loads(pub.stdout.splitlines()[-1])
    latencies = json.loads(out.splitlines()[-1])
    direct, forwarded = latencies['/bench/imu_raw'], latencies['/bench/imu']
    return {
        'forwarder': forwarder, 'rate_hz': rate, 'depth': depth, 'sent': sent['sent'],
        'received_direct': len(direct), 'received_forwarded': len(forwarded),
        'lost_forwarded': sent['sent'] - len(forwarded), 'lost_direct': sent['sent'] - len(direct),
        'cpu_share': round(cpu, 3),
        'latency_ms': {name: {'p50': percentile(values, 0.5), 'p95': percentile(values, 0.95),
                              'p99': percentile(values, 0.99)}
                       for name, values in (('direct', direct), ('forwarded', forwarded))},
    }


def percentile(values: list[float], share: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(share * len(ordered)))] if ordered else float('nan')


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--rates', type=float, nargs='+', default=[1000.0, 2000.0])
    parser.add_argument('--rate', type=float, default=1000.0, help=argparse.SUPPRESS)
    parser.add_argument('--seconds', type=float, default=10.0)
    parser.add_argument('--depth', type=int, default=10)
    parser.add_argument('--forwarders', nargs='+', default=['relay', 'proxy'])
    parser.add_argument('--load', type=int, default=0, help='processes spinning on the CPU meanwhile (a busy machine)')
    parser.add_argument('--json', type=Path, default=None)
    parser.add_argument('--role', choices=['publisher', 'subscriber', 'relay'], help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.role == 'publisher':
        publisher(args.rate, args.seconds)
        return 0
    if args.role == 'subscriber':
        subscriber(args.seconds)
        return 0
    if args.role == 'relay':
        relay(args.depth)
        return 0

    sys.path.insert(0, str(ROOT))
    import bagfault.live

    env = {**os.environ, 'ROS_DOMAIN_ID': os.environ.get('BENCH_DOMAIN_ID', '77'),
           'FASTRTPS_DEFAULT_PROFILES_FILE': str(bagfault.live.LOOPBACK_PROFILE)}
    results = []
    hogs = [subprocess.Popen([sys.executable, '-c', 'while True: pass']) for _ in range(args.load)]
    with tempfile.TemporaryDirectory() as tmp:
        for rate in args.rates:
            for forwarder in args.forwarders:
                row = measure(forwarder, rate, args.seconds, args.depth, env, Path(tmp))
                row['load'] = args.load
                results.append(row)
                fwd = row['latency_ms']['forwarded']
                print(f'{forwarder:<6} {rate:>6.0f} Hz depth {args.depth} load {args.load}: sent {row["sent"]}, lost '
                      f'{row["lost_forwarded"]} ({100 * row["lost_forwarded"] / row["sent"]:.2f} %), '
                      f'latency p50 {fwd["p50"]:.3f} p99 {fwd["p99"]:.3f} ms, CPU {100 * row["cpu_share"]:.0f} %',
                      flush=True)
    for hog in hogs:
        hog.kill()
    report = {'date': date.today().isoformat(), 'command': 'python bench/live_proxy.py ' + ' '.join(sys.argv[1:]),
              'seconds': args.seconds, 'results': results}
    from bench.run import RESULTS, save

    save(report, args.json or RESULTS / f'live-proxy-{report["date"]}.json')
    return 0


if __name__ == '__main__':
    sys.exit(main())
