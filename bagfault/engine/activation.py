"""A `--activate FAULT[@START[+DURATION]]` request, parsed without importing the engine (the leading copy's guess
reads it before the heavy imports)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from bagfault.units import MAX_SECONDS


@dataclass(frozen=True)
class Activation:
    """A `--activate FAULT[@START[+DURATION]]` request (seconds)."""

    fault_id: str
    start: float = 0.0
    duration: float | None = None

    @classmethod
    def parse(cls, text: str) -> Activation:
        """Parse FAULT, FAULT@START or FAULT@START+DURATION."""
        fault_id, _, when = text.partition('@')
        if not fault_id:
            raise ValueError(f'{text!r}: expected FAULT[@START[+DURATION]]')
        start_text, plus, duration_text = when.partition('+')
        try:
            start = float(start_text) if start_text else 0.0
            duration = float(duration_text) if plus else None
        except ValueError:
            raise ValueError(f'{text!r}: START and DURATION must be seconds, e.g. imu_bias@5+10') from None
        for value in (start, duration):
            if value is not None and not (math.isfinite(value) and 0 <= value <= MAX_SECONDS):
                raise ValueError(f'{text!r}: times must be from 0 to {MAX_SECONDS:g} seconds')
        return cls(fault_id, start, duration)
