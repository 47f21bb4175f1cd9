"""Run a campaign: its jobs on an engine, each result stored as it comes, then the tables and the report.

DIR/jobs/<key>.json holds each finished job's result, keyed by the hash of
(bag content, expanded scenario, seed, mode, bagfault version): `resume`
reuses every result whose key is still in the plan, so an interrupted or
edited campaign reruns only what is missing or changed. The tables are
written at the end, each under a temporary name first.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from bagfault import __version__
from bagfault.campaign.edit import expanded, scenario_data
from bagfault.campaign.engines import make_engine
from bagfault.campaign.plan import make_plan, scenario_file
from bagfault.campaign.results import make_table, parquet_available, render_report, write_csv, write_parquet
from bagfault.campaign.search import find_breaking_points
from bagfault.errors import CampaignError
from bagfault.io.outputs import Protected, check_output, write_atomic
from bagfault.io.regular import read_bytes, read_text
from bagfault.log import log
from bagfault.progress import JobProgress

if TYPE_CHECKING:
    from collections.abc import Collection

    from bagfault.campaign.engines import Job as RunJob
    from bagfault.campaign.model import Campaign
    from bagfault.campaign.plan import Job, Plan
    from bagfault.campaign.results import Table
    from bagfault.campaign.search import BreakingPoint


@dataclass
class CampaignResult:
    """What a campaign produced: the plan, the table (sweep and search rows), the breaking points."""

    plan: Plan
    table: Table
    breaking_points: list[BreakingPoint]
    directory: Path
    engine: str
    ran: int  # jobs run now (the others came from DIR/jobs)
    counts: dict[str, int] = field(default_factory=dict)  # sweep jobs by status
    notes: list[str] = field(default_factory=list)  # what was not written, and why
    parquet: bool = True  # results.parquet was written (pyarrow is there)

    @property
    def failed(self) -> bool:
        """True when a sweep job failed or could not run: exit code 1."""
        return bool(self.counts.get('failed') or self.counts.get('error'))


TABLES = ('results.csv', 'results.parquet', 'campaign.json', 'report.html')  # what a campaign writes at the top


class _Store:
    """DIR/jobs: finished results by key; DIR/outputs: the kept output files."""

    def __init__(self, directory: Path, plan: Plan, kept_elsewhere: Collection[str] = ()) -> None:
        self.directory = directory
        self.plan = plan
        self.kept_elsewhere = set(kept_elsewhere)  # outputs/ names already in the bucket the folder stands for
        self.jobs = directory / 'jobs'
        self.outputs = directory / 'outputs'
        self.results: dict[str, dict[str, Any]] = {}

    def check(self, resume: bool, *, force: bool = False) -> None:
        """A folder, one without results unless resuming, and whose files replace nothing the campaign reads
        nor (unless `force`) files bagfault did not write."""
        if self.directory.exists() and not self.directory.is_dir():
            raise CampaignError(f'{self.directory}: not a folder (-o names the campaign folder)')
        stored = list(self.jobs.glob('*.json')) if self.jobs.is_dir() else []
        if stored and not resume:
            raise CampaignError(f'{self.directory}: holds {len(stored)} results of a campaign already; '
                                f'--resume continues it (reruns only what is missing or changed), or choose another -o')
        protected = Protected.of(self._read())
        holder = protected.holding(self.directory)
        if holder is not None:
            raise CampaignError(f'{self.directory}: the campaign folder would be inside {holder[0]} {holder[1]}; '
                                'choose another -o')
        for name in TABLES if self.directory.is_dir() else ():
            check_output(self.directory / name, 'a campaign file', protected, force=force)

    def _read(self) -> list[tuple[str, Path]]:
        """What the campaign reads, named: its file, the scenario, the bags on this machine."""
        campaign = self.plan.campaign
        read = [('the campaign file', campaign.source)] if campaign.source is not None else []
        return [*read, ('the scenario', campaign.scenario),
                *(('the bag', bag) for bag in self.plan.bags if isinstance(bag, Path))]

    def open(self, resume: bool) -> None:
        """Make the folders; load what is there when resuming."""
        stored = sorted(self.jobs.glob('*.json')) if resume and self.jobs.is_dir() else []
        try:
            for folder in (self.jobs, self.outputs):
                folder.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise CampaignError(f'{self.directory}: cannot make the campaign folder: {exc.strerror}') from None
        for path in stored:
            try:
                self.results[path.stem] = json.loads(read_text(path))['result']
            except (OSError, ValueError, KeyError, TypeError):
                continue  # unreadable: the job runs again

    def output(self, job: Job) -> Path:
        """Where the job writes its output file."""
        return (self.outputs / f'{job.key}.mcap').resolve()

    def put(self, job: Job, result: dict[str, Any]) -> None:
        """Keep the result (and the output, by the keep policy)."""
        keep = self.plan.campaign.keep
        path = self.output(job)
        if keep == 'none' or (keep == 'failed' and result['status'] == 'passed'):
            path.unlink(missing_ok=True)
        self.results[job.key] = result
        write_atomic(self.jobs / f'{job.key}.json', json.dumps({'job': job.index, 'bag': str(job.bag),
                                                                 'values': job.values, 'seed': job.seed,
                                                                 'result': result}, sort_keys=True, indent=1), 'json')

    def kept(self, job: Job) -> str:
        """The job's output relative to the folder, if it is kept."""
        path = self.output(job)
        here = path.exists() or path.name in self.kept_elsewhere
        return str(path.relative_to(self.directory.resolve())) if here else ''


