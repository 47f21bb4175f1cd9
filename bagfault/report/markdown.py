"""Markdown report: scenario, inputs, fault timeline, assertion table, topics."""

from __future__ import annotations

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
    if report['fault_events']:
        lines += ['| t (s) | fault | injector | state | source | config |', '|---:|---|---|---|---|---|']
        lines += [
            f'| {e["t_s"]:.3f} | {e["fault_id"]} | {e["injector_id"]} | {e["state"]} | {e["source"]} | '
            f'`{_cell(e["details"])}` |'
            for e in report['fault_events']
        ]
    else:
        lines.append('No fault changed state during the bag.')
    if report['assertions']:
        lines += ['', '## Assertions', '', '| result | assertion | type | t (s) | message |', '|---|---|---|---:|---|']
        mark = {'passed': 'PASS', 'failed': 'FAIL', 'pending': 'PENDING'}
        for a in report['assertions']:
            t = '' if a['t_s'] is None else f'{a["t_s"]:.3f}'
            lines.append(f'| {mark[a["state"]]} | {a["id"]} | {a["type"]} | {t} | {_cell(a["message"])} |')
    lines += ['', '## Topics written', '', '| topic | messages |', '|---|---:|']
    lines += [f'| {topic} | {count} |' for topic, count in report['messages']['per_topic_written'].items()]
    if report['notes']:
        lines += ['', '## Notes', ''] + [f'- {note}' for note in report['notes']]
    return '\n'.join(lines) + '\n'
