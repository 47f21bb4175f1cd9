"""Campaign test data: IMU bags whose yaw rate is a known constant, and a detection scenario on them.

The fault manager condition reports FAILED while angular_velocity.z > 0.1 and
confirms after 3 reports (confirmation_threshold -3), so with a bag constant
at `z`, a bias `b` is detected exactly when z + b > 0.1, 40 ms after the fault
starts (the 3rd message at 50 Hz). Everything below is derived from that.
"""

from __future__ import annotations

import textwrap
from pathlib import Path
from typing import Any

from mcap.writer import Writer
from rosbags.typesys import Stores, get_typestore

START = 1_700_000_000_000_000_000
RATE_HZ = 50
SCENARIO = """\
name: drift_detection
injectors:
  - {id: imu, type: imu, input_topic: /imu, output_topic: /imu_out}
faults:
  - {id: bias, injector_id: imu, start: 1.0, duration: 2.0, config: {angular_velocity_z_bias: %(bias)s}}
fault_manager:
  confirmation_threshold: -3
  conditions:
    - {topic: /imu_out, when: {field: angular_velocity.z, above: 0.1}, code: IMU_DRIFT}
assertions:
  - {id: drift_detected, type: fault_status, code: IMU_DRIFT, status: CONFIRMED, after: bias, within: 1.0}
"""


def write_imu_bag(path: Path, z: float, seconds: float = 4.0, topic: str = '/imu') -> Path:
    """An MCAP of sensor_msgs/Imu at 50 Hz on `topic` with angular_velocity.z == z, written with mcap and rosbags
    only."""
    ts = get_typestore(Stores.ROS2_JAZZY)
    imu, header, time_, vec, quat = (ts.types[n] for n in (
        'sensor_msgs/msg/Imu', 'std_msgs/msg/Header', 'builtin_interfaces/msg/Time', 'geometry_msgs/msg/Vector3',
        'geometry_msgs/msg/Quaternion'))
    import numpy as np
    text, _ = ts.generate_msgdef('sensor_msgs/msg/Imu', ros_version=2)
    with path.open('wb') as stream:
        writer = Writer(stream)
        writer.start(profile='ros2', library='tests')
        schema = writer.register_schema('sensor_msgs/msg/Imu', 'ros2msg', text.encode())
        channel = writer.register_channel(topic, 'cdr', schema, {})
        for k in range(int(seconds * RATE_HZ)):
            stamp = START + k * 1_000_000_000 // RATE_HZ
            message = imu(header(time_(*divmod(stamp, 1_000_000_000)), 'imu'), quat(0.0, 0.0, 0.0, 1.0),
                          np.zeros(9), vec(0.0, 0.0, z), np.zeros(9), vec(0.0, 0.0, 9.81), np.zeros(9))
            writer.add_message(channel, stamp, bytes(ts.serialize_cdr(message, 'sensor_msgs/msg/Imu')), stamp)
        writer.finish()
    return path


def campaign_file(folder: Path, body: str, name: str = 'campaign.yaml') -> Path:
    """A campaign file in `folder` (dedented)."""
    path = folder / name
    path.write_text(textwrap.dedent(body))
    return path


class InterruptAfter:
    """A progress display that presses Ctrl-C after `count` finished jobs."""

    def __init__(self, count: int) -> None:
        from bagfault.progress import JobProgress

        self.bar = JobProgress(enabled=False)
        self.count = count

    def __getattr__(self, name: str) -> Any:
        return getattr(self.bar, name)

    def finished(self, status: str) -> None:
        self.bar.finished(status)
        if self.bar.done >= self.count:
            raise KeyboardInterrupt
