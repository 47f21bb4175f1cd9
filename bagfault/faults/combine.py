"""How several active faults on one injector combine (the anchor's rules).

Biases add up (`total`); probabilities, noise levels, delays and scales use
the strongest active value (`strongest`), whose fault also owns the random
draws for that key.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Sequence

    from bagfault.faults.active import ActiveFault


def total(active: Sequence[ActiveFault], key: str) -> float:
    """Sum of `key` over the active faults that set it."""
    return float(sum(f.config[key] for f in active if key in f.config))


def strongest(
    active: Sequence[ActiveFault],
    key: str,
    default: float = 0.0,
) -> tuple[float, ActiveFault | None]:
    """Largest `key` over the active faults that set it, and the first fault holding it. A nan is never the
    largest: the anchor folds levels with `std::max(level, value)` from a finite fallback
    (fault_injector_base.cpp, active_max_double), which keeps `level` when `value` is nan."""
    best: float | None = None
    owner = None
    for fault in active:
        if key in fault.config:
            value = fault.config[key]
            if value != value:  # nan
                continue
            if best is None or value > best:
                best, owner = value, fault
    return (default, None) if best is None else (float(best), owner)


def add(holder: object, attr: str, value: float) -> None:
    """holder.attr += value, leaving the field untouched when value is 0."""
    if value != 0.0:
        setattr(holder, attr, getattr(holder, attr) + value)
