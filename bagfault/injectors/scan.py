"""LaserScan injector (`scan`, sensor_msgs/msg/LaserScan), anchor keys and meaning."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from bagfault.faults.combine import total
from bagfault.faults.noise import gaussian
from bagfault.injectors.base import Injector
from bagfault.schema import DELAY_MS, DROP_PROBABILITY, Key, double, stddev

if TYPE_CHECKING:
    from collections.abc import Sequence

    from bagfault.faults.active import ActiveFault


class ScanInjector(Injector):
    """Range bias and noise on finite samples, and sector dropout."""

    type_name = 'scan'
    description = 'sensor_msgs/msg/LaserScan: range bias and noise, blind angular sector.'
    message_types = ('sensor_msgs/msg/LaserScan',)
    plotted = (('range_', 'ranges[*]'), ('sector_min', 'ranges[*]'))
    fields: ClassVar[tuple[Key, ...]] = (
        DROP_PROBABILITY,
        DELAY_MS,
        double('range_bias', 'Added to every finite range, in metres, then clamped to [range_min, range_max].',
               finite=False),
        stddev('range_noise_stddev',
               'Gaussian noise on every finite range, stddev in metres, clamped to [range_min, range_max].',
               finite=False),
        double('sector_min_deg', 'Start angle of the blind sector, in degrees in the scan frame.'),
        double('sector_max_deg', 'End angle of the blind sector, in degrees in the scan frame.'),
        Key('sector_value', 'special_float', 'Range written inside the sector, in metres, or inf, -inf, nan.',
                    default=math.inf),
    )

    @classmethod
    def config_warnings(cls, config: dict[str, Any]) -> list[str]:
        """A sector needs both bounds; with one (or only sector_value) no beam is blanked, as in the anchor."""
        has = sorted(k for k in ('sector_min_deg', 'sector_max_deg') if k in config)
        if len(has) == 1:
            missing = ({'sector_min_deg', 'sector_max_deg'} - set(has)).pop()
            return [f'{has[0]} without {missing}: no sector is blanked (ros2_fault_injection skips it too)']
        if 'sector_value' in config and not has:
            return ['sector_value without sector_min_deg and sector_max_deg: no sector is blanked']
        return []

    def mutate(self, message: Any, time: int, active: Sequence[ActiveFault]) -> None:
        """Bias, noise, then each active sector (anchor order)."""
        ranges = np.asarray(message.ranges, dtype=np.float32)
        if ranges.size == 0:
            return
        low, high = float(message.range_min), float(message.range_max)
        finite = np.isfinite(ranges)
        values = ranges.astype(np.float64)

        bias = total(active, 'range_bias')
        changed = False
        if bias != 0.0:
            values[finite] = np.clip(values[finite] + bias, low, high)
            changed = True
        noise = gaussian(active, 'range_noise_stddev', int(finite.sum()))
        if noise is not None:
            values[finite] = np.clip(values[finite] + noise, low, high)
            changed = True
        if changed:
            ranges = values.astype(np.float32)

        if message.angle_increment != 0.0:
            for fault in active:
                config = fault.config
                if 'sector_min_deg' not in config or 'sector_max_deg' not in config:
                    continue
                inside = sector_mask(
                    float(message.angle_min),
                    float(message.angle_increment),
                    ranges.size,
                    config['sector_min_deg'],
                    config['sector_max_deg'],
                )
                if inside.any():
                    ranges = ranges.copy()
                    ranges[inside] = np.float32(config.get('sector_value', math.inf))
        message.ranges = ranges


def _wrap_scalar(degrees: float) -> float:
    """Into (-180, 180] as the anchor's loop does, without looping (huge angles must not hang)."""
    if degrees > 180.0:
        degrees -= 360.0 * math.ceil((degrees - 180.0) / 360.0)
    elif degrees < -180.0:
        degrees += 360.0 * math.ceil((-180.0 - degrees) / 360.0)
    return degrees


def sector_mask(
    angle_min: float,
    angle_increment: float,
    count: int,
    min_deg: float,
    max_deg: float,
) -> np.ndarray:
    """Which beams fall inside [min_deg, max_deg] (wrapping through 180 when min > max)."""
    angles = np.degrees(angle_min + np.arange(count, dtype=np.float64) * angle_increment)
    angles = _wrap_array(angles)
    lo, hi = _wrap_scalar(min_deg), _wrap_scalar(max_deg)
    if lo <= hi:
        return (angles >= lo) & (angles <= hi)
    return (angles >= lo) | (angles <= hi)


def _wrap_array(degrees: np.ndarray) -> np.ndarray:
    out = degrees.copy()
    high = out > 180.0
    out[high] -= 360.0 * np.ceil((out[high] - 180.0) / 360.0)
    low = out < -180.0
    out[low] += 360.0 * np.ceil((-180.0 - out[low]) / 360.0)
    return out
