"""Joint state injector (`joint_state`, sensor_msgs/msg/JointState), anchor keys."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from bagfault.faults.combine import total
from bagfault.faults.noise import gaussian
from bagfault.injectors.base import Injector
from bagfault.schema import DELAY_MS, DROP_PROBABILITY, Key, double, stddev

if TYPE_CHECKING:
    from collections.abc import Sequence

    from bagfault.faults.active import ActiveFault


class JointStateInjector(Injector):
    """Bias and noise on every velocity entry (motor feedback)."""

    type_name = 'joint_state'
    description = 'sensor_msgs/msg/JointState: velocity bias and noise on every joint.'
    message_types = ('sensor_msgs/msg/JointState',)
    plotted = (('velocity_', 'velocity[*]'),)
    fields: ClassVar[tuple[Key, ...]] = (
        DROP_PROBABILITY,
        DELAY_MS,
        double('velocity_bias', 'Added to every velocity entry, in rad/s (or m/s for prismatic joints).', finite=False),
        stddev('velocity_noise_stddev', 'Gaussian noise on every velocity entry, stddev in rad/s.', finite=False),
    )

    def mutate(self, message: Any, time: int, active: Sequence[ActiveFault]) -> None:
        """velocity += bias, then += noise per entry."""
        velocity = np.asarray(message.velocity, dtype=np.float64)
        if velocity.size == 0:
            return
        bias = total(active, 'velocity_bias')
        if bias != 0.0:
            velocity = velocity + bias
        noise = gaussian(active, 'velocity_noise_stddev', velocity.size)
        if noise is not None:
            velocity = velocity + noise
        message.velocity = velocity
