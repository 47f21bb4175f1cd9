"""Before/after values of mutated fields, read back from the input and the output after a run."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from bagfault.errors import FieldPathError
from bagfault.faults.fieldpath import FieldPath
from bagfault.injectors.base import Injector
from bagfault.injectors.registry import get_injector_type
from bagfault.io.sources import InputSet
from bagfault.io.types import TypeCatalog

if TYPE_CHECKING:
    from pathlib import Path

    from bagfault.engine.result import RunResult

MAX_POINTS = 1500
NS = 1_000_000_000


@dataclass
class FieldPlot:
    """One field of one injector: values before (input topic) and after (output topic)."""

    injector_id: str
    input_topic: str
    output_topic: str
    field: str
    before: tuple[list[float], list[float]] = dataclasses.field(default_factory=lambda: ([], []))
    after: tuple[list[float], list[float]] = dataclasses.field(default_factory=lambda: ([], []))
    faults: list[str] = dataclasses.field(default_factory=list)


def plan(result: RunResult) -> list[FieldPlot]:
    """Fields touched by faults that were active during the run."""
    activated = {e.fault_id for e in result.stats.events if e.state == 'active'}
    plots = []
    for spec in result.scenario.injectors:
        cls = get_injector_type(spec.type)
        if cls is None or not issubclass(cls, Injector) or not spec.input_topic or not spec.output_topic:
            continue
        fields: dict[str, list[str]] = {}
        for fault in result.scenario.faults_of(spec.id):
            if fault.id not in activated:
                continue
            for key in fault.config:
                for path in cls.plot_fields(key, fault.config):
                    fields.setdefault(path, []).append(fault.id)
        plots += [FieldPlot(spec.id, spec.input_topic, spec.output_topic, path, faults=sorted(set(faults)))
                  for path, faults in fields.items()]
    return plots


def _series(paths: list[Path], topic: str, fields: list[str], origin: int,
            expected: int) -> dict[str, tuple[list[float], list[float]]]:
    out: dict[str, tuple[list[float], list[float]]] = {f: ([], []) for f in fields}
    inputs = InputSet(paths)
    try:
        catalog = TypeCatalog(inputs.channels, inputs.ros_distro)
        channels = {i: c for i, c in enumerate(inputs.channels) if c.topic == topic}
        if not channels:
            return out
        msgtype = next(iter(channels.values())).msgtype
        codec = catalog.codec(msgtype)
        if codec is None:
            return out
        resolved = {}
        for text in fields:
            try:
                resolved[text] = FieldPath.parse(text).resolve(msgtype, codec.store)
            except FieldPathError:
                continue
        stride = max(1, expected // MAX_POINTS)
        number = 0
        for channel, time, _, data in inputs.messages():
            if channel not in channels:
                continue
            number += 1
            if (number - 1) % stride:
                continue
            message = codec.decode(data)
            for text, path in resolved.items():
                values = path.read(message)
                finite = values[np.isfinite(values)]
                out[text][0].append((time - origin) / NS)
                out[text][1].append(float(finite.mean()) if finite.size else float('nan'))
    finally:
        inputs.close()
    return out


def collect(result: RunResult) -> list[FieldPlot]:
    """Fill before/after series of every planned field plot."""
    plots = plan(result)
    if not plots or result.output is None or result.stats.origin is None:
        return plots
    origin = result.stats.origin
    counts = result.stats.per_topic_out
    by_topic: dict[tuple[str, str], list[FieldPlot]] = {}
    for plot in plots:
        by_topic.setdefault((plot.input_topic, plot.output_topic), []).append(plot)
    for (input_topic, output_topic), group in by_topic.items():
        fields = [p.field for p in group]
        expected = counts.get(output_topic, 0)
        before = _series(list(result.inputs), input_topic, fields, origin, expected)
        after = _series([result.output], output_topic, fields, origin, expected)
        for plot in group:
            plot.before, plot.after = before[plot.field], after[plot.field]
    return plots
