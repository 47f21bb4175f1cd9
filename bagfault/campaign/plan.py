"""A campaign expanded into jobs: bag x sweep point x seed, each with the hash its result is stored under."""

from __future__ import annotations

import glob
import hashlib
import itertools
import json
import math
import random
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from bagfault import __version__
from bagfault.campaign.edit import expanded, scenario_data
from bagfault.errors import CampaignError, InputError
from bagfault.io.objects import RemoteBag, is_remote, list_bags
from bagfault.io.regular import read_text
from bagfault.io.sources import digests_of, fingerprint, remember_digests

if TYPE_CHECKING:
    from bagfault.campaign.model import Campaign

Kind = Literal['sweep', 'search']
Bag = Path | RemoteBag  # a local file or folder, or a bag in a bucket


@dataclass(frozen=True)
class Job:
    """One run: a bag, swept values, a seed, and the scenario they make."""

    index: int
    bag: Bag
    values: dict[str, Any]
    seed: int
    scenario_text: str
    key: str  # sha256 of bag content, expanded scenario, seed, mode, sample and bagfault version
    kind: Kind = 'sweep'
    sample: int = 0  # which run of the same value and seed (a search's repeat)

    @property
    def scenario_sha(self) -> str:
        """sha256 of the expanded scenario (as in the output's provenance)."""
        return hashlib.sha256(self.scenario_text.encode()).hexdigest()

    def spec(self, campaign: Campaign, output: Path | None,
             digests: dict[str, list[list[Any]]] | None = None) -> dict[str, Any]:
        """What a worker needs (plain JSON); `digests` the plan's file digests by bag."""
        digests = digests or {}
        return {'mode': campaign.mode, 'scenario_text': self.scenario_text,
                'scenario_source': str(campaign.scenario.resolve()),
                'bag': str(self.bag) if isinstance(self.bag, RemoteBag) else str(self.bag.resolve()), 'seed': self.seed,
                'remote': self.bag.to_dict() if isinstance(self.bag, RemoteBag) else None,
                'digests': digests.get(str(self.bag), []),
                'output': str(output) if output else None,
                'timeout': campaign.timeout}


@dataclass
class Plan:
    """Every job of the sweep, in table order; the bags with their fingerprints."""

    campaign: Campaign
    bags: list[Bag]
    jobs: list[Job] = field(default_factory=list)
    fingerprints: dict[str, str] = field(default_factory=dict)  # bag -> digest of its files
    file_digests: dict[str, list[list[Any]]] = field(default_factory=dict)  # bag -> [stat key..., BLAKE3] per file

    def describe(self) -> dict[str, Any]:
        """campaign.json: the expanded plan with hashes."""
        c = self.campaign
        return {
            'campaign': c.name, 'scenario': str(c.scenario), 'mode': c.mode, 'bagfault': __version__,
            'bags': [{'path': str(b), 'digest': self.fingerprints[str(b)]} for b in self.bags],
            'sweep': c.sweep, 'seeds': c.seeds, 'design': c.design, 'samples': c.samples, 'keep': c.keep,
            'search': asdict(c.search) if c.search is not None else None,
            'jobs': [{'index': j.index, 'bag': str(j.bag), 'values': j.values, 'seed': j.seed, 'key': j.key,
                      'kind': j.kind, 'scenario': scenario_file(j, c), **({'sample': j.sample} if j.sample else {})}
                     for j in self.jobs],
        }


    def summary(self) -> str:
        """--dry-run: the plan's size and its jobs, one line each."""
        c = self.campaign
        sizes = ' x '.join([f'{len(self.bags)} bags', *(f'{len(v)} {k}' for k, v in c.sweep.items()),
                            f'{len(c.seeds)} seeds'])
        lines = [f'campaign {c.name}: {len(self.jobs)} jobs ({sizes}'
                 + (f', random design of {c.samples} points' if c.design == 'random' else '') + f'), mode {c.mode}']
        if c.search is not None:
            lines.append(f'then a search of {c.search.parameter} in [{c.search.low:g}, {c.search.high:g}] to '
                         f'{c.search.tolerance:g}, {c.search.samples(c.mode)} samples per value and seed: at most '
                         f'{search_jobs(c)} jobs per bag')
        for job in self.jobs:
            values = ', '.join(f'{k}={v!r}' for k, v in job.values.items())
            lines.append(f'  {job.index:>5}  {job.bag}  {values}  seed={job.seed}  key={job.key}')
        return '\n'.join(lines)


def scenario_file(job: Job, campaign: Campaign) -> str:
    """Where the campaign folder keeps a job's expanded scenario, under the original file name (which the
    output's provenance records), so `bagfault run` on it by hand writes the job's output byte for byte."""
    return f'scenarios/{job.scenario_sha[:16]}/{campaign.scenario.name}'


def search_jobs(campaign: Campaign) -> int:
    """The most jobs the bisection runs for one bag: both ends, then one value per halving."""
    s = campaign.search
    assert s is not None
    halvings = max(0, math.ceil(math.log2((s.high - s.low) / s.tolerance)))
    return (2 + halvings) * len(campaign.seeds) * s.samples(campaign.mode)


