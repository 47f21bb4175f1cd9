"""battery_state injector (sensor_msgs/msg/BatteryState).

Installing this package makes `type: battery_state` usable in scenarios
(including the anchor's battery_faults.yaml) through the entry point group
`bagfault.injectors` declared in pyproject.toml.
"""

from __future__ import annotations

from typing import Any, ClassVar

from bagfault.faults.combine import add, total
from bagfault.injectors.base import Injector
from bagfault.schema import DELAY_MS, DROP_PROBABILITY, Key, double


class BatteryStateInjector(Injector):
    """Voltage and charge faults on sensor_msgs/msg/BatteryState."""

    type_name = 'battery_state'
    description = 'sensor_msgs/msg/BatteryState: voltage and percentage bias.'
    message_types = ('sensor_msgs/msg/BatteryState',)
    fields: ClassVar[tuple[Key, ...]] = (
        DROP_PROBABILITY,
        DELAY_MS,
        double('voltage_bias', 'Added to voltage, in volts; biases of several faults add.'),
        double('percentage_bias', 'Added to percentage (0..1 charge), result clamped to [0, 1].'),
    )

    def mutate(self, message: Any, time: int, active: Any) -> None:
        """voltage += bias; percentage += bias, kept within [0, 1]."""
        add(message, 'voltage', total(active, 'voltage_bias'))
        bias = total(active, 'percentage_bias')
        if bias:
            message.percentage = min(1.0, max(0.0, message.percentage + bias))
