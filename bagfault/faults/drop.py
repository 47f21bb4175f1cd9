"""Message drop decisions, one per message, drawn from the owning fault's stream."""

from __future__ import annotations

from typing import TYPE_CHECKING

from bagfault.faults.combine import strongest

if TYPE_CHECKING:
    from collections.abc import Sequence

    import numpy as np

    from bagfault.faults.active import ActiveFault

KEY = 'drop_probability'


def should_drop(active: Sequence[ActiveFault], key: str = KEY) -> bool:
    """Draw one drop decision (True = drop)."""
    probability, owner = strongest(active, key)
    if probability <= 0.0 or owner is None:
        return False
    return bool(owner.random.stream(key).random() < probability)


def drop_mask(active: Sequence[ActiveFault], count: int, key: str = KEY) -> np.ndarray | None:
    """Keep-mask for `count` consecutive messages, or None when nothing drops."""
    probability, owner = strongest(active, key)
    if probability <= 0.0 or owner is None:
        return None
    return owner.random.stream(key).random(count) >= probability
