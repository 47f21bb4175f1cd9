"""Example bagfault plugins: two injector types in an installable package.

- `battery_state` (sensor_msgs/msg/BatteryState), the type of ros2_fault_injection's
  example plugin, so the anchor's battery_faults.yaml runs unchanged;
- `wheel_encoders`, for a custom message type (rover_msgs/msg/WheelEncoders)
  whose definition only the bag carries.
"""

from __future__ import annotations

from bagfault_rover_plugins.battery import BatteryStateInjector
from bagfault_rover_plugins.wheels import WHEEL_ENCODERS_MSG, WheelEncodersInjector

__all__ = ['WHEEL_ENCODERS_MSG', 'BatteryStateInjector', 'WheelEncodersInjector']
