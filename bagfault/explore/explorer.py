"""`bagfault explore`: search a fault space for failures, shrink each to its minimal cause, replay it.

The run loop works in rounds: each active shrink asks for its next run, each
shrunk failure for its replay, and the search fills the round up to the
space's `batch`. A round that holds one shrink step alone (a failure
shrinking while the search waits for it: every other worker would wait too)
also holds a run ahead: the step that shrink asks for next were the step's
run to fail the failure's way, or to pass. The run ahead is kept until the
shrink asks for its candidate, and its outcome is then taken as that step's
run; runs ahead never taken (`unused_runs`) are not counted in the budget,
so runs ahead change how soon a shrink ends, not where. The round runs on
the campaign engines (a local pool or Ray, one process and, in closed loop,
one leased ROS domain per run) and its outcomes are taken in the order of
the round. So what is run depends on the outcomes alone, never on how many
workers ran them: offline, where runs are byte-identical, the same seed
gives the same runs and the same files for any `--workers`. Run 0 is the
baseline (no fault). The search stops proposing when the budget left is
what the shrinks in progress may need.

DIR/runs.jsonl gets each run's record as it finishes; `--resume` takes the
records whose scenario is still the one the loop asks for, so a stopped
exploration continues to the same result. At the end: explore.json,
report.html and failures/ (each failure's original and minimal scenario,
the faulty bag of the minimal's replay).
"""

from __future__ import annotations

import contextlib
import json
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from bagfault import __version__
from bagfault.campaign.engines import make_engine
from bagfault.errors import ExploreError
from bagfault.explore.candidate import Candidate, digest, dump, relocated, scenario_data
from bagfault.explore.draw import Search, Strategy
from bagfault.explore.records import Failure, Outcome, Purpose, RunRecord
from bagfault.explore.shrink import Shrinker, ShrinkMode
from bagfault.io.outputs import Protected, check_output, mark_table, write_atomic
from bagfault.io.regular import read_text
from bagfault.progress import ExploreProgress
from bagfault.spec.yamlnodes import load_located

if TYPE_CHECKING:
    from collections.abc import Callable, Generator, Sequence

    from bagfault.campaign.engines import Job
    from bagfault.spec.model import Explore, Scenario

RESERVE = 30  # runs the search leaves to each shrink in progress
RUN_TIMEOUT = 1800.0  # seconds one run may take
ERRORS = 8  # runs in a row that could not run: the exploration stops (exit 2)
FILES = ('explore.json', 'report.html')


@dataclass
class ExploreOptions:
    """How to explore (the command line's options; `search` and `shrink` are the benchmark's comparisons)."""

    budget: int | None = None  # None: the space's
    seed: int | None = None  # None: the scenario's, else 0
    workers: int | None = None
    ray: str | None = None  # None: the local pool; '': a local Ray instance; else a cluster address
    rate: float = 1.0
    resume: bool = False
    force: bool = False
    save_failures: Path | None = None
    search: Strategy = 'guided'
    shrink: ShrinkMode = 'full'


@dataclass
class ExploreResult:
    """What an exploration found."""

    directory: Path
    mode: Literal['run', 'test']
    budget: int
    seed: int
    runs: list[RunRecord]
    failures: list[Failure]
    engine: str
    ran: int  # runs made now (the others came from runs.jsonl)
    saved: list[Path] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)  # the baseline run's (made now), the clock check's among them

    @property
    def failed(self) -> bool:
        """A failure was found and shrunk: exit code 1."""
        return any(f.state == 'shrunk' for f in self.failures)


@dataclass
class _Request:
    candidate: Candidate
    purpose: Purpose
    failure: Failure | None = None
    ahead: bool = False  # run ahead of its failure's shrink: kept until the shrink asks for its candidate


