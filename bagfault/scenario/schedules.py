"""Extended schedule keys: `repeat`, `probability_per_second` with `hold`, `after`.

`start` and `duration` bound the window in which `repeat` and
`probability_per_second` act (default: the whole bag). `after` activates a
fault `delay` seconds after another one activates; it lasts `duration`
seconds, or until `delay` seconds after the trigger deactivates.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from bagfault.spec import sections
from bagfault.spec.model import After, FaultSpec, Repeat

if TYPE_CHECKING:
    from bagfault.scenario.loader import _Collector
    from bagfault.spec.reader import Read
    from bagfault.spec.yamlnodes import PathKey


def parse_extended_schedule(fault: FaultSpec, node: dict[str, object], read: Read, path: PathKey,
                            out: _Collector) -> None:
    """Fill fault.repeat / probability_per_second / hold / after from the fault's keys (`read`: the fault
    section, read by its declaration)."""
    if 'repeat' in read:
        fault.repeat = _repeat(read.get('repeat'), (*path, 'repeat'), out)
    _random(fault, read, path, out)
    if 'after' in read:
        after = out.reader().read(sections.AFTER, read.get('after'), (*path, 'after'))
        if after is not None and 'fault' in after and 'delay' in after:
            fault.after = After(fault=after.get('fault'), delay=after.get('delay'))
    _one_schedule(read, path, out)


def _one_schedule(read: Read, path: PathKey, out: _Collector) -> None:
    """At most one of repeat, random activations and a chain; a chained fault has no start of its own."""
    kinds = [k for k in ('repeat', 'probability_per_second', 'after') if k in read.given]
    if len(kinds) > 1:
        out.add(path, f'choose one schedule: {" and ".join(kinds)} cannot be combined')
    if 'after' in kinds and ('start' in read.given or read.get('active_on_startup')):
        out.add((*path, 'after'), "a chained fault starts from its trigger; drop 'start'/'active_on_startup'")


def _repeat(node: object, where: PathKey, out: _Collector) -> Repeat | None:
    """`repeat: {period, on}`: on for `on` seconds of every `period` (None when refused)."""
    repeat = out.reader().read(sections.REPEAT, node, where)
    if repeat is None or not {'period', 'on'} <= set(repeat.values):
        return None
    period, on = repeat.get('period'), repeat.get('on')
    if on > period:
        out.add((*where, 'on'), f'{on} is longer than the period {period}')
        return None
    return Repeat(period=period, on=on)


def _random(fault: FaultSpec, read: Read, path: PathKey, out: _Collector) -> None:
    """Random activations: `probability_per_second` and `hold`, each of which needs the other."""
    if 'probability_per_second' in read.given:
        fault.probability_per_second = read.get('probability_per_second')
        if 'hold' not in read.given:
            out.add((*path, 'probability_per_second'), "needs 'hold': how long each random activation lasts, in "
                                                       'seconds')
    if 'hold' in read.given:
        fault.hold = read.get('hold')
        if 'probability_per_second' not in read.given:
            out.add((*path, 'hold'), "only makes sense with 'probability_per_second'")
