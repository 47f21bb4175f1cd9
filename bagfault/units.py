"""Units in one place: bag time is integer nanoseconds; scenario files say seconds and milliseconds."""

from __future__ import annotations

NS = 1_000_000_000  # nanoseconds per second
MS = 1_000_000  # nanoseconds per millisecond
