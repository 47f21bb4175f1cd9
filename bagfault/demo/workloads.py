"""The benchmark's workloads: deterministic synthetic bags (zstd-chunked MCAP, ros2 profile) and the scenarios
bench/run.py times on them (the tests run the same ones).

sensor-heavy: IMU 200 Hz, odometry 50 Hz, TF 100 Hz, joint states 100 Hz,
LaserScan 20 Hz (1081 ranges), PointCloud2 10 Hz (32768 points), Image 10 Hz
(640x480 rgb8). message-heavy: four IMU topics at 1 kHz each.

Messages are serialized once per topic from bagfault.demo.synthetic and
then re-stamped in place, so generating a 600 s bag takes seconds, not
minutes; every message still differs (stamp, and values that change).
"""

from __future__ import annotations

import math
import struct
from pathlib import Path
from typing import Any

import numpy as np
from mcap.writer import CompressionType, Writer

from bagfault.demo import synthetic
from bagfault.demo.synthetic import Stream
from bagfault.io.qos import DEFAULT_QOS as QOS  # channels as ros2 bag record writes them
from bagfault.units import NS

SENSOR_HEAVY = (
    Stream('/imu', 'sensor_msgs/msg/Imu', 200.0),
    Stream('/odom', 'nav_msgs/msg/Odometry', 50.0),
    Stream('/tf', 'tf2_msgs/msg/TFMessage', 100.0),
    Stream('/joint_states', 'sensor_msgs/msg/JointState', 100.0),
    Stream('/scan', 'sensor_msgs/msg/LaserScan', 20.0),
    Stream('/points', 'sensor_msgs/msg/PointCloud2', 10.0),
    Stream('/camera/image_raw', 'sensor_msgs/msg/Image', 10.0),
)
MESSAGE_HEAVY = tuple(Stream(f'/imu{i}', 'sensor_msgs/msg/Imu', 1000.0) for i in range(4))
KINDS = {'sensor-heavy': SENSOR_HEAVY, 'message-heavy': MESSAGE_HEAVY}


def _template(ts: Any, topic: Stream) -> bytes:
    """One serialized message of the topic (stamp patched per message later)."""
    builders = {
        'sensor_msgs/msg/LaserScan': lambda: synthetic.laser_scan(ts, 0, 0.0, beams=1081),
        'sensor_msgs/msg/PointCloud2': lambda: synthetic.point_cloud(ts, 0, 0.0, count=32768),
        'sensor_msgs/msg/Image': lambda: synthetic.raw_image(ts, 0, 0.0, width=640, height=480),
    }
    message = builders.get(topic.msgtype, lambda: synthetic.BUILDERS[topic.msgtype](ts, 0, 0.0))()
    return bytes(ts.serialize_cdr(message, topic.msgtype))


def _vary(template: bytearray, topic: Stream, k: int, time: int) -> bytes:
    """Patch the header stamp (bytes 4..12 when the type has a header) and a changing value."""
    if topic.msgtype != 'tf2_msgs/msg/TFMessage':
        struct.pack_into('<iI', template, 4, time // NS, time % NS)
    if topic.msgtype == 'sensor_msgs/msg/Imu':
        # linear_acceleration.z is the last float64 before the last covariance (9 doubles)
        struct.pack_into('<d', template, len(template) - 9 * 8 - 8, 9.81 + 0.01 * math.sin(k / 50.0))
    return bytes(template)


def write_bag(path: Path, kind: str, seconds: float) -> int:
    """Write one benchmark bag; return its message count."""
    ts = synthetic.store()
    topics = KINDS[kind]
    templates = {t.topic: bytearray(_template(ts, t)) for t in topics}
    periods = {t.topic: round(NS / t.rate_hz) for t in topics}
    counts = {t.topic: math.ceil(seconds * t.rate_hz - 1e-9) for t in topics}
    start = synthetic.DEFAULT_START
    # merge the per-topic time grids in time order (topic order on ties)
    times = np.concatenate([start + np.arange(counts[t.topic], dtype=np.int64) * periods[t.topic] for t in topics])
    owners = np.concatenate([np.full(counts[t.topic], i, dtype=np.int64) for i, t in enumerate(topics)])
    indexes = np.concatenate([np.arange(counts[t.topic], dtype=np.int64) for t in topics])
    order = np.lexsort((owners, times))
    with path.open('wb') as stream:
        writer = Writer(stream, compression=CompressionType.ZSTD)
        writer.start(profile='ros2', library='bagfault-bench')
        channels = []
        for topic in topics:
            text, _ = ts.generate_msgdef(topic.msgtype, ros_version=2)
            schema = writer.register_schema(topic.msgtype, 'ros2msg', text.encode())
            channels.append(writer.register_channel(topic.topic, 'cdr', schema, {'offered_qos_profiles': QOS}))
        for position in order.tolist():
            time, owner, k = int(times[position]), int(owners[position]), int(indexes[position])
            topic = topics[owner]
            writer.add_message(channels[owner], time, _vary(templates[topic.topic], topic, k, time), time)
        writer.finish()  # type: ignore[no-untyped-call]
    return len(order)


def scenario(kind: str, case: str) -> str:
    """The four bagfault scenarios for a bag kind (in-place injectors on its topics)."""
    topics = KINDS[kind]
    imus = [t.topic for t in topics if t.msgtype == 'sensor_msgs/msg/Imu']
    lines = ['injectors:']
    faults = ['faults:']
    if case in ('a', 'b', 'w'):
        for number, topic in enumerate(imus):
            lines.append(f'  - {{id: imu{number}, type: imu, input_topic: {topic}, output_topic: {topic}}}')
            config = ('{angular_velocity_z_bias: 0.05, angular_velocity_z_noise_stddev: 0.02, '
                      'linear_acceleration_z_bias: 0.2, linear_acceleration_z_noise_stddev: 0.05}')
            schedule = {'a': 'start: 100000.0', 'b': 'active_on_startup: true', 'w': 'start: 100.0, duration: 10.0'}[
                case]
            faults.append(f'  - {{id: bias{number}, injector_id: imu{number}, {schedule}, config: {config}}}')
    if case == 'c':
        lines.append('  - {id: pc, type: pointcloud2, input_topic: /points, output_topic: /points}')
        faults.append('  - {id: pc_noise, injector_id: pc, active_on_startup: true, '
                      'config: {xyz_noise_stddev: 0.02, dropout_probability: 0.1}}')
    if case == 'd':
        for number, stream in enumerate(topics):
            lines.append(f'  - {{id: s{number}, type: topic, input_topic: {stream.topic}, '
                         f'output_topic: {stream.topic}}}')
            faults.append(f'  - {{id: f{number}, injector_id: s{number}, active_on_startup: true, '
                          'config: {drop_probability: 0.2, delay_ms: 50}}')
    return '\n'.join(lines + faults) + '\n'


CASES = {
    'sensor-heavy': ['a', 'c', 'd'],
    'message-heavy': ['a', 'b', 'd'],
}
