"""IMU injector (`imu`, sensor_msgs/msg/Imu), keys and meaning of the anchor."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, ClassVar

from bagfault.faults.combine import add, total
from bagfault.faults.noise import gaussian_one
from bagfault.injectors.base import Injector
from bagfault.schema import DELAY_MS, DROP_PROBABILITY, Key, double, stddev

if TYPE_CHECKING:
    from collections.abc import Sequence

    from bagfault.faults.active import ActiveFault

AXES = ('x', 'y', 'z')


class ImuInjector(Injector):
    """Yaw-rate and linear acceleration bias and noise."""

    type_name = 'imu'
    description = 'sensor_msgs/msg/Imu: angular velocity z and linear acceleration bias and noise.'
    message_types = ('sensor_msgs/msg/Imu',)
    plotted = (('angular_velocity_z', 'angular_velocity.z'), ('linear_acceleration_x', 'linear_acceleration.x'),
               ('linear_acceleration_y', 'linear_acceleration.y'), ('linear_acceleration_z', 'linear_acceleration.z'))
    linear_ops = (
        ('angular_velocity.z', 'angular_velocity_z_bias', 'bias'),
        ('angular_velocity.z', 'angular_velocity_z_noise_stddev', 'noise'),
        *((f'linear_acceleration.{a}', f'linear_acceleration_{a}_bias', 'bias') for a in AXES),
        *((f'linear_acceleration.{a}', f'linear_acceleration_{a}_noise_stddev', 'noise') for a in AXES),
    )
    fields: ClassVar[tuple[Key, ...]] = (
        DROP_PROBABILITY,
        DELAY_MS,
        double('angular_velocity_z_bias', 'Added to angular_velocity.z, in rad/s.', finite=False),
        stddev('angular_velocity_z_noise_stddev', 'Gaussian noise on angular_velocity.z, stddev in rad/s.',
               finite=False),
        *(double(f'linear_acceleration_{a}_bias', f'Added to linear_acceleration.{a}, in m/s^2.', finite=False)
          for a in AXES),
        *(
            stddev(f'linear_acceleration_{a}_noise_stddev',
                   f'Gaussian noise on linear_acceleration.{a}, stddev in m/s^2.', finite=False)
            for a in AXES
        ),
    )

    def mutate(self, message: Any, time: int, active: Sequence[ActiveFault]) -> None:
        """Angular velocity bias, its noise, acceleration biases, their noise (anchor order)."""
        add(message.angular_velocity, 'z', total(active, 'angular_velocity_z_bias'))
        add(message.angular_velocity, 'z', gaussian_one(active, 'angular_velocity_z_noise_stddev'))
        accel = message.linear_acceleration
        for axis in AXES:
            add(accel, axis, total(active, f'linear_acceleration_{axis}_bias'))
        for axis in AXES:
            add(accel, axis, gaussian_one(active, f'linear_acceleration_{axis}_noise_stddev'))
