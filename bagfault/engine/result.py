"""What a run produced besides its output file: statistics, verdicts, notes."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

if TYPE_CHECKING:
    from bagfault.assertions.base import AssertionResult
    from bagfault.events import AssertionEvent, FaultEvent, ScenarioStatus
    from bagfault.spec.model import Scenario

Mode = Literal['run', 'check', 'play', 'proxy', 'test']


@dataclass
class RunStats:
    """Counts and times of one run, for the summary and the reports (times in ns of bag time)."""

    input_messages: int = 0
    output_messages: int = 0
    first_time: int | None = None
    last_time: int | None = None
    origin: int | None = None
    per_topic_out: dict[str, int] = field(default_factory=dict)
    events: list[FaultEvent] = field(default_factory=list)
    replaced_topics: list[str] = field(default_factory=list)
    max_buffered: int = 0
    last_output_time: int | None = None
    malformed: dict[str, int] = field(default_factory=dict)  # input topic -> messages that could not take a fault
    malformed_first: dict[str, tuple[int, str]] = field(default_factory=dict)  # input topic -> (time, reason)
    chunks: int = 0  # chunk copy: the input's chunks ...
    chunks_copied: int = 0  # ... and those written as they are
    chunks_verified: int = 0  # ... of which read again and checked (--verify)

    def add(self, other: RunStats) -> None:
        """Fold a later pass (play --loop) into these totals; the first pass keeps the origin."""
        self.input_messages += other.input_messages
        self.output_messages += other.output_messages
        if self.first_time is None:
            self.first_time, self.origin = other.first_time, other.origin
        if other.last_time is not None:
            self.last_time = other.last_time
        if other.last_output_time is not None:
            self.last_output_time = other.last_output_time
        for topic, count in other.per_topic_out.items():
            self.per_topic_out[topic] = self.per_topic_out.get(topic, 0) + count
        self.events.extend(other.events)
        for topic, count in other.malformed.items():
            self.malformed[topic] = self.malformed.get(topic, 0) + count
        for topic, first in other.malformed_first.items():
            self.malformed_first.setdefault(topic, first)
        self.max_buffered = max(self.max_buffered, other.max_buffered)
        self.replaced_topics = list(dict.fromkeys([*self.replaced_topics, *other.replaced_topics]))


@dataclass
class SystemReport:
    """What `bagfault test` saw of the system under test."""

    command: list[str]
    domain_id: int
    ready_seconds: float = 0.0
    ending: str = 'running'  # exited (on its own), SIGINT, SIGTERM or SIGKILL (the last signal it got)
    signals: list[tuple[str, float]] = field(default_factory=list)  # each signal sent, seconds into the stop

    def stopped_by(self) -> str:
        """'exited', 'SIGINT' or 'SIGINT, then SIGTERM after 5.0 s': every signal that was sent."""
        if not self.signals:
            return self.ending
        first, *later = self.signals
        return ', then '.join([first[0], *(f'{name} after {at:.1f} s' for name, at in later)])
    returncode: int | None = None
    logs: Path | None = None  # the folder of system.stdout.log and system.stderr.log, when kept
    tail: list[str] = field(default_factory=list)  # its last lines of output
    played: dict[str, int] = field(default_factory=dict)  # messages published to it, per topic
    heard: dict[str, int] = field(default_factory=dict)  # messages it published that were recorded, per topic
    lost: dict[str, int] = field(default_factory=dict)  # messages it published known lost before heard, per topic
    unwatched: list[str] = field(default_factory=list)  # asserted topics whose type nobody told
    leftovers: list[int] = field(default_factory=list)  # processes still running after the stop (none)


@dataclass
class RunResult:
    """Everything a run, check, play, proxy or test produced besides its output file."""

    scenario: Scenario
    inputs: list[Path]
    output: Path | None
    seed: int
    stats: RunStats
    notes: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    assertions: list[AssertionResult] = field(default_factory=list)
    assertion_events: list[AssertionEvent | ScenarioStatus] = field(default_factory=list)
    mode: Mode = 'run'
    fault_manager: dict[str, Any] | None = None
    wall_seconds: float | None = None
    system: SystemReport | None = None  # `test`: the system under test
    repeats: list[RunResult] = field(default_factory=list)  # `test --repeat`: each run (this one aggregates)

    @property
    def failed(self) -> bool:
        """True when an assertion failed (in any repeated run): exit code 1."""
        return any(r.state == 'failed' for r in self.assertions) or any(r.failed for r in self.repeats)

    def pass_rates(self) -> dict[str, float]:
        """Assertion id -> share of the runs it passed: of each repeated run (`test --repeat`), else 1.0 or 0.0."""
        runs = self.repeats or [self]
        return {a.id: [next((b.state for b in r.assertions if b.id == a.id), 'pending') for r in runs].count('passed')
                / len(runs) for a in runs[0].assertions}
