"""Gaussian noise drawn from the stream of the fault that sets the strongest level."""

from __future__ import annotations

from typing import TYPE_CHECKING

from bagfault.faults.combine import strongest

if TYPE_CHECKING:
    from collections.abc import Sequence

    import numpy as np

    from bagfault.faults.active import ActiveFault


def gaussian(active: Sequence[ActiveFault], key: str, count: int) -> np.ndarray | None:
    """`count` noise samples for the strongest `key` stddev, or None when it is zero."""
    sigma, owner = strongest(active, key)
    if sigma <= 0.0 or owner is None:
        return None
    return owner.random.stream(key).standard_normal(count) * sigma


def gaussian_one(active: Sequence[ActiveFault], key: str) -> float:
    """One noise sample (0.0 when the level is zero); equals gaussian(..., 1)[0]."""
    samples = gaussian(active, key, 1)
    return 0.0 if samples is None else float(samples[0])
