"""Read and check a campaign file: every problem with its line and column, as for scenarios."""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

from bagfault.campaign.edit import PathError, expanded, scenario_data
from bagfault.campaign.model import Campaign, Search, Until
from bagfault.errors import CampaignError, ScenarioError, one_line
from bagfault.io.regular import read_text
from bagfault.spec import sections
from bagfault.spec.reader import Read, Reader
from bagfault.spec.yamlnodes import YamlSyntaxError, format_path, load_located

if TYPE_CHECKING:
    from bagfault.spec.model import Scenario
    from bagfault.spec.yamlnodes import LocatedYaml, PathKey

MAX_RANGE = 100_000


class _Problems:
    def __init__(self, name: str, located: LocatedYaml) -> None:
        self.name = name
        self.located = located
        self.lines: list[str] = []
        self._places: list[tuple[int, int]] = []

    def add(self, path: PathKey, message: str) -> None:
        where = self.located.where(path)
        self.lines.append(f'{self.name}:{where}: {format_path(path) or "<top>"}: {message}')
        line, _, column = where.partition(':')
        self._places.append((int(line), int(column or 0)))

    def in_file_order(self) -> list[str]:
        """The problems by line and column (as a scenario's are listed)."""
        return [text for _, text in sorted(zip(self._places, self.lines, strict=True), key=lambda x: x[0])]


def load_campaign(path: str | Path) -> Campaign:
    """The campaign, checked (its scenario and every swept path included); CampaignError with all problems."""
    file = Path(path)
    text, located = _located(file)
    problems = _Problems(str(file), located)
    data = located.data
    if not isinstance(data, dict):
        raise CampaignError(f'{file}: a campaign file is a mapping (campaign, scenario, bags, sweep, ...)')
    read = Reader(problems.add).read(sections.CAMPAIGN, data, ())
    assert read is not None
    campaign = _campaign(read, file, text)
    _bags(read.get('bags'), campaign, problems)
    campaign.sweep = {str(key): values for key, raw in read.get('sweep', {}).items()
                      if (values := _values(raw, ('sweep', key), problems))}
    if 'seeds' in data:
        _seeds(data['seeds'], campaign, problems)
    _design(read.get('design'), campaign, problems)
    if 'search' in read:
        campaign.search = _search(read.get('search'), problems)
    if not problems.lines:
        _check_scenario(campaign, problems, seeded='seeds' in data)
    if problems.lines:
        raise CampaignError('\n'.join(problems.in_file_order()))
    return campaign


def _campaign(read: Read, file: Path, text: str) -> Campaign:
    """The campaign's name (the file's by default), scenario (beside the file), mode, keep and timeout."""
    campaign = Campaign(name=str(read.get('campaign') or file.stem), scenario=file.parent / 'missing',
                        source=file, text=text)
    if 'scenario' in read:
        campaign.scenario = file.parent / read.get('scenario')
    campaign.mode = read.get('mode', campaign.mode)
    campaign.keep = read.get('keep', campaign.keep)
    campaign.timeout = read.get('timeout', campaign.timeout)
    return campaign


def _located(file: Path) -> tuple[str, LocatedYaml]:
    """The file's text and its YAML with places; CampaignError naming the file when it cannot be read or parsed."""
    try:
        text = read_text(file)
    except OSError as exc:
        raise CampaignError(f'{file}: cannot read the campaign file: {exc.strerror}') from None
    try:
        return text, load_located(text)
    except YamlSyntaxError as exc:
        raise CampaignError(f'{file}: {one_line(exc)}') from None


def _bags(bags: list[Any] | None, campaign: Campaign, problems: _Problems) -> None:
    """The bags (paths, globs, bucket URLs): a non-empty list of texts."""
    if bags is None:
        return
    if not bags or not all(isinstance(b, str) and b for b in bags):
        problems.add(('bags',), f'must be {sections.CAMPAIGN.key("bags").what}')  # type: ignore[union-attr]
    else:
        campaign.bags = list(bags)


def _seeds(node: object, campaign: Campaign, problems: _Problems) -> None:
    """The seeds: a list or a range of integers from 0 to 2^64 - 1."""
    seeds = _values(node, ('seeds',), problems, integers=True)
    if seeds and not all(isinstance(s, int) and 0 <= s < 2**64 for s in seeds):
        problems.add(('seeds',), 'seeds are integers from 0 to 2^64 - 1')
    elif seeds:
        campaign.seeds = [int(s) for s in seeds]


def _values(node: object, path: PathKey, problems: _Problems, *, integers: bool = False) -> list[Any]:
    """A list, or {range: [start, stop, step]} (stop excluded for integers, included within a tolerance else)."""
    if isinstance(node, list) and node:
        return list(node)
    if isinstance(node, dict) and set(node) == {'range'}:
        return _range(node['range'], (*path, 'range'), problems, integers=integers)
    problems.add(path, 'must be a list of values or {range: [start, stop, step]}')
    return []


