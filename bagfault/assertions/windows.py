"""`during` / `outside` windows shared by assertion types."""

from __future__ import annotations

from typing import TYPE_CHECKING

from bagfault.schema import Key

if TYPE_CHECKING:
    from bagfault.assertions.base import AssertionType

DURING = Key('during', 'non_empty_string', 'Only while this fault is active.')
OUTSIDE = Key('outside', 'non_empty_string', 'Only while this fault is not active.')


def in_window(check: AssertionType) -> bool:
    """True when the assertion's window condition holds now."""
    params, active = check.params, check.runner.active
    if 'during' in params:
        return params['during'] in active
    if 'outside' in params:
        return params['outside'] not in active
    return True


def describe(check: AssertionType) -> str:
    """' during F' / ' outside F' / ''."""
    params = check.params
    if 'during' in params:
        return f" during {params['during']}"
    if 'outside' in params:
        return f" outside {params['outside']}"
    return ''