class _Folder:
    """DIR: runs.jsonl (each run as it ends), explore.json, report.html, failures/."""

    def __init__(self, directory: Path, scenario: Scenario, bags: Sequence[Path]) -> None:
        self.directory = directory
        self.failures = directory / 'failures'
        self.log = directory / 'runs.jsonl'
        self.read = [('the scenario', scenario.source)] if scenario.source is not None else []
        self.read += [('the bag', bag) for bag in bags]

    def check(self, resume: bool, force: bool) -> dict[int, RunRecord]:
        """A folder that holds no exploration (unless resuming) and whose files replace nothing they must not;
        the records a resume starts from."""
        if self.directory.exists() and not self.directory.is_dir():
            raise ExploreError(f"{self.directory}: not a folder (-o names the exploration's folder)")
        if self.log.exists() and not resume:
            raise ExploreError(f'{self.directory}: holds an exploration already (runs.jsonl); --resume continues it, '
                               'or choose another -o')
        self._check_files(force or resume)
        return self._stored() if resume and self.log.exists() else {}

    def _check_files(self, force: bool) -> None:
        """The folder is inside no input folder, and its files replace no input nor (unless forced) a file
        bagfault did not write."""
        protected = Protected.of(self.read)
        holder = protected.holding(self.directory)
        if holder is not None:
            raise ExploreError(f'{self.directory}: would be inside {holder[0]} {holder[1]}; choose another -o')
        if self.directory.is_dir():
            for name in FILES:
                check_output(self.directory / name, 'an exploration file', protected, force=force)

    def _stored(self) -> dict[int, RunRecord]:
        """The runs runs.jsonl holds, by index (a line cut short by a kill left out)."""
        stored: dict[int, RunRecord] = {}
        for line in read_text(self.log).splitlines():
            with contextlib.suppress(ValueError, KeyError, TypeError):
                record = RunRecord.from_json(json.loads(line))
                stored[record.index] = record
        return stored

    def open(self) -> None:
        """Make the folders."""
        try:
            self.failures.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise ExploreError(f'{self.directory}: cannot make the folder: {exc.strerror}') from None

    def keep(self, records: Sequence[RunRecord]) -> None:
        """runs.jsonl as these records (rewritten at a resume that diverged, appended otherwise)."""
        write_atomic(self.log, ''.join(json.dumps(r.to_json(), sort_keys=True) + '\n' for r in records), 'table')

    def append(self, record: RunRecord) -> None:
        """One more finished run."""
        with self.log.open('a', encoding='utf-8') as stream:
            stream.write(json.dumps(record.to_json(), sort_keys=True) + '\n')


def _space(scenario: Scenario, bags: Sequence[Path]) -> Explore:
    """The scenario's fault space; ExploreError without one, or without a bag to explore."""
    if scenario.explore is None:
        raise ExploreError(f'{scenario.name}: no explore: section (the fault space to search)')
    if not bags:
        raise ExploreError(f'{scenario.name}: no bag given, and the scenario names none under `bags:`')
    return scenario.explore


def _budget(budget: int) -> int:
    """The runs in all; ExploreError below one."""
    if budget < 1:
        raise ExploreError(f'--budget {budget}: must be 1 or more')
    return budget