def bags_of(campaign: Campaign) -> list[Bag]:
    """Each glob expanded (sorted), relative to the campaign file, or listed in its bucket; CampaignError for a
    glob that finds nothing or a store that refuses."""
    base = campaign.source.parent if campaign.source is not None else Path('.')
    found: list[Bag] = []
    for pattern in campaign.bags:
        matches = _matches(campaign, pattern, base)
        if not matches:
            raise CampaignError(f'{campaign.source}: bags: {pattern!r} matches no file or folder')
        found += [m for m in matches if m not in found]
    return found


def _matches(campaign: Campaign, pattern: str, base: Path) -> list[Bag]:
    """The bags a bucket URL lists, or a glob (relative to `base`) finds, sorted."""
    if is_remote(pattern):
        try:
            return list(list_bags(pattern))
        except InputError as exc:
            raise CampaignError(f'{campaign.source}: bags: {exc}') from None
    full = pattern if Path(pattern).is_absolute() else str(base / pattern)
    return [Path(m) for m in sorted(m.rstrip('/') for m in glob.glob(full))]


def points(campaign: Campaign) -> list[dict[str, Any]]:
    """Sweep points: the full grid in file order, or `samples` points of it drawn with the design seed."""
    keys = list(campaign.sweep)
    axes = [campaign.sweep[k] for k in keys]
    total = grid_size(campaign)
    if campaign.design == 'random' and campaign.samples < total:  # indices of the grid, never the grid itself
        picked = sorted(random.Random(campaign.design_seed).sample(range(total), campaign.samples))
        return [dict(zip(keys, _grid_point(axes, i), strict=True)) for i in picked]
    return [dict(zip(keys, values, strict=True)) for values in itertools.product(*axes)]


def _grid_point(axes: list[list[Any]], index: int) -> tuple[Any, ...]:
    """The `index`th point of itertools.product(*axes) (the last axis varies fastest)."""
    values = []
    for axis in reversed(axes):
        index, position = divmod(index, len(axis))
        values.append(axis[position])
    return tuple(reversed(values))


def bag_digest(bag: Bag) -> str:
    """One digest over the bag's files (names, sizes, BLAKE3 digests; in a bucket, names, sizes and ETags)."""
    if isinstance(bag, RemoteBag):
        return bag.digest
    return hashlib.sha256(json.dumps([asdict(f) for f in fingerprint(bag)], sort_keys=True).encode()).hexdigest()


def job_key(bag_sha: str, scenario_text: str, seed: int, mode: str, sample: int = 0) -> str:
    """Where a job's result is stored: changes when the bag, the expanded scenario, the seed, the sample or bagfault
    does."""
    fields = {'bag': bag_sha, 'scenario': scenario_text, 'seed': seed, 'mode': mode, 'version': __version__}
    if sample:
        fields['sample'] = sample
    text = json.dumps(fields, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:24]


MAX_JOBS = 100_000  # sweep jobs a campaign may plan: each is a run; more is a mistake (or a random design's job)


def grid_size(campaign: Campaign) -> int:
    """How many points the sweep's full grid has."""
    return math.prod(len(v) for v in campaign.sweep.values())


def _check_size(campaign: Campaign, bags: list[Bag]) -> None:
    """CampaignError when the sweep would make more than MAX_JOBS jobs."""
    size = min(campaign.samples, grid_size(campaign)) if campaign.design == 'random' else grid_size(campaign)
    count = len(bags) * size * len(campaign.seeds)
    if count > MAX_JOBS:
        parts = ' x '.join([f'{len(bags)} bags', *(f'{len(v)} {k}' for k, v in campaign.sweep.items()),
                            f'{len(campaign.seeds)} seeds'])
        raise CampaignError(f'{campaign.source}: the sweep makes {count:,} jobs ({parts}), more than {MAX_JOBS:,}: '
                            'give fewer values, or design: {random: {samples: N, seed: S}}')


def make_plan(campaign: Campaign) -> Plan:
    """The sweep's jobs, bag-major, then point, then seed; CampaignError before anything is expanded or hashed
    when they would be more than MAX_JOBS."""
    bags = bags_of(campaign)
    _check_size(campaign, bags)
    plan = Plan(campaign, bags)
    for bag in bags:  # each bag hashed once: the jobs are handed the digests (a job on this machine reads no bag twice)
        if isinstance(bag, Path):
            known = digests_of(bag)
            remember_digests(known)
            plan.file_digests[str(bag)] = [[*key, digest] for key, digest in known.items()]
        plan.fingerprints[str(bag)] = bag_digest(bag)
    data = scenario_data(read_text(campaign.scenario))
    texts = [(point, expanded(data, point, campaign.scenario)[0]) for point in points(campaign)]
    for bag in bags:
        for point, text in texts:
            for seed in campaign.seeds:
                key = job_key(plan.fingerprints[str(bag)], text, seed, campaign.mode)
                plan.jobs.append(Job(len(plan.jobs), bag, point, seed, text, key))
    return plan


def search_job(plan: Plan, index: int, bag: Bag, value: float, seed: int, sample: int = 0) -> Job:
    """A job of the bisection: the searched parameter at `value` (with the first sweep point's other values), the
    `sample`th run of that value and seed."""
    campaign = plan.campaign
    assert campaign.search is not None
    data = scenario_data(read_text(campaign.scenario))
    values = {campaign.search.parameter: value}
    text = expanded(data, values, campaign.scenario)[0]
    return Job(index, bag, values, seed, text,
               job_key(plan.fingerprints[str(bag)], text, seed, campaign.mode, sample), 'search', sample)
