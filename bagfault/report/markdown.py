"""Markdown report: scenario, inputs, fault timeline, assertion table, topics."""

from __future__ import annotations

import json
from typing import Any


def _cell(text: object) -> str:
    return str(text).replace('|', '\\|').replace('\n', ' ')


def render(report: dict[str, Any]) -> str:
    """Markdown text of a report model."""
    counts = report['assertion_counts']
    lines = [
        f'# bagfault report: {report["scenario"]["name"]}',
        '',
        f'**{report["verdict"].upper()}**: {counts["passed"]} passed, {counts["failed"]} failed'
        if report['assertions'] else '_No assertions in this scenario._',
        '',
        f'- mode: {report["mode"]}',
        f'- scenario: `{report["scenario"]["file"]}`',
        f'- inputs: {", ".join(f"`{p}`" for p in report["inputs"])}',
    ]
    if report['output']:
        lines.append(f'- output: `{report["output"]}`')
    lines += [
        f'- seed: {report["seed"]}',
        f'- bag duration: {report["time"]["duration_s"]} s; messages read {report["messages"]["read"]}, '
        f'written {report["messages"]["written"]}',
        f'- bagfault {report["tool"]["version"]}',
        '',
        '## Fault timeline',
        '',
    ]
    lines += _timeline(report['fault_events'])
    lines += _assertions(report['assertions'])
    if 'fault_manager' in report:
        lines += fault_manager_section(report['fault_manager'])
    lines += ['', '## Topics written', '', '| topic | messages |', '|---|---:|']
    lines += [f'| {topic} | {count} |' for topic, count in report['messages']['per_topic_written'].items()]
    if report['notes']:
        lines += ['', '## Notes', ''] + [f'- {note}' for note in report['notes']]
    return '\n'.join(lines) + '\n'


def _timeline(events: list[dict[str, Any]]) -> list[str]:
    """The fault timeline's table, or a line saying nothing changed."""
    if not events:
        return ['No fault changed state during the bag.']
    return ['| t (s) | fault | injector | state | source | config |', '|---:|---|---|---|---|---|'] + [
        f'| {e["t_s"]:.3f} | {e["fault_id"]} | {e["injector_id"]} | {e["state"]} | {e["source"]} | '
        f'`{_cell(e["details"])}` |'
        for e in events
    ]


def _assertions(assertions: list[dict[str, Any]]) -> list[str]:
    """The assertion table (nothing without assertions)."""
    if not assertions:
        return []
    lines = ['', '## Assertions', '', '| result | assertion | type | t (s) | message |', '|---|---|---|---:|---|']
    mark = {'passed': 'PASS', 'failed': 'FAIL', 'pending': 'PENDING'}
    for a in assertions:
        t = '' if a['t_s'] is None else f'{a["t_s"]:.3f}'
        lines.append(f'| {mark[a["state"]]} | {a["id"]} | {a["type"]} | {t} | {_cell(a["message"])} |')
    return lines


def fault_manager_section(summary: dict[str, Any]) -> list[str]:
    """Final fault table, events, clusters and snapshots of the fault manager oracle."""
    lines = ['', '## Fault manager', '',
             f'At the end of the bag: {len(summary["confirmed"])} confirmed, {summary["muted_count"]} muted, '
             f'{summary["cluster_count"]} clusters.', '',
             '| code | severity | status | occurrences | first (s) | last (s) | sources |',
             '|---|---|---|---:|---:|---:|---|']
    for fault in summary['faults']:
        lines.append(f'| {fault["fault_code"]} | {fault["severity"]} | {fault["status"]} | '
                     f'{fault["occurrence_count"]} | {fault["first_occurred_s"]:.3f} | '
                     f'{fault["last_occurred_s"]:.3f} | '
                     f'{", ".join(fault["reporting_sources"])} |')
    lines += _fault_manager_events(summary['events'])
    for cluster in summary['clusters']:
        lines.append(f'- cluster {cluster["cluster_id"]} ({cluster["rule_name"]}): {cluster["count"]} faults, '
                     f'shown as {cluster["representative_code"]}')
    for muted in summary['muted']:
        lines.append(f'- muted {muted["fault_code"]} (root {muted["root_cause_code"]}, rule {muted["rule_id"]}, '
                     f'+{muted["delay_ms"]} ms)')
    for snapshot in summary['snapshots']:
        box = f', black box `{snapshot["black_box"]}` ({snapshot["black_box_messages"]} messages)' \
            if snapshot['black_box'] else ''
        lines += ['', f'### Snapshot of {snapshot["fault_code"]} at {snapshot["t_s"]:.3f} s{box}', '', '```json',
                  json.dumps(snapshot['freeze_frame'], indent=1, sort_keys=True)[:4000], '```']
    return lines


def _fault_manager_events(events: list[dict[str, Any]]) -> list[str]:
    """The fault manager's state changes (the first 200) and its fault_updated events folded into counts."""
    lines: list[str] = []
    changes = [e for e in events if e['event_type'] != 'fault_updated']
    if changes:
        lines += ['', '| t (s) | event | code | status | auto-cleared |', '|---:|---|---|---|---|']
        shown = changes[:200]
        lines += [f'| {e["t_s"]:.3f} | {e["event_type"]} | {e["fault_code"]} | {e["status"]} | '
                  f'{", ".join(e["auto_cleared_codes"])} |' for e in shown]
        if len(changes) > len(shown):
            lines.append(f'| | ... {len(changes) - len(shown)} more events | | | |')
    updates: dict[str, int] = {}
    for event in events:
        if event['event_type'] == 'fault_updated':
            updates[event['fault_code']] = updates.get(event['fault_code'], 0) + 1
    if updates:
        folded = ', '.join(f'{code} {count}' for code, count in sorted(updates.items()))
        lines += ['', f'fault_updated events (folded): {folded}']
    return lines
