"""`path_latency`: a statistic of a CARET named path's latency stays under max_ms."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from bagfault.assertions.base import AssertionType, fault_reference_problem
from bagfault.errors import AssertionSetupError, LatencyError
from bagfault.faults.header import has_header
from bagfault.latency.architecture import load_architecture
from bagfault.latency.collect import SeriesCollector
from bagfault.latency.compute import path_latency, statistics, window_mask
from bagfault.schema import Key

if TYPE_CHECKING:
    from bagfault.assertions.runner import AssertionRunner
    from bagfault.events import FaultEvent
    from bagfault.spec.model import AssertionSpec, Scenario

CHOICES = ('min', 'mean', 'p50', 'p95', 'p99', 'max')


def architecture_path(spec: AssertionSpec, scenario: Scenario) -> Path:
    """The architecture file, relative to the scenario file's folder."""
    path = Path(spec.params['architecture'])
    if not path.is_absolute() and scenario.source is not None:
        path = scenario.source.parent / path
    return path


class PathLatencyAssertion(AssertionType):
    """Computed at the end of the bag from the output's path topics."""

    type_name = 'path_latency'
    description = 'A statistic (p95, p99, max, mean, ...) of a CARET path latency stays at or under max_ms.'
    fields: ClassVar[tuple[Key, ...]] = (
        Key('architecture', 'non_empty_string', 'CARET architecture file (relative to the scenario).',
                    required=True),
        Key('path', 'non_empty_string', 'Named path in the architecture file.', required=True),
        Key('statistic', 'non_empty_string', 'min, mean, p50, p95, p99 or max.', default='p95'),
        Key('max_ms', 'number', 'Largest accepted value of the statistic, in milliseconds.', required=True,
                    minimum=0.0),
        Key('during', 'non_empty_string', 'Only samples whose first message came while this fault was active.'),
        Key('min_samples', 'integer', 'Fewest samples needed for a verdict.', default=1, minimum=1),
        Key('stamp_origin', 'boolean', "Measure from the first message's header.stamp, not its receive time."),
    )
    takes_within = False

    @classmethod
    def check(cls, spec: AssertionSpec, scenario: Scenario) -> list[tuple[str, str]]:
        """Statistic known, architecture loads, path exists and can be measured."""
        problems = fault_reference_problem(spec, scenario, 'during')
        if spec.params.get('statistic', 'p95') not in CHOICES:
            problems.append(('statistic', f"{spec.params['statistic']!r} is not one of {', '.join(CHOICES)}"))
        try:
            architecture = load_architecture(architecture_path(spec, scenario))
        except LatencyError as exc:
            return [*problems, ('architecture', str(exc))]
        path = architecture.paths.get(spec.params['path'])
        if path is None:
            problems.append(('path', f"no path {spec.params['path']!r} (paths: {', '.join(architecture.paths)})"))
        elif not path.usable:
            problems.append(('path', f'path {path.name} cannot be measured: {"; ".join(path.problems)}'))
        return problems

    def __init__(self, spec: AssertionSpec, runner: AssertionRunner) -> None:
        super().__init__(spec, runner)
        self.architecture = load_architecture(architecture_path(spec, runner.scenario))
        self.path = self.architecture.paths[self.params['path']]
        self.collector: SeriesCollector | None = None
        self.windows: list[tuple[int, int | None]] = []

    def topics(self) -> set[str]:
        """The path's topics."""
        return set(self.path.topics)

    def prepare(self) -> None:
        """Know which path topics carry header stamps."""
        stamped = {}
        for topic in self.path.topics:
            msgtype = self.runner.topic_types.get(topic)
            codec = self.runner.catalog.codec(msgtype) if msgtype else None
            stamped[topic] = codec is not None and has_header(codec.msgtype, codec.store)
        self.collector = SeriesCollector(stamped)

    def on_event(self, event: FaultEvent) -> None:
        """Track the windows of the `during` fault."""
        if event.fault_id != self.params.get('during'):
            return
        if event.state == 'active' and (not self.windows or self.windows[-1][1] is not None):
            self.windows.append((event.time, None))
        elif event.state == 'inactive' and self.windows and self.windows[-1][1] is None:
            self.windows[-1] = (self.windows[-1][0], event.time)

    def on_message(self, topic: str, time: int, message: object) -> None:
        """Collect receive time and stamp."""
        assert self.collector is not None
        self.collector.add(topic, time, message)  # type: ignore[arg-type]

    def finish(self, time: int) -> None:
        """Compute the latency and decide."""
        assert self.collector is not None
        try:
            result = path_latency(self.architecture, self.path, self.collector.series(),
                                  stamp_origin=bool(self.params.get('stamp_origin')))
        except LatencyError as exc:
            raise AssertionSetupError(f'assertion {self.spec.id!r}: {exc}') from None
        values = result.latency_ms
        scope = ''
        if 'during' in self.params:
            values = values[window_mask(result.input_times, self.windows)]
            scope = f" during {self.params['during']}"
        stats = statistics(np.asarray(values))
        name, limit = self.params.get('statistic', 'p95'), self.params['max_ms']
        needed = self.params.get('min_samples', 1)
        if stats['count'] < needed:
            self.fail(time, f'path {self.path.name}{scope}: {stats["count"]} samples, at least {needed} needed')
            return
        text = (f'{name} of path {self.path.name}{scope} = {stats[name]:.3f} ms (max {limit:g} ms, '
                f'{stats["count"]} samples, max {stats["max"]:.3f} ms)')
        if stats[name] > limit:
            self.fail(time, text, float(stats[name]), 'ms', margin=limit - float(stats[name]))
        else:
            self.passed(time, text, float(stats[name]), 'ms', margin=limit - float(stats[name]))
