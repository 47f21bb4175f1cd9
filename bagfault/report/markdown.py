"""Markdown report: scenario, inputs, fault timeline, topics."""

from __future__ import annotations

from typing import Any


def render(report: dict[str, Any]) -> str:
    """Markdown text of a report model."""
    lines = [
        f'# bagfault report: {report["scenario"]["name"]}',
        '',
        f'- scenario: `{report["scenario"]["file"]}`',
        f'- inputs: {", ".join(f"`{p}`" for p in report["inputs"])}',
        f'- output: `{report["output"]}`',
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
            f'`{e["details"]}` |'
            for e in report['fault_events']
        ]
    else:
        lines.append('No fault changed state during the bag.')
    lines += ['', '## Topics written', '', '| topic | messages |', '|---|---:|']
    lines += [f'| {topic} | {count} |' for topic, count in report['messages']['per_topic_written'].items()]
    if report['notes']:
        lines += ['', '## Notes', ''] + [f'- {note}' for note in report['notes']]
    return '\n'.join(lines) + '\n'