class Explorer:
    """One exploration: the loop of the module's docstring."""

    def __init__(self, scenario: Scenario, bags: Sequence[Path], directory: Path, options: ExploreOptions,
                 progress: ExploreProgress | None = None, *, job: Job) -> None:
        self.scenario = scenario
        self.space: Explore = _space(scenario, bags)
        self.bags = [Path(b) for b in bags]
        self.options = options
        self.job = job  # a run in its process (`bagfault.api.job`)
        self.mode: Literal['run', 'test'] = 'test' if scenario.system is not None else 'run'
        self.confirm = self.space.confirm or (2 if self.mode == 'test' else 1)
        self.budget = _budget(options.budget or self.space.budget)
        self.seed = options.seed if options.seed is not None else scenario.seed or 0
        self.source = (scenario.source or Path('space.yaml')).resolve()
        self.base: dict[str, Any] = load_located(scenario.text).data
        self.folder = _Folder(directory, scenario, self.bags)
        self.progress = progress or ExploreProgress(enabled=False)
        self.search = Search(self.space, self.seed, options.search)
        self.runs: list[RunRecord] = []
        self.failures: list[Failure] = []
        self.shrinks: dict[int, tuple[Generator[Candidate, tuple[int, Outcome], None], Shrinker]] = {}
        self.waiting: dict[int, Candidate] = {}  # failure number -> the candidate its shrink asks to run
        self.sent: dict[int, list[tuple[int, Outcome]]] = {}  # failure number -> what its shrink was told, in order
        self.ahead: dict[int, list[RunRecord]] = {}  # failure number -> its runs ahead not taken yet
        self.replays: list[Failure] = []
        self.search_runs = 0
        self.ran = 0
        self.warnings: list[str] = []  # what the baseline run warned of, when it ran now

    # -- the loop --------------------------------------------------------------------------------------------
    def run(self) -> ExploreResult:
        """Explore until the budget is spent or nothing is left to do; write the results."""
        stored = self.folder.check(self.options.resume, self.options.force)
        engine = make_engine(self.options.workers, self.options.ray, self.job)
        description = getattr(engine, 'description', type(engine).__name__)
        with contextlib.closing(engine), contextlib.closing(self.progress), \
                tempfile.TemporaryDirectory(prefix='bagfault-explore-') as scratch:
            self.folder.open()
            try:
                while True:
                    requests = self._round()
                    if not requests:
                        break
                    stored = self._run_round(engine, requests, stored, Path(scratch))
            finally:
                self._write(description)
        return ExploreResult(self.folder.directory, self.mode, self.budget, self.seed, self.runs, self.failures,
                             description, self.ran, self._save(), self.warnings)

    def _round(self) -> list[_Request]:
        """The next round's runs: the baseline first; then shrink steps, replays, and fresh search."""
        left = self.budget - self.spent
        if not self.runs:
            return [_Request(Candidate(()), 'baseline')]
        if self.waiting and left <= len(self.waiting):  # what is left replays what each shrink has so far
            self._cut_short()
        if left <= 0:
            return []
        requests = [_Request(f.minimal, 'replay', f) for f in self.replays[:left] if f.minimal is not None]
        del self.replays[:left]
        requests += self._shrink_requests(left - len(self.waiting) - len(requests))
        reserve = RESERVE * len(self.waiting)
        while len(requests) < self.space.batch and self.spent + len(requests) < self.budget - reserve:
            candidate, purpose = self.search.propose()
            requests.append(_Request(candidate, purpose))
        lone = requests[0] if len(requests) == 1 else None
        if lone is not None and lone.failure is not None and lone.purpose != 'replay' and self.space.batch > 1 \
                and left - len(self.waiting) > 1:
            requests += self._ahead(lone.failure)
        return requests

    def _ahead(self, failure: Failure) -> list[_Request]:
        """A run ahead of a shrink step that is alone in its round (every other worker would wait): the step the
        shrink asks for next were the step's run to fail the failure's way, else were it to pass, whichever does
        not depend on the run's margins and has not run ahead already."""
        for branch in ('fails', 'passes'):
            following = self._following(failure, branch)
            if following is not None and not any(r.candidate == following[0]
                                                  for r in self.ahead.get(failure.number, [])):
                return [_Request(following[0], following[1], failure, ahead=True)]
        return []

    def _following(self, failure: Failure, branch: Literal['fails', 'passes']) -> tuple[Candidate, Purpose] | None:
        """The candidate (and purpose) a failure's shrink asks for after its waiting one were that run to fail the
        failure's way or to pass, when that is the same whatever the run's margins (guessed with two sets: the
        failure's last failing run's and none, the baseline's and none); None when it is not, or the shrink
        would end."""
        if branch == 'fails':
            kept = self.shrinks[failure.number][1].kept
            outcomes = [Outcome('failed', failure.assertions, kept.margins if kept is not None else {}),
                        Outcome('failed', failure.assertions, {})]
        else:
            outcomes = [Outcome('passed', frozenset(), self.runs[0].outcome.margins),
                        Outcome('passed', frozenset(), {})]
        guesses = {self._twin_asks(failure, outcome) for outcome in outcomes}
        return guesses.pop() if len(guesses) == 1 else None

    def _twin_asks(self, failure: Failure, outcome: Outcome) -> tuple[Candidate, Purpose] | None:
        """What a twin of a failure's shrink, told what the shrink was told and then `outcome`, asks for next (None
        when it ends). The twin sees the failures found now; where the shrink saw others, the guess may miss, and
        its run ahead goes unused."""
        twin = Failure(failure.number, failure.assertions, failure.found_at_run, failure.search_runs,
                       failure.original)
        composite = self._composite(failure)
        shrinker = self._shrinker(twin, self.runs[failure.found_at_run].outcome, lambda: composite)
        steps = shrinker.steps()
        try:
            next(steps)
            for told in self.sent.get(failure.number, []):
                steps.send(told)
            return steps.send((-1, outcome)), shrinker.purpose
        except StopIteration:
            return None

    def _shrink_requests(self, room: int) -> list[_Request]:
        """The shrink steps waiting, those of the smallest failures first: at most half a round of them and
        `room` (each shrink keeps a run for its replay)."""
        shrinking = sorted((self.failures[n - 1] for n in self.waiting), key=lambda f: (len(f.assertions), f.number))
        requests = []
        for failure in shrinking[:max(1, self.space.batch // 2)][:max(0, room)]:
            shrinker = self.shrinks[failure.number][1]
            requests.append(_Request(self.waiting[failure.number], shrinker.purpose, failure))
        return requests

    def _run_round(self, engine: Any, requests: list[_Request], stored: dict[int, RunRecord],
                   scratch: Path) -> dict[int, RunRecord]:
        first = len(self.runs)
        specs, texts, stored = self._specs(requests, stored, scratch)
        results: dict[int, dict[str, Any]] = {}

        def done(position: int, result: dict[str, Any]) -> None:
            index = list(specs)[position]
            results[index] = result
            request = requests[index - first]
            if request.purpose == 'baseline':
                self.warnings = list(result.get('warnings') or [])
            record = self._record(index, request, texts[index - first][0], Outcome.of(result), result.get('seconds'))
            self.folder.append(record)

        if specs:
            engine.run(list(specs.values()), done)
            self.ran += len(specs)
        for number, request in enumerate(requests):
            index = first + number
            if index in results:
                result = results[index]
                record = self._record(index, request, texts[number][0], Outcome.of(result), result.get('seconds'))
            else:
                record = stored[index]
            self._take(record, request)
            output = scratch / f'{index}.mcap'
            output.unlink(missing_ok=True)
        return stored

    def _specs(self, requests: list[_Request], stored: dict[int, RunRecord], scratch: Path,
               ) -> tuple[dict[int, dict[str, Any]], list[tuple[str, Path]], dict[int, RunRecord]]:
        """The round's jobs by run index (those a resumed log holds, unchanged, left out), each request's scenario
        text and file, and the stored runs still valid (from where the resumed log diverges, none)."""
        first = len(self.runs)
        last = first + len(requests)  # a stopped round's log may hold any of its runs, in the order they ended
        specs: dict[int, dict[str, Any]] = {}
        texts: list[tuple[str, Path]] = []
        for number, request in enumerate(requests):
            text, source = self._scenario(request)
            texts.append((text, source))
            index = first + number
            kept = stored.get(index)
            if kept is not None and (kept.scenario_sha256, kept.purpose) == (digest(text), request.purpose):
                continue
            if kept is not None or any(i >= last for i in stored):  # the resumed log diverges here: what
                stored = self._cut_log(stored, first, index)        # follows is run again
            specs[index] = self._spec(text, source, self._output(request, index, scratch),
                                      clock_check=request.purpose == 'baseline')
        return specs, texts, stored

    def _cut_log(self, stored: dict[int, RunRecord], first: int, index: int) -> dict[int, RunRecord]:
        """The stored runs before `index`, and runs.jsonl rewritten to hold only them (the round from `first`)."""
        stored = {i: r for i, r in stored.items() if i < index}
        self.folder.keep([*self.runs, *(stored[i] for i in range(first, index) if i in stored)])
        return stored

    def _record(self, index: int, request: _Request, text: str, outcome: Outcome,
                seconds: float | None) -> RunRecord:
        return RunRecord(index, request.purpose, request.candidate, digest(text), self.seed, outcome, seconds,
                         request.failure.name if request.failure is not None else None)

    # -- what a run tells ------------------------------------------------------------------------------------
    def _take(self, record: RunRecord, request: _Request) -> None:
        self.runs.append(record)
        if record.outcome.status == 'error':
            self._could_not_run(record)
        if request.ahead:  # told to no one until its shrink asks for it: unused, it changes nothing
            assert request.failure is not None
            self.ahead.setdefault(request.failure.number, []).append(record)
            self._take_ahead(request.failure)
        else:
            self._taken(record, request)
        self.progress.update(self.spent, self.budget, sum(f.state != 'unconfirmed' for f in self.failures),
                             self.search.best())

    def _taken(self, record: RunRecord, request: _Request) -> None:
        """A run on the exploration's path, told to the search and to the shrink or replay it was for."""
        if request.purpose in ('search', 'refine'):
            self.search_runs += 1
        self._tell(record, request)
        self.search.observe(record, [f.assertions for f in self.failures])
        if request.failure is not None and request.purpose != 'replay':
            self._step(request.failure, record)

    def _tell(self, record: RunRecord, request: _Request) -> None:
        """A replay's outcome to its failure; a new failure found; one found again by the search counted."""
        outcome = record.outcome
        known = {f.assertions: f for f in self.failures}
        if request.purpose == 'replay':
            assert request.failure is not None
            request.failure.replay = outcome
            request.failure.shrink_runs += 1
        elif outcome.status == 'failed' and outcome.failing not in known:
            self._found(record)
        elif outcome.status == 'failed' and request.purpose in ('search', 'refine'):
            known[outcome.failing].hits += 1

    def _could_not_run(self, record: RunRecord) -> None:
        """A run that could not run decides nothing; the baseline, or ERRORS in a row, end the exploration."""
        why = record.outcome.message or 'no reason given'
        if record.purpose == 'baseline':
            raise ExploreError(f'{self.scenario.name}: the baseline run (no fault) could not run: {why}')
        streak = self.runs[-ERRORS:]
        if len(streak) == ERRORS and all(r.outcome.status == 'error' for r in streak):
            raise ExploreError(f'{self.scenario.name}: {ERRORS} runs in a row could not run (the last, run '
                               f'{record.index}: {why})')

    def _found(self, record: RunRecord) -> None:
        failure = Failure(len(self.failures) + 1, record.outcome.failing, record.index, self.search_runs,
                          record.candidate)
        self.failures.append(failure)
        self._write_scenario(f'{failure.name}.original.yaml', record.candidate,
                             f'bagfault explore: {failure.name}, as first found (run {record.index})')
        shrinker = self._shrinker(failure, record.outcome, lambda: self._composite(failure))
        steps = shrinker.steps()
        self.shrinks[failure.number] = (steps, shrinker)
        self._advance(failure, lambda: next(steps))

    def _shrinker(self, failure: Failure, found: Outcome, composite: Callable[[], str]) -> Shrinker:
        """The shrink of a failure first seen in `found` (a failure's own, or a twin's)."""
        return Shrinker(self.space, failure, found, confirm=self.confirm, mode=self.options.shrink,
                        composite=composite)

    def _composite(self, failure: Failure) -> str:
        """'F3 and F4' when the failure's assertions are the union of those of smaller failures found, each
        confirmed ('' otherwise): two causes at once, each shrunk on its own."""
        parts = [f for f in self.failures if f is not failure and f.assertions < failure.assertions
                 and f.state != 'unconfirmed']
        covered = frozenset().union(*(f.assertions for f in parts)) if parts else frozenset()
        return ' and '.join(f.name for f in parts) if parts and covered == failure.assertions else ''

    def _step(self, failure: Failure, record: RunRecord) -> None:
        steps, _ = self.shrinks[failure.number]
        told = (record.index, record.outcome)
        self.sent.setdefault(failure.number, []).append(told)
        self._advance(failure, lambda: steps.send(told))

    def _advance(self, failure: Failure, step: Any) -> None:
        try:
            self.waiting[failure.number] = step()
        except StopIteration:
            self.waiting.pop(failure.number, None)
            self._unused(failure)
            self._shrunk(failure)
            return
        self._take_ahead(failure)

    def _take_ahead(self, failure: Failure) -> None:
        """The shrink's waiting candidate taken from a run ahead of it, when one ran it; the runs ahead counted
        unused once the shrink ended."""
        waiting = self.waiting.get(failure.number)
        if waiting is None:
            self._unused(failure)
            return
        kept = self.ahead.get(failure.number, [])
        for position, record in enumerate(kept):
            if record.candidate == waiting:
                del kept[position]
                self._taken(record, _Request(record.candidate, record.purpose, failure))
                return

    def _unused(self, failure: Failure) -> None:
        failure.unused_runs += len(self.ahead.pop(failure.number, []))

    @property
    def spent(self) -> int:
        """Runs counted in the budget: every run made but the runs ahead not taken (yet, or ever)."""
        return len(self.runs) - self.unused - sum(len(kept) for kept in self.ahead.values())

    @property
    def unused(self) -> int:
        """Runs ahead that no shrink took (not counted in the budget)."""
        return sum(f.unused_runs for f in self.failures)

    def _shrunk(self, failure: Failure) -> None:
        if failure.state != 'shrunk' or failure.minimal is None:
            return
        self._write_scenario(f'{failure.name}.min.yaml', failure.minimal,
                             f'bagfault explore: {failure.name}, its minimal cause: fails '
                             f'{", ".join(sorted(failure.assertions))}\n'
                             f'faults: {failure.minimal.describe()}')
        self.replays.append(failure)

    def _cut_short(self) -> None:
        """The budget is spent: each shrink in progress ends with the smallest candidate confirmed so far."""
        for number in sorted(self.waiting):
            failure = self.failures[number - 1]
            failure.minimal = self.shrinks[number][1].current
            failure.state = 'shrunk'
            failure.note = 'the budget was spent before the shrink ended: the smallest candidate confirmed so far'
            self._unused(failure)
            self._write_scenario(f'{failure.name}.min.yaml', failure.minimal,
                                 f'bagfault explore: {failure.name}, its smallest cause when the budget was spent\n'
                                 f'faults: {failure.minimal.describe()}')
            self.replays.append(failure)
        self.waiting.clear()

    # -- scenarios and job specs -----------------------------------------------------------------------------
    def _scenario(self, request: _Request) -> tuple[str, Path]:
        """The scenario text of a request, and the file its relative paths are relative to."""
        if request.purpose == 'replay':
            assert request.failure is not None
            path = self.folder.failures / f'{request.failure.name}.min.yaml'
            return read_text(path), path.resolve()
        data = scenario_data(self.base, self.space, request.candidate)
        data['seed'] = self.seed
        return dump(data), self.source

    def _spec(self, text: str, source: Path, output: Path | None, *, clock_check: bool) -> dict[str, Any]:
        """A run's job spec; `clock_check`: the baseline looks once whether the system publishes on wall time
        (a second of held clock at a rate other than 1), the runs after it do not pay that second again."""
        return {'mode': self.mode, 'scenario_text': text, 'scenario_source': str(source),
                'bag': str(self.bags[0].resolve()), 'bags': [str(b.resolve()) for b in self.bags], 'seed': self.seed,
                'remote': None, 'digests': [], 'output': str(output) if output is not None else None,
                'timeout': RUN_TIMEOUT, 'rate': self.options.rate, 'clock_check': clock_check}

    def _output(self, request: _Request, index: int, scratch: Path) -> Path | None:
        if request.purpose == 'replay':
            assert request.failure is not None
            return (self.folder.failures / f'{request.failure.name}.mcap').resolve()
        return scratch / f'{index}.mcap' if self.mode == 'run' else None

    def _write_scenario(self, name: str, candidate: Candidate, header: str) -> None:
        path = self.folder.failures / name
        data = relocated(scenario_data(self.base, self.space, candidate), self.source, path)
        data['seed'] = self.seed
        write_atomic(path, dump(data, f'{header}\nreplay: bagfault {self.mode} {path.name}'), 'yaml')

    def _save(self) -> list[Path]:
        """--save-failures: each minimal scenario where pytest runs it (test_<name>.bagfault.yaml)."""
        target = self.options.save_failures
        if target is None:
            return []
        target.mkdir(parents=True, exist_ok=True)
        saved = []
        for failure in self.failures:
            if failure.minimal is None:
                continue
            path = target / f'test_{failure.name}.bagfault.yaml'
            check_output(path, '--save-failures file', self.folder.read, force=self.options.force)
            data = relocated(scenario_data(self.base, self.space, failure.minimal), self.source, path)
            data['seed'] = self.seed
            write_atomic(path, dump(data, f'bagfault explore: {failure.name}, a regression test (fails until the '
                                          f'cause is fixed)\nfaults: {failure.minimal.describe()}'), 'yaml')
            saved.append(path)
        return saved

    # -- results ---------------------------------------------------------------------------------------------
    def _write(self, engine: str) -> None:
        from bagfault.explore.report import render_report  # noqa: PLC0415

        document = self.describe(engine)
        write_atomic(self.folder.directory / 'explore.json', json.dumps(document, indent=1, sort_keys=True) + '\n',
                     'json')
        if self.folder.log.exists():
            mark_table(self.folder.log)  # appended run by run: marked now it is whole
        write_atomic(self.folder.directory / 'report.html', render_report(document), 'html')

    def describe(self, engine: str) -> dict[str, Any]:
        """explore.json (keys documented in docs/modes/explore.md)."""
        space = self.space
        return {
            'tool': {'name': 'bagfault', 'version': __version__}, 'command': 'explore',
            'scenario': str(self.scenario.source or self.scenario.name), 'mode': self.mode,
            'bags': [str(b) for b in self.bags], 'seed': self.seed, 'budget': self.budget, 'runs_used': len(self.runs),
            'unused_runs': self.unused,
            'confirm': self.confirm, 'batch': space.batch, 'resolution': space.resolution,
            'max_faults': space.max_faults, 'search': self.options.search, 'shrink': self.options.shrink,
            'rate': self.options.rate if self.mode == 'test' else None, 'engine': engine,
            'baseline_warnings': self.warnings,
            'space': [{'id': f.id, 'injector_id': f.injector_id,
                       'dimensions': [{'name': d.name, 'low': d.low, 'high': d.high, 'integer': d.integer}
                                      for d in f.dimensions]} for f in space.faults],
            'assertions': sorted({k for r in self.runs for k in r.outcome.margins}),
            'failures': [f.to_json() for f in self.failures],
            'runs': [r.to_json() for r in self.runs],
        }


def explore(scenario: Scenario, bags: Sequence[Path], directory: Path, options: ExploreOptions,
            progress: ExploreProgress | None = None, *, job: Job) -> ExploreResult:
    """Explore a scenario's fault space (see the module's docstring), each run by `job` in a process of its own
    (`bagfault.api.job`)."""
    return Explorer(scenario, bags, directory, options, progress, job=job).run()
