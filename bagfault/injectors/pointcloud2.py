"""PointCloud2 injector (`pointcloud2`): vectorised noise, bias, dropout, blind sector, NaN points.

x, y and z are found by name in the message's PointField list (float32 or
float64, either byte order), so any driver's layout works. Removed points
disappear from unorganized clouds (height 1); organized clouds keep their
grid and get NaN coordinates instead.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from bagfault.errors import InjectorConfigError, InjectorError, MalformedMessageError
from bagfault.faults.combine import strongest, total
from bagfault.injectors.base import Injector
from bagfault.schema import DELAY_MS, DROP_PROBABILITY, Key, double, probability, stddev

if TYPE_CHECKING:
    from collections.abc import Sequence

    from bagfault.faults.active import ActiveFault

FLOAT_TYPES = {7: 'f4', 8: 'f8'}  # sensor_msgs/PointField FLOAT32, FLOAT64


def xyz_view(message: Any) -> tuple[np.ndarray, np.ndarray]:
    """(points structured array view over a contiguous copy of the data, n x 3 float64 coordinates)."""
    offsets = {}
    order = '>' if message.is_bigendian else '<'
    for field in message.fields:
        if field.name in ('x', 'y', 'z'):
            if field.datatype not in FLOAT_TYPES:
                raise MalformedMessageError(f'field {field.name} has datatype {field.datatype}, not a float')
            offsets[field.name] = (field.offset, order + FLOAT_TYPES[field.datatype])
    if set(offsets) != {'x', 'y', 'z'}:
        raise MalformedMessageError(f'cloud has fields {[f.name for f in message.fields]}, not x, y and z')
    count = message.width * message.height
    raw = np.asarray(message.data, dtype=np.uint8)
    rows = raw[: message.height * message.row_step].reshape(message.height, message.row_step)
    body = np.array(rows[:, : message.width * message.point_step]).reshape(count, message.point_step)
    dtype = np.dtype({'names': ['x', 'y', 'z'], 'formats': [offsets[k][1] for k in 'xyz'],
                      'offsets': [offsets[k][0] for k in 'xyz'], 'itemsize': message.point_step})
    points = body.view(dtype).reshape(count)
    xyz = np.stack([points['x'], points['y'], points['z']], axis=1).astype(np.float64)
    return body, xyz


class PointCloud2Injector(Injector):
    """Noise/bias on x, y, z; point dropout; range-limited blind sector; NaN points."""

    type_name = 'pointcloud2'
    description = 'sensor_msgs/msg/PointCloud2: xyz noise and bias, point dropout, blind sector, NaN points.'
    message_types = ('sensor_msgs/msg/PointCloud2',)
    fields: ClassVar[tuple[Key, ...]] = (
        DROP_PROBABILITY,
        DELAY_MS,
        stddev('xyz_noise_stddev', 'Gaussian noise on x, y and z of every point, stddev in metres.'),
        double('x_bias', 'Added to x of every point, in metres.'),
        double('y_bias', 'Added to y of every point, in metres.'),
        double('z_bias', 'Added to z of every point, in metres.'),
        probability('dropout_probability', 'Probability that a point is removed (0..1).'),
        probability('nan_probability', 'Probability that a point gets NaN coordinates (0..1).'),
        double('sector_min_deg', 'Start azimuth of the blind sector (atan2(y, x)), in degrees.'),
        double('sector_max_deg', 'End azimuth of the blind sector, in degrees.'),
        Key('sector_min_range', 'number', 'Blind only beyond this range, in metres.', default=0.0, minimum=0.0),
        Key('sector_max_range', 'number', 'Blind only up to this range, in metres.', default=math.inf, minimum=0.0),
    )

    @classmethod
    def check_fault(cls, config: dict[str, Any], options: dict[str, Any]) -> None:
        """A sector needs both angles."""
        if ('sector_min_deg' in config) != ('sector_max_deg' in config):
            raise InjectorConfigError('sector_min_deg and sector_max_deg go together')
        if config.get('sector_min_range', 0.0) > config.get('sector_max_range', math.inf):
            raise InjectorConfigError('sector_min_range is above sector_max_range')

    def mutate(self, message: Any, time: int, active: Sequence[ActiveFault]) -> None:
        """Bias, noise, sector, NaN points, dropout; the cloud is rewritten once."""
        try:
            body, xyz = xyz_view(message)
        except MalformedMessageError as exc:
            raise InjectorError(f'pointcloud2 injector {self.spec.id!r}: {exc}') from None
        count = len(xyz)
        changed = False
        bias = np.array([total(active, f'{a}_bias') for a in 'xyz'])
        if bias.any():
            xyz += bias
            changed = True
        sigma, owner = strongest(active, 'xyz_noise_stddev')
        if owner is not None and sigma > 0:
            xyz += owner.random.stream('xyz_noise_stddev').standard_normal((count, 3)) * sigma
            changed = True
        remove = np.zeros(count, dtype=bool)
        for fault in active:
            config = fault.config
            if 'sector_min_deg' in config:
                remove |= _sector(xyz, config)
        p, owner = strongest(active, 'dropout_probability')
        if owner is not None and p > 0:
            remove |= owner.random.stream('dropout_probability').random(count) < p
        p, owner = strongest(active, 'nan_probability')
        invalid = np.zeros(count, dtype=bool)
        if owner is not None and p > 0:
            invalid = owner.random.stream('nan_probability').random(count) < p
        if message.height > 1:
            invalid |= remove
            remove[:] = False
        if invalid.any():
            xyz[invalid] = np.nan
            changed = True
        if not changed and not remove.any():
            return
        _write_xyz(message, body, xyz)
        if remove.any():
            body = body[~remove]
            message.width = len(body)
            message.height = 1
            message.row_step = message.width * message.point_step
        if invalid.any():
            message.is_dense = False
        message.data = body.reshape(-1).copy()


def _sector(xyz: np.ndarray, config: dict[str, Any]) -> np.ndarray:
    azimuth = np.degrees(np.arctan2(xyz[:, 1], xyz[:, 0]))
    low, high = (((config[k] + 180.0) % 360.0) - 180.0 for k in ('sector_min_deg', 'sector_max_deg'))
    inside = (azimuth >= low) & (azimuth <= high) if low <= high else (azimuth >= low) | (azimuth <= high)
    distance = np.linalg.norm(xyz, axis=1)
    low, high = config.get('sector_min_range', 0.0), config.get('sector_max_range', np.inf)
    selected: np.ndarray = inside & (distance >= low) & (distance <= high)
    return selected


def _write_xyz(message: Any, body: np.ndarray, xyz: np.ndarray) -> None:
    order = '>' if message.is_bigendian else '<'
    for axis, field in enumerate(f for name in 'xyz' for f in message.fields if f.name == name):
        dtype = np.dtype(order + FLOAT_TYPES[field.datatype])
        column = body[:, field.offset: field.offset + dtype.itemsize]
        column[:] = xyz[:, axis].astype(dtype).view(np.uint8).reshape(-1, dtype.itemsize)
