"""The /clock bagfault publishes, as the clock faults warp it: jumps and rates over windows of bag time.

Bag time stays the time axis of the run (played stamps, the recording, the
oracles); only the clock the system follows is warped. A jump moves it by
`jump_s` for the window; a rate runs it at that factor of bag time from the
window's start; at the window's end it is bag time again (a jump back).
"""

from __future__ import annotations

import struct
from typing import TYPE_CHECKING, Any

from bagfault.units import NS

if TYPE_CHECKING:
    from bagfault.spec.model import FaultSpec

CLOCK_TYPE = 'rosgraph_msgs/msg/Clock'
CLOCK_TRACE = '/bagfault/clock'  # what /clock said, recorded at the bag time it said it


def stall_seconds(fault: FaultSpec) -> float:
    """How long one activation of a stall lasts in bag seconds: a repeat's `on` (when it is shorter than the
    period), a random activation's `hold`, else the fault's `duration` (0 without one: a switch from outside)."""
    if fault.repeat is not None and fault.repeat.on < fault.repeat.period:
        return fault.repeat.on
    if fault.probability_per_second is not None and fault.hold is not None:
        return fault.hold
    return fault.duration or 0.0


def clock_cdr(value: int) -> bytes:
    """A rosgraph_msgs/msg/Clock in CDR (little endian): the time `value` (ns)."""
    sec, nanosec = divmod(value, NS)
    return b'\x00\x01\x00\x00' + struct.pack('<iI', sec, nanosec)


class ClockWarps:
    """The clock faults in force, applied in the order they started."""

    def __init__(self) -> None:
        self._warps: dict[str, tuple[str, int, float]] = {}  # fault id -> (kind, bag time it started, value)

    def start(self, fault_id: str, at: int, config: dict[str, Any]) -> str:
        """A jump or rate fault starts at bag time `at`; what /clock does now."""
        if config.get('jump_s'):
            self._warps[fault_id] = ('jump', at, float(config['jump_s']))
            return f'/clock jumps by {float(config["jump_s"]):+g} s to {self.clock_of(at) / NS:.3f} s'
        self._warps[fault_id] = ('rate', at, float(config['rate']))
        return f'/clock runs at {float(config["rate"]):g} x bag time from {self.clock_of(at) / NS:.3f} s'

    def end(self, fault_id: str) -> str:
        """A warp ends: /clock is bag time again."""
        return '/clock follows bag time again' if self._warps.pop(fault_id, None) is not None else ''

    def clock_of(self, bag_time: int) -> int:
        """What /clock says at bag time `bag_time` (never below zero)."""
        value = bag_time
        for kind, at, amount in self._warps.values():
            if kind == 'jump':
                value += round(amount * NS)
            else:
                value = at + round((value - at) * amount)
        return max(value, 0)
