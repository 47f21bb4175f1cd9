"""One result model for every report: terminal, markdown, JSON, JUnit, HTML.

The keys of `build` are the JSON report's keys; docs/reference/report.md documents
them and they only ever grow.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from bagfault import __version__
from bagfault.events import AssertionEvent, ScenarioStatus
from bagfault.units import NS

if TYPE_CHECKING:
    from bagfault.engine.result import RunResult

SCHEMA_VERSION = 1


def seconds(time: int | None, origin: int | None) -> float | None:
    """Bag time in seconds from time zero."""
    if time is None or origin is None:
        return None
    return round((time - origin) / NS, 9)


def fault_windows(result: RunResult) -> list[dict[str, Any]]:
    """[{fault_id, start_s, end_s}] from the fault events (end None while still active)."""
    origin = result.stats.origin
    open_: dict[str, float | None] = {}
    windows = []
    for event in result.stats.events:
        if event.state == 'active':
            open_[event.fault_id] = seconds(event.time, origin)
        elif event.state == 'inactive' and event.fault_id in open_:
            windows.append({'fault_id': event.fault_id, 'start_s': open_.pop(event.fault_id),
                            'end_s': seconds(event.time, origin)})
    windows += [{'fault_id': f, 'start_s': s, 'end_s': None} for f, s in open_.items()]
    return sorted(windows, key=lambda w: (w['start_s'], w['fault_id']))


def build(result: RunResult) -> dict[str, Any]:
    """Plain, JSON-ready dictionary with stable keys."""
    stats = result.stats
    assertions = _assertions(result)
    counts = {state: sum(a['state'] == state for a in assertions) for state in ('passed', 'failed', 'pending')}
    statuses = [e for e in result.assertion_events if isinstance(e, ScenarioStatus)]
    return _sections(result) | {
        'schema_version': SCHEMA_VERSION,
        'tool': {'name': 'bagfault', 'version': __version__},
        'mode': result.mode,
        'verdict': 'failed' if counts['failed'] else 'passed',
        'scenario': {'file': str(result.scenario.source or result.scenario.name), 'name': result.scenario.name},
        'seed': result.seed,
        'inputs': [str(p) for p in result.inputs],
        'output': str(result.output) if result.output else None,
        'time': _time(result),
        'messages': {'read': stats.input_messages, 'written': stats.output_messages,
                     'per_topic_written': dict(sorted(stats.per_topic_out.items())),
                     'malformed': dict(sorted(stats.malformed.items()))},
        'fault_events': _fault_events(result),
        'fault_windows': fault_windows(result),
        'injectors': _injectors(result),
        'assertions': assertions,
        'assertion_counts': counts,
        'assertion_events': _assertion_events(result),
        'final_status': statuses[-1].state if statuses else None,
        'notes': list(result.notes),
        'warnings': list(result.warnings),
    }


def _time(result: RunResult) -> dict[str, Any]:
    """Time zero, the first and last message, the bag's span and the run's wall time."""
    stats = result.stats
    return {
        'origin_ns': stats.origin,
        'first_ns': stats.first_time,
        'last_ns': stats.last_time,
        'duration_s': seconds(stats.last_time, stats.first_time),
        'wall_s': None if result.wall_seconds is None else round(result.wall_seconds, 3),
    }


def _assertion_events(result: RunResult) -> list[dict[str, Any]]:
    """Each assertion's changes of state, in bag time."""
    return [
        {'t_s': seconds(e.time, result.stats.origin), 'assertion_id': e.assertion_id, 'state': e.state,
         'message': e.message}
        for e in result.assertion_events if isinstance(e, AssertionEvent)
    ]


def _fault_events(result: RunResult) -> list[dict[str, Any]]:
    """Each fault's changes of state, in bag time, with the injector and the config it applied."""
    origin = result.stats.origin
    return [
        {'t_s': seconds(e.time, origin), 'stamp_ns': e.time, 'fault_id': e.fault_id,
         'injector_id': e.injector_id, 'state': e.state, 'source': e.source, 'details': e.details}
        for e in result.stats.events
    ]


def _injectors(result: RunResult) -> list[dict[str, Any]]:
    """Each injector: its type, topics and the faults declared on it."""
    return [
        {'id': i.id, 'type': i.type, 'input_topic': i.input_topic, 'output_topic': i.output_topic,
         'faults': [f.id for f in result.scenario.faults_of(i.id)]}
        for i in result.scenario.injectors
    ]


def _assertions(result: RunResult) -> list[dict[str, Any]]:
    """Each assertion's verdict, with the scenario line it is declared on."""
    origin = result.stats.origin
    lines = {spec.id: int(result.scenario.located.where(spec.path).split(':')[0]) if spec.path else None
             for spec in result.scenario.assertions}
    return [
        {'id': r.id, 'type': r.type, 'state': r.state, 't_s': seconds(r.time, origin), 'stamp_ns': r.time,
         'message': r.message, 'line': lines.get(r.id), 'wall_s': round(r.wall_ns / NS, 6),
         'value': r.value, 'unit': r.unit, 'margin': r.margin, 'margin_unit': r.margin_unit}
        for r in result.assertions
    ]


def _sections(result: RunResult) -> dict[str, Any]:
    """The sections a run has only with a fault manager, a system under test or repeats."""
    extra: dict[str, Any] = {}
    if result.fault_manager is not None:
        extra['fault_manager'] = result.fault_manager
    if result.system is not None:
        extra['system_under_test'] = system_section(result)
    if result.repeats:
        extra['repeats'] = repeats_section(result)
    return extra


def system_section(result: RunResult) -> dict[str, Any]:
    """`test`: the system under test, its logs and message counts."""
    system = result.system
    assert system is not None
    return {
        'command': list(system.command), 'ros_domain_id': system.domain_id,
        'ready_s': round(system.ready_seconds, 3), 'stopped_by': system.ending,
        'signals_sent': [{'signal': name, 't_s': round(at, 3)} for name, at in system.signals],
        'exit_code': system.returncode,
        'logs': str(system.logs) if system.logs is not None else None, 'output_tail': list(system.tail),
        'played_per_topic': dict(sorted(system.played.items())),
        'heard_per_topic': dict(sorted(system.heard.items())),
        'lost_per_topic': dict(sorted(system.lost.items())),
        'unwatched_topics': list(system.unwatched), 'leftover_pids': list(system.leftovers),
    }


def repeats_section(result: RunResult) -> dict[str, Any]:
    """`test --repeat`: per assertion its pass rate and each run's state and decision time."""
    runs = result.repeats
    rates = result.pass_rates()
    section: dict[str, Any] = {'runs': len(runs), 'assertions': {}}
    for assertion in runs[0].assertions:
        per_run = [next((a for a in r.assertions if a.id == assertion.id), None) for r in runs]
        states = [a.state if a is not None else 'pending' for a in per_run]
        section['assertions'][assertion.id] = {
            'pass_rate': rates[assertion.id],
            'states': states,
            't_s': [seconds(a.time, r.stats.origin) if a is not None else None
                    for r, a in zip(runs, per_run, strict=True)],
        }
    return section
