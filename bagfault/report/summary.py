"""Compact terminal summary of a run."""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING, TextIO

if TYPE_CHECKING:
    from bagfault.api import RunResult


def _seconds(time: int, origin: int | None) -> str:
    return f'{(time - (origin or 0)) / 1e9:8.3f} s'


def print_run_summary(result: RunResult, stream: TextIO | None = None) -> None:
    """Inputs, output, message counts, fault timeline, notes."""
    out = stream or sys.stdout
    stats = result.stats
    print(f'scenario  {result.scenario.name}  (seed {result.seed})', file=out)
    print(f'inputs    {", ".join(str(p) for p in result.inputs)}', file=out)
    print(f'output    {result.output}  ({stats.output_messages} messages from {stats.input_messages} read)', file=out)
    if stats.events:
        print('fault events (bag time from zero):', file=out)
        for event in stats.events:
            print(f'  {_seconds(event.time, stats.origin)}  {event.fault_id:<32} {event.state:<8} ({event.source})',
                  file=out)
    for note in result.notes:
        print(f'note: {note}', file=out)