def _range(spec: object, path: PathKey, problems: _Problems, *, integers: bool) -> list[Any]:
    """[start, stop] or [start, stop, step] as its values (at most MAX_RANGE); [] and a problem when it is not."""
    if not isinstance(spec, list) or not 2 <= len(spec) <= 3 or not all(_finite_number(v) for v in spec):
        problems.add(path, 'must be [start, stop] or [start, stop, step]')
        return []
    start, stop = spec[0], spec[1]
    step = spec[2] if len(spec) == 3 else 1
    if step <= 0 or (stop - start) / step > MAX_RANGE:
        problems.add(path, f'step must be above 0 and give at most {MAX_RANGE} values')
        return []
    return _stepped(start, stop, step, integers=integers or all(isinstance(v, int) for v in spec))


def _stepped(start: float, stop: float, step: float, *, integers: bool) -> list[Any]:
    """From start by step: integers before stop, or numbers up to stop within a tolerance (to 12 decimals)."""
    if integers:
        return list(range(int(start), int(stop), int(step)))
    count = math.floor((stop - start) / step + 1e-9) + 1
    return [round(start + i * step, 12) for i in range(count)]


def _finite_number(value: object) -> bool:
    """True for an int or float (not a bool) that is finite."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _design(node: object, campaign: Campaign, problems: _Problems) -> None:
    if node == 'grid':
        return
    if isinstance(node, dict) and set(node) == {'random'} and isinstance(node['random'], dict):
        samples, seed = node['random'].get('samples'), node['random'].get('seed', 0)
        if isinstance(samples, int) and not isinstance(samples, bool) and 0 < samples <= MAX_RANGE \
                and isinstance(seed, int) and not isinstance(seed, bool):
            campaign.design, campaign.samples, campaign.design_seed = 'random', samples, seed
            return
        problems.add(('design', 'random'), 'needs samples (1 to 100000) and an integer seed')
        return
    problems.add(('design',), 'must be grid or {random: {samples: N, seed: S}}')


def _search(node: object, problems: _Problems) -> Search | None:
    reader = Reader(problems.add)
    read = reader.read(sections.SEARCH, node, ('search',))
    if read is None:
        return None
    until = reader.read(sections.UNTIL, read.get('until'), ('search', 'until')) if 'until' in read else None
    if not _complete(read) or until is None or 'assertion' not in until or 'state' not in until:
        return None
    low, high, tolerance = (float(read.get(k)) for k in ('low', 'high', 'tolerance'))
    if not low < high:
        problems.add(('search',), 'needs low < high')
        return None
    return Search(read.get('parameter'), low, high, tolerance, Until(until.get('assertion'), until.get('state')),
                  read.get('repeat'))


def _complete(read: Read) -> bool:
    """True when the search section was read whole: nothing refused, every required key there."""
    return not read.refused and all(k.name in read for k in sections.SEARCH.keys if k.required)


def _check_scenario(campaign: Campaign, problems: _Problems, *, seeded: bool) -> None:
    """The scenario loads, and every swept path takes its first and last value (as it would in a job)."""
    try:
        text = read_text(campaign.scenario)
    except OSError as exc:
        problems.add(('scenario',), f'cannot read {campaign.scenario}: {exc.strerror}')
        return
    try:
        data = scenario_data(text)
        _, scenario = expanded(data, {}, campaign.scenario)
    except (ScenarioError, YamlSyntaxError) as exc:
        problems.add(('scenario',), f'{campaign.scenario} does not load: {one_line(exc)}')
        return
    if not seeded:
        campaign.seeds = [scenario.seed if scenario.seed is not None else 0]  # the scenario's own seed
    if campaign.mode == 'test' and scenario.system is None:
        problems.add(('mode',), 'test needs a system_under_test section in the scenario')
    _check_paths(campaign, data, problems)
    if campaign.search is not None:
        _check_until(campaign.search, scenario, problems)


def _check_until(search: Search, scenario: Scenario, problems: _Problems) -> None:
    """The assertion a search waits for is in the scenario."""
    ids = {a.id for a in scenario.assertions}
    if search.until.assertion not in ids:
        problems.add(('search', 'until', 'assertion'), f'no assertion {search.until.assertion!r} in the scenario '
                                                        f'(there are: {", ".join(sorted(ids)) or "none"})')


def _check_paths(campaign: Campaign, data: dict[str, Any], problems: _Problems) -> None:
    """Every swept path (and the searched one) takes its first and last value."""
    paths = dict(campaign.sweep)
    if campaign.search is not None:
        paths[campaign.search.parameter] = [campaign.search.low, campaign.search.high]
    for path, values in paths.items():
        key: PathKey = ('search', 'parameter') if campaign.search is not None and path == \
            campaign.search.parameter and path not in campaign.sweep else ('sweep', path)
        for value in {id(v): v for v in (values[0], values[-1])}.values():
            problem = _edit_problem(data, path, value, campaign.scenario)
            if problem:
                problems.add(key, problem)
                break


def _edit_problem(data: dict[str, Any], path: str, value: object, scenario: Path) -> str:
    """Why setting `path` to `value` in the scenario fails ('' when it works)."""
    try:
        expanded(data, {path: value}, scenario)
    except PathError as exc:
        return str(exc)
    except ScenarioError as exc:
        return f'{value!r} makes the scenario invalid: {exc.problems[0].message}'
    return ''
