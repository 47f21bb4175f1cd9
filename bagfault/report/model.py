"""One result model for every report: terminal, markdown, JSON, JUnit, HTML."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from bagfault import __version__

if TYPE_CHECKING:
    from bagfault.api import RunResult

NS = 1_000_000_000


def seconds(time: int | None, origin: int | None) -> float | None:
    """Bag time in seconds from time zero."""
    if time is None or origin is None:
        return None
    return round((time - origin) / NS, 9)


def build(result: RunResult) -> dict[str, Any]:
    """Plain, JSON-ready dictionary with stable keys (documented in docs/report.md)."""
    stats = result.stats
    origin = stats.origin
    return {
        'tool': {'name': 'bagfault', 'version': __version__},
        'mode': 'run',
        'scenario': {'file': str(result.scenario.source or result.scenario.name), 'name': result.scenario.name},
        'seed': result.seed,
        'inputs': [str(p) for p in result.inputs],
        'output': str(result.output),
        'time': {
            'origin_ns': origin,
            'first_ns': stats.first_time,
            'last_ns': stats.last_time,
            'duration_s': seconds(stats.last_time, stats.first_time),
        },
        'messages': {'read': stats.input_messages, 'written': stats.output_messages,
                     'per_topic_written': dict(sorted(stats.per_topic_out.items()))},
        'fault_events': [
            {'t_s': seconds(e.time, origin), 'stamp_ns': e.time, 'fault_id': e.fault_id,
             'injector_id': e.injector_id, 'state': e.state, 'source': e.source, 'details': e.details}
            for e in stats.events
        ],
        'notes': list(result.notes),
    }
