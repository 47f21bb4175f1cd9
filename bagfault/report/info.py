"""`bagfault info`: storage, time span and topics of one or more bags."""

from __future__ import annotations

from typing import TYPE_CHECKING

from bagfault.io.sources import InputSet
from bagfault.io.types import TypeCatalog
from bagfault.units import NS

if TYPE_CHECKING:
    from collections.abc import Sequence
    from pathlib import Path

    from bagfault.io.channel import Channel


def render_info(paths: Sequence[Path]) -> str:
    """Topics with type, count, definition source and QoS; time span."""
    with InputSet(paths) as inputs:
        counts, first, last = _counted(inputs)
        catalog = TypeCatalog(inputs.channels, inputs.ros_distro)
        lines = [f'inputs:    {", ".join(str(p) for p in paths)}',
                 f'distro:    {inputs.ros_distro or "unknown (standard types of " + catalog.distro + ")"}',
                 f'messages:  {sum(counts)}']
        if first is not None and last is not None:
            lines.append(f'duration:  {(last - first) / NS:.3f} s  (start {stamp(first)}, end {stamp(last)})')
        lines.append('topics:')
        width = max((len(c.topic) for c in inputs.channels), default=10)
        for channel, count in zip(inputs.channels, counts, strict=True):
            qos = ' qos' if channel.qos else ''
            lines.append(f'  {channel.topic:<{width}}  {count:8d}  {channel.msgtype or "?"}  '
                         f'[{_definition(channel, catalog)}{qos}]')
        return '\n'.join(lines)


def _counted(inputs: InputSet) -> tuple[list[int], int | None, int | None]:
    """Messages per channel, and the first and last log time (None without messages)."""
    counts = [0] * len(inputs.channels)
    first = last = None
    for index, log_time, _, _ in inputs.messages():
        counts[index] += 1
        first = log_time if first is None else first
        last = log_time
    return counts, first, last


def _definition(channel: Channel, catalog: TypeCatalog) -> str:
    """Where a channel's type definition comes from: the bag, bagfault's standard types, or nowhere."""
    if channel.schema_text:
        return 'stored'
    if catalog.schema(channel.msgtype)[1]:
        return 'standard'
    return 'none: passed through undecoded'


def stamp(time: int) -> str:
    """Exact seconds.nanoseconds text of a time in ns."""
    return f'{time // NS}.{time % NS:09d}'
