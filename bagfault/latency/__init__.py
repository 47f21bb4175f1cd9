"""Path latency from bag data, with CARET architecture files."""

from __future__ import annotations

from bagfault.errors import BagfaultError


class LatencyError(BagfaultError):
    """An architecture file or a latency computation cannot be used."""
