"""Compact terminal summary of a run or check, ending with the assertion table."""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING, TextIO

from bagfault.units import NS

if TYPE_CHECKING:
    from bagfault.engine.result import RunResult


def _seconds(time: int | None, origin: int | None) -> str:
    if time is None:
        return '       -  '
    return f'{(time - (origin or 0)) / NS:8.3f} s'


def _short(text: str, width: int) -> str:
    return text if len(text) <= width else text[: width - 1] + '…'


def print_run_summary(result: RunResult, stream: TextIO | None = None) -> None:
    """Inputs, output, fault timeline, notes, then one line per assertion and the verdict; warnings go to stderr
    (as `validate` writes them) unless a `stream` takes everything."""
    out = stream or sys.stdout
    err = stream or sys.stderr
    _print_files(result, out)
    if result.system is not None:
        _print_system(result, out)
    stats = result.stats
    if stats.events:
        print('fault events (bag time from zero):', file=out)
        for event in stats.events:
            print(f'  {_seconds(event.time, stats.origin)}  {event.fault_id:<32} {event.state:<8} ({event.source})',
                  file=out)
    for note in result.notes:
        print(f'note: {note}', file=out)
    for warning in result.warnings:
        print(f'warning: {warning}', file=err)
    _print_verdicts(result, out)


def _print_files(result: RunResult, out: TextIO) -> None:
    """The scenario, what was read and what was written (or only checked, or passed on live)."""
    stats = result.stats
    print(f'scenario  {result.scenario.name}  (seed {result.seed})', file=out)
    live = ', '.join(sorted({i.input_topic for i in result.scenario.injectors if i.input_topic}))
    sources = ', '.join(str(p) for p in result.inputs) if result.inputs else f'live topics {live}'.rstrip()
    print(f'inputs    {sources}', file=out)
    if result.output is not None:
        print(f'output    {result.output}  ({stats.output_messages} messages from {stats.input_messages} read'
              f'{_copied(result)})', file=out)
    elif result.mode == 'check':
        print(f'checked   {stats.input_messages} messages', file=out)
    else:
        print(f'{result.mode:<9} {stats.output_messages} messages from {stats.input_messages} received (not recorded)',
              file=out)


def _copied(result: RunResult) -> str:
    """'; N of M chunks copied as they are' and whether they were verified, or '' without chunks."""
    stats = result.stats
    if not stats.chunks:
        return ''
    unverified = stats.chunks_copied - stats.chunks_verified
    checked = (f', {unverified} unverified (--verify reads them)' if unverified else
               ' and verified' if stats.chunks_copied else '')
    return f'; {stats.chunks_copied} of {stats.chunks} chunks copied as they are{checked}'


def _print_verdicts(result: RunResult, out: TextIO) -> None:
    """One line per assertion and the verdict, with the count of scenario parts that do nothing."""
    doing_nothing = _inert_note(result.scenario.inert_warnings)
    if not result.assertions:
        if doing_nothing:
            print(f'note: {doing_nothing}', file=out)
        return
    width = max(len(r.id) for r in result.assertions)
    print('assertions:', file=out)
    for r in result.assertions:
        mark = {'passed': 'PASS', 'failed': 'FAIL'}.get(r.state, r.state.upper())
        print(f'  {mark:<4}  {r.id:<{width}}  {_seconds(r.time, result.stats.origin)}  {_short(r.message, 100)}',
              file=out)
    failed = sum(r.state == 'failed' for r in result.assertions)
    passed = sum(r.state == 'passed' for r in result.assertions)
    print(f'{"FAILED" if failed else "PASSED"}: {passed} passed, {failed} failed'
          + (f'; {doing_nothing}' if doing_nothing else ''), file=out)


def _inert_note(inert: int) -> str:
    """'N warnings of something in the scenario that does nothing (above)', or '' for none."""
    if not inert:
        return ''
    return f'{inert} warning{"s" if inert != 1 else ""} of something in the scenario that does nothing (above)'


def _print_system(result: RunResult, out: TextIO) -> None:
    """`test`: what ran, on which domain, what it was sent and what it said; its last lines if it died."""
    system = result.system
    assert system is not None
    print(f'system    {" ".join(system.command)}', file=out)
    print(f'          ROS domain {system.domain_id}, ready after {system.ready_seconds:.2f} s, stopped: '
          f'{system.stopped_by()} (exit code {system.returncode})', file=out)
    played = ', '.join(f'{t} {n}' for t, n in sorted(system.played.items())) or 'nothing'
    heard = ', '.join(f'{t} {n}' for t, n in sorted(system.heard.items())) or 'nothing'
    print(f'played    {played}', file=out)
    print(f'heard     {heard}', file=out)
    if system.lost:
        print(f'lost      {", ".join(f"{t} {n}" for t, n in sorted(system.lost.items()))}', file=out)
    if system.logs is not None:
        print(f'logs      {system.logs}', file=out)
    _print_tail(result, out)


def _print_tail(result: RunResult, out: TextIO) -> None:
    """The system's last lines, when it did not stay alive."""
    system = result.system
    assert system is not None
    if any(a.id == 'system_alive' and a.state == 'failed' for a in result.assertions) and system.tail:
        print('its last lines:', file=out)
        for line in system.tail:
            print(f'  | {line}', file=out)
