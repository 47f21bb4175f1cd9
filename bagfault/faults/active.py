"""A fault that is active now, as injectors and the fault primitives see it."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from bagfault.faults.rng import FaultRandom
    from bagfault.spec.model import FaultSpec


@dataclass
class ActiveFault:
    """A fault that is active now: its spec, when it started, its random streams."""

    spec: FaultSpec
    since: int
    random: FaultRandom

    @property
    def id(self) -> str:
        """Fault id."""
        return self.spec.id

    @property
    def config(self) -> dict[str, Any]:
        """Validated config values."""
        return self.spec.config