def run_campaign(campaign: Campaign, directory: Path, *, job: RunJob, workers: int | None = None,
                 ray: str | None = None, resume: bool = False, progress: JobProgress | None = None,
                 force: bool = False, kept_elsewhere: Collection[str] = ()) -> CampaignResult:
    """Every job of the plan (and the search rounds) run by `job` in a process of its own (`bagfault.api.job`),
    then the tables and the report in `directory`."""
    plan = make_plan(campaign)
    store = _Store(directory, plan, kept_elsewhere)
    store.check(resume, force=force)
    if not parquet_available():  # said before the jobs, not after an hour of them
        log.warning('pyarrow is not installed: results.csv and report.html will hold the table, not '
                    'results.parquet (pip install "bagfault[campaign]")')
    bar = progress or JobProgress(enabled=False)
    ran = 0
    # the engine before any folder is made: an engine that cannot start leaves nothing
    with contextlib.closing(make_engine(workers, ray, job)) as engine, contextlib.closing(bar):
        store.open(resume)

        def run_jobs(jobs: list[Job]) -> dict[str, dict[str, Any]]:
            nonlocal ran
            todo = list({job.key: job for job in jobs if job.key not in store.results}.values())
            bar.add(len({j.key for j in jobs}), len({j.key for j in jobs}) - len(todo))
            bar.show(bar.line())

            def done(i: int, result: dict[str, Any]) -> None:
                store.put(todo[i], result)
                bar.finished(result['status'])

            engine.run([job.spec(campaign, store.output(job), plan.file_digests) for job in todo], done)
            ran += len(todo)
            return {job.key: store.results[job.key] for job in jobs}

        run_jobs(plan.jobs)
        points, search_jobs = ([], []) if campaign.search is None else \
            find_breaking_points(plan, run_jobs, len(plan.jobs))
    plan.jobs += search_jobs
    _, scenario = expanded(scenario_data(read_text(campaign.scenario)), {}, campaign.scenario)
    table = make_table(plan, [(job, store.results[job.key], store.kept(job)) for job in plan.jobs],
                       [a.id for a in scenario.assertions])
    description = getattr(engine, 'description', type(engine).__name__)
    _write_scenarios(directory, plan)
    write_csv(table, directory / 'results.csv')
    described = {**plan.describe(), 'breaking_points': [point.describe() for point in points]}
    write_atomic(directory / 'campaign.json', json.dumps(described, indent=1, sort_keys=True) + '\n', 'json')
    write_atomic(directory / 'report.html', render_report(plan, table, points, description), 'html')
    notes = _write_parquet(campaign, table, directory)
    rows = table.sweep_rows()
    counts = {s: sum(r['status'] == s for r in rows) for s in ('passed', 'failed', 'error')}
    return CampaignResult(plan, table, points, directory, description, ran, counts, notes, not notes)


def _write_parquet(campaign: Campaign, table: Table, directory: Path) -> list[str]:
    """results.parquet with what made it (campaign, version, digests of the files); without pyarrow, a note
    saying results.csv holds the table instead."""
    if not parquet_available():  # the jobs ran: their table is in results.csv and the report, whatever is missing
        return ['results.parquet not written: pyarrow is not installed (pip install "bagfault[campaign]"); '
                'results.csv holds the same table']
    made = {'campaign': campaign.name, 'version': __version__,
            'scenario_sha256': hashlib.sha256(read_bytes(campaign.scenario)).hexdigest()}
    if campaign.source is not None:
        made['campaign_sha256'] = hashlib.sha256(read_bytes(campaign.source)).hexdigest()
    write_parquet(table, directory / 'results.parquet', made)
    return []


def _write_scenarios(directory: Path, plan: Plan) -> None:
    """DIR/scenarios/<sha256[:16]>/<scenario name>: each expanded scenario once (campaign.json names it per job)."""
    for job in {job.scenario_text: job for job in plan.jobs}.values():
        path = directory / scenario_file(job, plan.campaign)
        if not path.exists():
            path.parent.mkdir(parents=True, exist_ok=True)
            write_atomic(path, job.scenario_text, 'yaml')
