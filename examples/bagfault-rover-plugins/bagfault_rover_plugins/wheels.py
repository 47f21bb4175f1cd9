"""wheel_encoders injector: faults on a custom message type.

bagfault decodes rover_msgs/msg/WheelEncoders with the definition stored in
the bag; the injector only declares the type name and works on the decoded
fields like any built-in one.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from bagfault.faults.combine import strongest
from bagfault.injectors.base import Injector
from bagfault.schema import DELAY_MS, DROP_PROBABILITY, Key, boolean

WHEEL_ENCODERS_MSG = """std_msgs/Header header
int32[] ticks
float64[] speeds
uint8 status
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
"""


class WheelEncodersInjector(Injector):
    """Stuck encoder counts, wrong speed scale, forced status code."""

    type_name = 'wheel_encoders'
    description = 'rover_msgs/msg/WheelEncoders: stuck ticks, speed scale, forced status.'
    message_types = ('rover_msgs/msg/WheelEncoders',)
    fields: ClassVar[tuple[Key, ...]] = (
        DROP_PROBABILITY,
        DELAY_MS,
        boolean('ticks_stuck', 'Every tick counter keeps the value it had when the fault started.'),
        Key('speed_scale', 'number', 'Multiplies every wheel speed (factor).', default=1.0, minimum=0.0),
        Key('status_override', 'integer', 'Status code reported instead of the real one.', default=0, minimum=0,
            maximum=255),
    )

    def __init__(self, spec: Any, codec: Any = None, faults: Any = ()) -> None:
        super().__init__(spec, codec, faults)
        self._held: dict[tuple[str, int], np.ndarray] = {}

    def mutate(self, message: Any, time: int, active: Any) -> None:
        """Apply the three faults."""
        for fault in active:
            if fault.config.get('ticks_stuck'):
                held = self._held.setdefault((fault.id, fault.since), np.array(message.ticks, copy=True))
                message.ticks = held.copy()
        scale, owner = strongest(active, 'speed_scale', 1.0)
        if owner is not None:
            message.speeds = np.asarray(message.speeds) * scale
        status, owner = strongest(active, 'status_override')
        if owner is not None:
            message.status = int(status)
