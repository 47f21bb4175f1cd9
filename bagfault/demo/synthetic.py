"""Deterministic synthetic robot streams with known values, and a plain MCAP writer.

The demo bag, the test fixtures and the benchmark bags come from here. Every
value is a closed-form function of time, so tests can derive expected
outputs independently. Bags are written with the `mcap` library directly
(not with bagfault's own sink) so bagfault is never tested against itself.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from mcap.writer import CompressionType, Writer
from rosbags.typesys import Stores, get_typestore

from bagfault.units import NS

if TYPE_CHECKING:
    from collections.abc import Callable, Iterable, Iterator

    from rosbags.typesys.store import Typestore

DEFAULT_START = 1_700_000_000 * NS
SCAN_BEAMS = 360
JOINTS = ('front_left_wheel', 'front_right_wheel', 'rear_left_wheel', 'rear_right_wheel')


@dataclass(frozen=True)
class Stream:
    """One topic of a synthetic bag."""

    topic: str
    msgtype: str
    rate_hz: float


def store() -> Typestore:
    """The typestore used to build synthetic messages (Humble)."""
    return get_typestore(Stores.ROS2_HUMBLE)


def _header(ts: Typestore, time: int, frame: str) -> Any:
    Time = ts.types['builtin_interfaces/msg/Time']
    return ts.types['std_msgs/msg/Header'](stamp=Time(sec=time // NS, nanosec=time % NS), frame_id=frame)


def yaw_quaternion(ts: Typestore, yaw: float) -> Any:
    """geometry_msgs Quaternion of a pure yaw."""
    return ts.types['geometry_msgs/msg/Quaternion'](x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))


def odom_pose(t: float) -> tuple[float, float, float]:
    """x, y (m) and yaw (rad) of the synthetic robot at t seconds."""
    return 0.1 * t, 0.05 * t, math.atan2(math.sin(0.1 * t), math.cos(0.1 * t))


def odometry(ts: Typestore, time: int, t: float, frame: str = 'odom') -> Any:
    """Odometry with diagonal covariance 0.01 and zero off-diagonal."""
    x, y, yaw = odom_pose(t)
    T = ts.types
    cov = np.zeros(36)
    cov[::7] = 0.01
    pose = T['geometry_msgs/msg/PoseWithCovariance'](
        pose=T['geometry_msgs/msg/Pose'](position=T['geometry_msgs/msg/Point'](x=x, y=y, z=0.0),
                                         orientation=yaw_quaternion(ts, yaw)),
        covariance=cov.copy(),
    )
    vec = T['geometry_msgs/msg/Vector3']
    twist = T['geometry_msgs/msg/TwistWithCovariance'](
        twist=T['geometry_msgs/msg/Twist'](linear=vec(x=0.1, y=0.05, z=0.0), angular=vec(x=0.0, y=0.0, z=0.1)),
        covariance=cov.copy(),
    )
    return T['nav_msgs/msg/Odometry'](header=_header(ts, time, frame), child_frame_id='base_link', pose=pose,
                                      twist=twist)


def scan_ranges(t: float, beams: int = SCAN_BEAMS) -> np.ndarray:
    """float32 ranges: 2 m + 0.5 m * sin(angle + 0.1 t); every 37th beam has no return (inf)."""
    angles = -math.pi + np.arange(beams) * (2 * math.pi / beams)
    ranges = (2.0 + 0.5 * np.sin(angles + 0.1 * t)).astype(np.float32)
    ranges[::37] = np.inf
    return ranges  # type: ignore[no-any-return]


def laser_scan(ts: Typestore, time: int, t: float, beams: int = SCAN_BEAMS) -> Any:
    """A full-circle LaserScan from -pi, range limits [0.1, 10] m."""
    return ts.types['sensor_msgs/msg/LaserScan'](
        header=_header(ts, time, 'laser'),
        angle_min=-math.pi,
        angle_max=math.pi - 2 * math.pi / beams,
        angle_increment=2 * math.pi / beams,
        time_increment=0.0,
        scan_time=0.1,
        range_min=0.1,
        range_max=10.0,
        ranges=scan_ranges(t, beams),
        intensities=np.full(beams, 100.0, dtype=np.float32),
    )


def joint_velocities(t: float) -> np.ndarray:
    """Wheel speeds (rad/s): 1.0, 1.1, 1.2, 1.3 plus 0.01 t."""
    return np.array([1.0, 1.1, 1.2, 1.3]) + 0.01 * t


def joint_state(ts: Typestore, time: int, t: float) -> Any:
    """JointState of four wheels."""
    return ts.types['sensor_msgs/msg/JointState'](
        header=_header(ts, time, ''),
        name=list(JOINTS),
        position=np.array([0.5 * t] * 4),
        velocity=joint_velocities(t),
        effort=np.zeros(4),
    )


def imu_values(t: float) -> tuple[float, tuple[float, float, float]]:
    """angular_velocity.z (rad/s) and linear_acceleration (m/s^2) at t."""
    return 0.1, (0.01 * math.sin(t), 0.02 * math.cos(t), 9.81)


def imu(ts: Typestore, time: int, t: float, frame: str = 'imu_link') -> Any:
    """Imu with fixed covariances."""
    wz, (ax, ay, az) = imu_values(t)
    T = ts.types
    vec = T['geometry_msgs/msg/Vector3']
    cov = np.zeros(9)
    cov[::4] = 0.001
    return T['sensor_msgs/msg/Imu'](
        header=_header(ts, time, frame),
        orientation=yaw_quaternion(ts, 0.1 * t),
        orientation_covariance=cov.copy(),
        angular_velocity=vec(x=0.0, y=0.0, z=wz),
        angular_velocity_covariance=cov.copy(),
        linear_acceleration=vec(x=ax, y=ay, z=az),
        linear_acceleration_covariance=cov.copy(),
    )


def tf_message(ts: Typestore, time: int, t: float) -> Any:
    """odom -> base_link (following the odometry) and base_link -> laser (fixed)."""
    T = ts.types
    x, y, yaw = odom_pose(t)
    vec = T['geometry_msgs/msg/Vector3']
    odom_base = T['geometry_msgs/msg/TransformStamped'](
        header=_header(ts, time, 'odom'),
        child_frame_id='base_link',
        transform=T['geometry_msgs/msg/Transform'](translation=vec(x=x, y=y, z=0.0),
                                                   rotation=yaw_quaternion(ts, yaw)),
    )
    base_laser = T['geometry_msgs/msg/TransformStamped'](
        header=_header(ts, time, 'base_link'),
        child_frame_id='laser',
        transform=T['geometry_msgs/msg/Transform'](translation=vec(x=0.2, y=0.0, z=0.3),
                                                   rotation=yaw_quaternion(ts, 0.0)),
    )
    return T['tf2_msgs/msg/TFMessage'](transforms=[odom_base, base_laser])


def battery_values(t: float) -> tuple[float, float]:
    """voltage (V) and percentage (0..1) at t seconds."""
    return 12.6 - 0.01 * t, 0.9 - 0.001 * t


def battery_state(ts: Typestore, time: int, t: float) -> Any:
    """BatteryState of a slowly discharging pack."""
    voltage, percentage = battery_values(t)
    return ts.types['sensor_msgs/msg/BatteryState'](
        header=_header(ts, time, 'battery'), voltage=voltage, temperature=25.0, current=-2.0, charge=math.nan,
        capacity=math.nan, design_capacity=10.0, percentage=percentage, power_supply_status=2,
        power_supply_health=1, power_supply_technology=3, present=True,
        cell_voltage=np.full(3, voltage / 3, dtype=np.float32), cell_temperature=np.full(3, 25.0, dtype=np.float32),
        location='base', serial_number='synthetic-1',
    )


def cloud_points(t: float, count: int) -> np.ndarray:
    """count x 4 float32 (x, y, z, intensity): a ring of points around the sensor, 1..10 m."""
    angle = np.linspace(-math.pi, math.pi, count, endpoint=False, dtype=np.float64)
    distance = 1.0 + (np.arange(count) % 90) / 10.0
    points = np.empty((count, 4), dtype=np.float32)
    points[:, 0] = distance * np.cos(angle + 0.01 * t)
    points[:, 1] = distance * np.sin(angle + 0.01 * t)
    points[:, 2] = (np.arange(count) % 16) * 0.1 - 0.8
    points[:, 3] = 100.0
    return points


def point_cloud(ts: Typestore, time: int, t: float, count: int = 2000) -> Any:
    """Unorganized PointCloud2 with float32 x, y, z, intensity (point_step 16)."""
    T = ts.types
    field = T['sensor_msgs/msg/PointField']
    fields = [field(name=n, offset=4 * i, datatype=7, count=1) for i, n in enumerate(('x', 'y', 'z', 'intensity'))]
    data = cloud_points(t, count).tobytes()
    return T['sensor_msgs/msg/PointCloud2'](
        header=_header(ts, time, 'lidar'), height=1, width=count, fields=fields, is_bigendian=False,
        point_step=16, row_step=16 * count, data=np.frombuffer(data, dtype=np.uint8), is_dense=True,
    )


def image_pixels(t: float, width: int, height: int) -> np.ndarray:
    """height x width x 3 uint8 gradient that moves with time."""
    x = np.arange(width, dtype=np.uint32)[None, :]
    y = np.arange(height, dtype=np.uint32)[:, None]
    shift = int(t * 10)
    red = ((x + shift) % 256).astype(np.uint8)
    green = ((y + shift) % 256).astype(np.uint8)
    blue = ((x + y) % 256).astype(np.uint8)
    return np.stack(np.broadcast_arrays(red, green, blue), axis=2)


def raw_image(ts: Typestore, time: int, t: float, width: int = 64, height: int = 48) -> Any:
    """rgb8 Image of the moving gradient."""
    pixels = image_pixels(t, width, height)
    return ts.types['sensor_msgs/msg/Image'](
        header=_header(ts, time, 'camera'), height=height, width=width, encoding='rgb8', is_bigendian=0,
        step=width * 3, data=np.frombuffer(pixels.tobytes(), dtype=np.uint8),
    )


def compressed_image(ts: Typestore, time: int, t: float) -> Any:
    """CompressedImage with deterministic stand-in bytes (a JPEG start marker and noise)."""
    body = np.random.default_rng(int(t * 1000)).integers(0, 256, 512, dtype=np.uint8).tobytes()
    return ts.types['sensor_msgs/msg/CompressedImage'](
        header=_header(ts, time, 'camera'), format='jpeg',
        data=np.frombuffer(b'\xff\xd8' + body, dtype=np.uint8),
    )


BUILDERS: dict[str, Callable[[Typestore, int, float], Any]] = {
    'nav_msgs/msg/Odometry': odometry,
    'sensor_msgs/msg/LaserScan': laser_scan,
    'sensor_msgs/msg/JointState': joint_state,
    'sensor_msgs/msg/Imu': imu,
    'tf2_msgs/msg/TFMessage': tf_message,
    'sensor_msgs/msg/BatteryState': battery_state,
    'sensor_msgs/msg/PointCloud2': point_cloud,
    'sensor_msgs/msg/Image': raw_image,
    'sensor_msgs/msg/CompressedImage': compressed_image,
}

ROVER_STREAMS = (
    Stream('/odom_raw', 'nav_msgs/msg/Odometry', 50.0),
    Stream('/scan_raw', 'sensor_msgs/msg/LaserScan', 10.0),
    Stream('/platform/motors/feedback_raw', 'sensor_msgs/msg/JointState', 50.0),
    Stream('/sensors/imu_raw', 'sensor_msgs/msg/Imu', 100.0),
    Stream('/tf_raw', 'tf2_msgs/msg/TFMessage', 50.0),
)


def sample_times(rate_hz: float, duration: float, start: int = DEFAULT_START) -> list[int]:
    """Exact integer ns times k / rate for k = 0 .. while < duration."""
    period = round(NS / rate_hz)
    return [start + k * period for k in range(math.ceil(duration * rate_hz - 1e-9))]


def messages(
    streams: Iterable[Stream],
    duration: float,
    start: int = DEFAULT_START,
    ts: Typestore | None = None,
) -> Iterator[tuple[Stream, int, Any]]:
    """(stream, log time ns, message) of every stream, in time order (stream order on ties)."""
    ts = ts or store()
    items = []
    for number, stream in enumerate(streams):
        for time in sample_times(stream.rate_hz, duration, start):
            items.append((time, number, stream))
    items.sort(key=lambda x: (x[0], x[1]))
    for time, _, stream in items:
        t = (time - start) / NS
        yield stream, time, BUILDERS[stream.msgtype](ts, time, t)


def write_mcap(
    path: Path,
    records: Iterable[tuple[Stream, int, Any]],
    ts: Typestore | None = None,
    *,
    compression: CompressionType = CompressionType.ZSTD,
    chunk_size: int = 1 << 20,
) -> int:
    """Write records to a ros2-profile MCAP with full schemas; return the message count."""
    ts = ts or store()
    count = 0
    with path.open('wb') as stream:
        writer = Writer(stream, compression=compression, chunk_size=chunk_size)
        writer.start(profile='ros2', library='bagfault-synthetic')
        channels: dict[str, int] = {}
        schemas: dict[str, int] = {}
        for topic_stream, time, message in records:
            if topic_stream.topic not in channels:
                msgtype = topic_stream.msgtype
                if msgtype not in schemas:
                    text, _ = ts.generate_msgdef(msgtype, ros_version=2)
                    schemas[msgtype] = writer.register_schema(msgtype, 'ros2msg', text.encode())
                channels[topic_stream.topic] = writer.register_channel(topic_stream.topic, 'cdr', schemas[msgtype], {})
            data = (message if isinstance(message, (bytes, bytearray, memoryview))
                    else ts.serialize_cdr(message, topic_stream.msgtype))
            writer.add_message(channels[topic_stream.topic], time, bytes(data), time)
            count += 1
        writer.finish()  # type: ignore[no-untyped-call]
    return count


def write_rover_bag(path: Path, duration: float = 20.0, start: int = DEFAULT_START) -> int:
    """The rover bag of the anchor's multi-injector scenario: raw topics only."""
    ts = store()
    return write_mcap(path, messages(ROVER_STREAMS, duration, start, ts), ts)
