"""What an exploration keeps: each run's outcome, each failure with its shrink path, as plain JSON."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

from bagfault.explore.candidate import Candidate

Purpose = Literal['baseline', 'search', 'refine', 'confirm', 'shrink', 'replay']
Status = Literal['passed', 'failed', 'error']


@dataclass(frozen=True)
class Outcome:
    """What one run told: its status, the assertions that did not pass, every margin."""

    status: Status
    failing: frozenset[str]
    margins: dict[str, tuple[float | None, str]]  # assertion -> (margin, unit)
    message: str = ''

    @classmethod
    def of(cls, result: dict[str, Any]) -> Outcome:
        """From a job's result (campaign.job.run_job): `error` when it could not run."""
        assertions = result.get('assertions') or {}
        if result.get('status') == 'error':
            return cls('error', frozenset(), {}, str(result.get('message', '')))
        failing = frozenset(k for k, a in assertions.items() if a.get('state') != 'passed')
        margins = {k: (a.get('margin'), str(a.get('margin_unit') or '')) for k, a in assertions.items()}
        return cls('failed' if failing else 'passed', failing, margins, str(result.get('message', '')))

    def to_json(self) -> dict[str, Any]:
        """{status, failing, margins: {id: [margin, unit]}, message}."""
        return {'status': self.status, 'failing': sorted(self.failing),
                'margins': {k: [m, u] for k, (m, u) in sorted(self.margins.items())}, 'message': self.message}

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> Outcome:
        """The outcome `to_json` wrote."""
        return cls(data['status'], frozenset(data['failing']),
                   {k: (None if m is None else float(m), str(u)) for k, (m, u) in data['margins'].items()},
                   str(data.get('message', '')))


@dataclass(frozen=True)
class RunRecord:
    """One run of the exploration."""

    index: int
    purpose: Purpose
    candidate: Candidate
    scenario_sha256: str
    seed: int
    outcome: Outcome
    seconds: float | None = None
    failure: str | None = None  # the failure this run confirmed, shrank or replayed

    def to_json(self) -> dict[str, Any]:
        """One line of runs.jsonl and one entry of explore.json's `runs`."""
        return {'index': self.index, 'purpose': self.purpose, 'faults': self.candidate.to_json(),
                'scenario_sha256': self.scenario_sha256, 'seed': self.seed, **self.outcome.to_json(),
                'seconds': self.seconds, 'failure': self.failure}

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> RunRecord:
        """The record `to_json` wrote."""
        return cls(int(data['index']), data['purpose'], Candidate.from_json(data['faults']),
                   str(data['scenario_sha256']), int(data['seed']), Outcome.from_json(data), data.get('seconds'),
                   data.get('failure'))


@dataclass(frozen=True)
class ShrinkStep:
    """One step of a shrink: what changed, whether the smaller candidate still failed the same way."""

    run: int  # its first run
    change: str
    candidate: Candidate
    kept: bool
    runs: int

    def to_json(self) -> dict[str, Any]:
        """{run, change, faults, kept, runs}."""
        return {'run': self.run, 'change': self.change, 'faults': self.candidate.to_json(), 'kept': self.kept,
                'runs': self.runs}


@dataclass
class Failure:
    """A set of failing assertions and the smallest cause found for it."""

    number: int
    assertions: frozenset[str]
    found_at_run: int
    search_runs: int  # search runs made until the first run that failed so
    original: Candidate
    minimal: Candidate | None = None
    state: Literal['shrinking', 'unconfirmed', 'shrunk'] = 'shrinking'
    steps: list[ShrinkStep] = field(default_factory=list)
    shrink_runs: int = 0  # runs spent on it after it was found: confirmations, shrink steps, the replay
    unused_runs: int = 0  # runs made ahead of its shrink (a step for either outcome) that its path did not take
    confirmations: int = 0  # runs that repeated a candidate that had failed once (the original's, each step's)
    hits: int = 1  # search runs that failed this way
    replay: Outcome | None = None
    note: str = ''

    @property
    def name(self) -> str:
        """'F2_turn_limit' (its number and assertions), the stem of its files."""
        return f'F{self.number}_' + '+'.join(sorted(self.assertions))[:80]

    def to_json(self) -> dict[str, Any]:
        """explore.json's entry."""
        return {'name': self.name, 'assertions': sorted(self.assertions), 'found_at_run': self.found_at_run,
                'search_runs_to_find': self.search_runs, 'state': self.state, 'hits': self.hits,
                'original': f'failures/{self.name}.original.yaml', 'original_faults': self.original.to_json(),
                'minimal': f'failures/{self.name}.min.yaml' if self.minimal is not None else None,
                'minimal_faults': self.minimal.to_json() if self.minimal is not None else None,
                'faulty_bag': f'failures/{self.name}.mcap' if self.replay is not None else None,
                'shrink_runs': self.shrink_runs, 'unused_runs': self.unused_runs, 'confirmations': self.confirmations,
                'replay': self.replay.to_json() if self.replay is not None else None,
                'steps': [s.to_json() for s in self.steps], 'note': self.note}
