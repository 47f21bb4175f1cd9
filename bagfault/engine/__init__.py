"""Engine: bag-time scheduler, router, time-ordered merge, per-fault random streams."""

from __future__ import annotations

from bagfault.errors import BagfaultError


class EngineError(BagfaultError):
    """The scenario cannot run on these inputs (missing topic, wrong type, ...)."""
