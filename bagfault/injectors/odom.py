"""Odometry injector (`odom`, nav_msgs/msg/Odometry), keys and meaning of the anchor."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from bagfault.faults.combine import add, strongest, total
from bagfault.faults.noise import gaussian_one
from bagfault.faults.rotation import add_rpy
from bagfault.injectors.base import Injector
from bagfault.schema import DELAY_MS, DROP_PROBABILITY, Key, double, stddev

if TYPE_CHECKING:
    from collections.abc import Sequence

    from bagfault.faults.active import ActiveFault


class OdomInjector(Injector):
    """Position and yaw bias/noise and covariance inflation on odometry."""

    type_name = 'odom'
    description = 'nav_msgs/msg/Odometry: position and yaw bias and noise, covariance inflation.'
    message_types = ('nav_msgs/msg/Odometry',)
    plotted = (('x_', 'pose.pose.position.x'), ('y_', 'pose.pose.position.y'), ('yaw_', 'pose.pose.orientation:yaw'),
               ('pose_covariance', 'pose.covariance[0]'), ('twist_covariance', 'twist.covariance[0]'))
    linear_ops = (
        ('pose.pose.position.x', 'x_bias', 'bias'),
        ('pose.pose.position.y', 'y_bias', 'bias'),
        ('pose.pose.position.x', 'x_noise_stddev', 'noise'),
        ('pose.pose.position.y', 'y_noise_stddev', 'noise'),
    )
    fields: ClassVar[tuple[Key, ...]] = (
        DROP_PROBABILITY,
        DELAY_MS,
        double('x_bias', 'Added to pose.pose.position.x, in metres; biases of several faults add.', finite=False),
        double('y_bias', 'Added to pose.pose.position.y, in metres; biases of several faults add.', finite=False),
        stddev('x_noise_stddev', 'Gaussian noise on pose.pose.position.x, stddev in metres.', finite=False),
        stddev('y_noise_stddev', 'Gaussian noise on pose.pose.position.y, stddev in metres.', finite=False),
        double('yaw_bias_deg', 'Added to the yaw of pose.pose.orientation, in degrees.', finite=False),
        stddev('yaw_noise_stddev_deg', 'Gaussian noise on the yaw of pose.pose.orientation, stddev in degrees.',
               finite=False),
        Key('pose_covariance_scale', 'number', 'Multiplies every pose covariance entry (factor).', default=1.0,
                    minimum=0.0, finite=False),
        Key('twist_covariance_scale', 'number', 'Multiplies every twist covariance entry (factor).', default=1.0,
                    minimum=0.0, finite=False),
        Key('pose_covariance_floor', 'number', 'Minimum of every pose covariance entry after scaling.', default=0.0,
                    minimum=0.0, finite=False),
        Key('twist_covariance_floor', 'number', 'Minimum of every twist covariance entry after scaling.', default=0.0,
                    minimum=0.0, finite=False),
    )

    @classmethod
    def config_warnings(cls, config: dict[str, Any]) -> list[str]:
        """Scales below 1 do nothing: covariance is only ever inflated (the anchor takes max(1.0, scales))."""
        return [f'{key} {config[key]:g} is below 1 and changes nothing: ros2_fault_injection only inflates covariance'
                for key in ('pose_covariance_scale', 'twist_covariance_scale') if config.get(key, 1.0) < 1.0]

    def mutate(self, message: Any, time: int, active: Sequence[ActiveFault]) -> None:
        """Apply bias, noise, yaw bias, yaw noise, covariance (anchor order)."""
        position = message.pose.pose.position
        add(position, 'x', total(active, 'x_bias'))
        add(position, 'y', total(active, 'y_bias'))
        add(position, 'x', gaussian_one(active, 'x_noise_stddev'))
        add(position, 'y', gaussian_one(active, 'y_noise_stddev'))

        yaw_bias = total(active, 'yaw_bias_deg')
        if yaw_bias != 0.0:
            add_rpy(message.pose.pose.orientation, 0.0, 0.0, math.radians(yaw_bias))
        yaw_noise = gaussian_one(active, 'yaw_noise_stddev_deg')
        if yaw_noise != 0.0:
            add_rpy(message.pose.pose.orientation, 0.0, 0.0, math.radians(yaw_noise))

        inflate_covariance(message.pose, active, 'pose')
        inflate_covariance(message.twist, active, 'twist')


def inflate_covariance(holder: Any, active: Sequence[ActiveFault], prefix: str) -> None:
    """covariance = max(scale * covariance, floor), the scale being the largest of 1.0 and the active scales
    (the anchor's active_max_double with fallback 1.0: covariance is only ever inflated)."""
    scale = max(1.0, strongest(active, f'{prefix}_covariance_scale', 1.0)[0])
    floor = max(0.0, strongest(active, f'{prefix}_covariance_floor', 0.0)[0])
    if scale == 1.0 and floor <= 0.0:
        return
    holder.covariance = np.maximum(np.asarray(holder.covariance, dtype=np.float64) * scale, floor)
