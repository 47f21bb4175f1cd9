"""Units in one place: bag time is integer nanoseconds; scenario files say seconds and milliseconds."""

from __future__ import annotations

NS = 1_000_000_000  # nanoseconds per second
MS = 1_000_000  # nanoseconds per millisecond
MAX_SECONDS = 1e7  # any time in a scenario (about 115 days): far beyond a bag, far below int64 nanoseconds
