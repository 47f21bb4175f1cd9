"""Extended schedule keys: `repeat`, `probability_per_second` with `hold`, `after`.

`start` and `duration` bound the window in which `repeat` and
`probability_per_second` act (default: the whole bag). `after` activates a
fault `delay` seconds after another one activates; it lasts `duration`
seconds, or until `delay` seconds after the trigger deactivates.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from bagfault.scenario.loader import seconds
from bagfault.spec.model import After, FaultSpec, Repeat

if TYPE_CHECKING:
    from bagfault.scenario.loader import _Collector
    from bagfault.spec.yamlnodes import PathKey


MIN_PERIOD = 0.01  # seconds: a repeat faster than 100 Hz toggles faster than any sensor it acts on
MIN_SPAN = 0.001  # seconds: the shortest `on` and `hold`, the anchor's timer resolution
MAX_RATE = 100.0  # random activations per second at most


def parse_extended_schedule(fault: FaultSpec, node: dict[str, Any], path: PathKey, out: _Collector) -> None:
    """Fill fault.repeat / probability_per_second / hold / after from the fault's mapping."""
    if 'repeat' in node:
        value, where = node['repeat'], (*path, 'repeat')
        if not isinstance(value, dict) or set(value) != {'period', 'on'}:
            out.add(where, 'must be a mapping {period: S, on: S}')
        else:
            period = seconds(value['period'], (*where, 'period'), out, positive=True, minimum=MIN_PERIOD)
            on = seconds(value['on'], (*where, 'on'), out, positive=True, minimum=MIN_SPAN)
            if period is not None and on is not None:
                if on > period:
                    out.add((*where, 'on'), f'{on} is longer than the period {period}')
                else:
                    fault.repeat = Repeat(period=period, on=on)
    if 'probability_per_second' in node:
        where = (*path, 'probability_per_second')
        rate = node['probability_per_second']
        if isinstance(rate, bool) or not isinstance(rate, (int, float)) or not 0 < rate <= MAX_RATE:
            out.add(where, f'{rate!r} must be a rate above 0 and at most {MAX_RATE:g} activations per second')
        else:
            fault.probability_per_second = float(rate)
        if 'hold' not in node:
            out.add(where, "needs 'hold': how long each random activation lasts, in seconds")
    if 'hold' in node:
        fault.hold = seconds(node['hold'], (*path, 'hold'), out, positive=True, minimum=MIN_SPAN)
        if 'probability_per_second' not in node:
            out.add((*path, 'hold'), "only makes sense with 'probability_per_second'")
    if 'after' in node:
        value, where = node['after'], (*path, 'after')
        if not isinstance(value, dict) or 'fault' not in value or not set(value) <= {'fault', 'delay'}:
            out.add(where, 'must be a mapping {fault: ID, delay: S}')
        else:
            delay = seconds(value.get('delay', 0.0), (*where, 'delay'), out)
            if delay is not None:
                fault.after = After(fault=str(value['fault']), delay=delay)
    kinds = [k for k in ('repeat', 'probability_per_second', 'after') if node.get(k) is not None]
    if len(kinds) > 1:
        out.add(path, f'choose one schedule: {" and ".join(kinds)} cannot be combined')
    if 'after' in kinds and (node.get('start') is not None or node.get('active_on_startup')):
        out.add((*path, 'after'), "a chained fault starts from its trigger; drop 'start'/'active_on_startup'")
