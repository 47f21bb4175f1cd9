"""Roll/pitch/yaw biases on quaternions, with tf2's getRPY/setRPY conventions."""

from __future__ import annotations

import math


def quaternion_to_rpy(x: float, y: float, z: float, w: float) -> tuple[float, float, float]:
    """Roll, pitch, yaw (rad, fixed axes X-Y-Z) of a quaternion. The zero quaternion has none: tf2's
    Matrix3x3(q) scales by 2 / |q|^2 = inf, and 0 * inf makes every angle NaN, so the anchor writes a NaN
    orientation; so does bagfault."""
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    if norm == 0.0:
        return math.nan, math.nan, math.nan
    x, y, z, w = x / norm, y / norm, z / norm, w / norm
    roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    sinp = max(-1.0, min(1.0, 2.0 * (w * y - z * x)))
    pitch = math.asin(sinp)
    yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return roll, pitch, yaw


def rpy_to_quaternion(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """Unit quaternion (x, y, z, w) of roll, pitch, yaw (rad), like tf2 setRPY."""
    cr, sr = math.cos(roll / 2.0), math.sin(roll / 2.0)
    cp, sp = math.cos(pitch / 2.0), math.sin(pitch / 2.0)
    cy, sy = math.cos(yaw / 2.0), math.sin(yaw / 2.0)
    x = sr * cp * cy - cr * sp * sy
    y = cr * sp * cy + sr * cp * sy
    z = cr * cp * sy - sr * sp * cy
    w = cr * cp * cy + sr * sp * sy
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    return x / norm, y / norm, z / norm, w / norm


def add_rpy(quaternion: object, droll: float, dpitch: float, dyaw: float) -> None:
    """Add angle biases (rad) to a geometry_msgs Quaternion object in place."""
    q = quaternion
    roll, pitch, yaw = quaternion_to_rpy(q.x, q.y, q.z, q.w)  # type: ignore[attr-defined]
    q.x, q.y, q.z, q.w = rpy_to_quaternion(roll + droll, pitch + dpitch, yaw + dyaw)  # type: ignore[attr-defined]
