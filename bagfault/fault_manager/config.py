"""The `fault_manager:` section of a scenario and the `report:` block of faults.

    fault_manager:
      confirmation_threshold: -3        # debounce (see fault_manager.md)
      healing_enabled: true
      healing_threshold: 3
      auto_confirm_after_sec: 0
      overrides: [{source: /powertrain, confirmation_threshold: -1}]
      diagnostics: {topic: /diagnostics, codes: {'imu: driver': IMU_DRIVER}}
      conditions:
        - {topic: /imu, when: {field: linear_acceleration.z, above: 15.0}, code: IMU_SPIKE, severity: ERROR}
      correlation: {enabled: true, default_window_ms: 500, patterns: {...}, rules: [...]}
      snapshots: {default_topics: [/odom], duration_sec: 5.0, duration_after_sec: 1.0}
      clear: [{code: IMU_SPIKE, at: 12.0}]

Every problem is reported through `problem(path, message)` with its place.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, TypeVar

import re2  # type: ignore[import-untyped]

from bagfault.fault_manager.correlation import CorrelationConfig, no_warning, parse_correlation
from bagfault.fault_manager.model import severity_value, valid_code
from bagfault.spec import sections
from bagfault.spec.reader import Read, Reader

if TYPE_CHECKING:
    from bagfault.spec.model import Scenario

Problem = Callable[[tuple[Any, ...], str], None]
T = TypeVar('T')
PREFIX = ('fault_manager',)


@dataclass(frozen=True)
class Thresholds:
    """Debounce parameters (normalized: confirmation <= -1, healing >= 0)."""

    confirmation_threshold: int = -1
    healing_enabled: bool = False
    healing_threshold: int = 3
    auto_confirm_after_sec: float = 0.0


@dataclass(frozen=True)
class Condition:
    """FAILED while a field condition holds on a topic, PASSED otherwise."""

    topic: str
    field: str
    code: str
    severity: int
    source: str
    above: float | None = None
    below: float | None = None
    outside: tuple[float, float] | None = None
    not_finite: bool = False

    def describe(self) -> str:
        """'linear_acceleration.z above 15' and the like."""
        if self.above is not None:
            return f'{self.field} above {self.above:g}'
        if self.below is not None:
            return f'{self.field} below {self.below:g}'
        if self.outside is not None:
            return f'{self.field} outside [{self.outside[0]:g}, {self.outside[1]:g}]'
        return f'{self.field} not finite'


@dataclass(frozen=True)
class InjectedReport:
    """`report:` of a scenario fault."""

    fault_id: str
    code: str
    severity: int
    source: str
    period: float | None = None


@dataclass(frozen=True)
class Clear:
    """A ClearFault call at bag time `at` (seconds)."""

    code: str
    at: float
    skip_correlation_auto_clear: bool = False


@dataclass(frozen=True)
class Snapshots:
    """Freeze frame and black box capture on confirmation."""

    enabled: bool = True
    default_topics: tuple[str, ...] = ()
    fault_specific: dict[str, tuple[str, ...]] = field(default_factory=dict)
    patterns: tuple[tuple[str, tuple[str, ...]], ...] = ()
    duration_sec: float = 5.0
    duration_after_sec: float = 1.0
    recapture_cooldown_sec: float = 60.0

    def topics_for(self, code: str) -> tuple[str, ...]:
        """Fault-specific list, then the first matching regex in sorted order, then the defaults."""
        if code in self.fault_specific:
            return self.fault_specific[code]
        for pattern, topics in self.patterns:
            if snapshot_regex(pattern).fullmatch(code):
                return topics
        return self.default_topics

    def all_topics(self) -> set[str]:
        """Every topic any code could capture."""
        topics = set(self.default_topics)
        for values in self.fault_specific.values():
            topics.update(values)
        for _, values in self.patterns:
            topics.update(values)
        return topics


@dataclass
class FaultManagerConfig:
    """Everything the fault manager oracle needs."""

    thresholds: Thresholds = field(default_factory=Thresholds)
    overrides: list[tuple[str, Thresholds]] = field(default_factory=list)
    diagnostics_topic: str | None = None
    diagnostics_codes: dict[str, str] = field(default_factory=dict)
    conditions: list[Condition] = field(default_factory=list)
    correlation: CorrelationConfig | None = None
    snapshots: Snapshots = field(default_factory=Snapshots)
    clears: list[Clear] = field(default_factory=list)
    reports: list[InjectedReport] = field(default_factory=list)

    def thresholds_for(self, source_id: str) -> Thresholds:
        """The override of the longest prefix that source_id starts with at a '/' boundary (the prefix as written,
        as medkit's EntityThresholdResolver compares it: `/powertrain/` matches only itself, `/` only `/`)."""
        best, best_len = self.thresholds, -1
        for prefix, thresholds in self.overrides:
            matches = source_id.startswith(prefix) and (len(source_id) == len(prefix) or source_id[len(prefix)] == '/')
            if matches and len(prefix) > best_len:
                best, best_len = thresholds, len(prefix)
        return best


def _thresholds(read: Read, base: Thresholds) -> Thresholds:
    """The thresholds given in a section read by its declaration, over `base`; medkit's signs."""
    values: dict[str, Any] = {k: read.get(k) for k in ('healing_enabled', 'auto_confirm_after_sec') if k in read.given
                              and k in read}
    if 'confirmation_threshold' in read.given and 'confirmation_threshold' in read:
        value = read.get('confirmation_threshold')
        values['confirmation_threshold'] = -1 if value == 0 else -abs(value)
    if 'healing_threshold' in read.given and 'healing_threshold' in read:
        values['healing_threshold'] = abs(read.get('healing_threshold'))
    return replace(base, **values)


def _severity(read: Read, path: tuple[Any, ...], problem: Problem) -> int:
    value = severity_value(read.get('severity'))
    if value is None:
        problem((*path, 'severity'), f"{read.get('severity')!r} is not INFO, WARN, ERROR, CRITICAL or 0-3")
        return 2
    return value


def _code(read: Read, path: tuple[Any, ...], problem: Problem) -> str:
    code = read.get('code')
    if code is None:
        return ''
    if not valid_code(code):
        problem((*path, 'code'), f'{code!r} is not a fault code (1-128 of A-Z a-z 0-9 _ . -, no "..")')
        return ''
    return str(code)


def _topics(value: object, path: tuple[Any, ...], problem: Problem) -> tuple[str, ...]:
    if not isinstance(value, list) or not all(isinstance(x, str) for x in value):
        problem(path, 'must be a list of topic names')
        return ()
    return tuple(value)


def parse_report(fault_id: str, injector_id: str, node: object, path: tuple[Any, ...],
                 problem: Problem) -> InjectedReport | None:
    """The `report:` block of a fault."""
    read = Reader(problem).read(sections.REPORT, node, path)
    if read is None:
        return None
    code = _code(read, path, problem)
    severity = _severity(read, path, problem)
    return InjectedReport(fault_id, code, severity, read.get('source', f'/bagfault/{injector_id}'),
                          read.get('report_period'))


def scenario_config(scenario: Scenario, problem: Problem, ignored: Problem) -> FaultManagerConfig | None:
    """A scenario's fault manager: its `fault_manager` section and its faults' `report` blocks; None when the
    scenario uses none (no section, no report, no fault_status or fault_count assertion). `ignored` hears what
    medkit accepts and does nothing with."""
    config = parse_fault_manager(scenario.fault_manager, problem, ignored)
    for fault in scenario.faults:
        if fault.report is not None:
            report = parse_report(fault.id, fault.injector_id, fault.report, (*fault.path, 'report'), problem)
            if report is not None:
                config.reports.append(report)
    uses = scenario.fault_manager is not None or config.reports or any(
        a.type in ('fault_status', 'fault_count') for a in scenario.assertions)
    return config if uses else None


def parse_fault_manager(section: dict[str, Any] | None, problem: Problem,
                        warn: Problem | None = None) -> FaultManagerConfig:
    """Parse and check the whole section; `warn` hears what medkit accepts but the user may not mean."""
    config = FaultManagerConfig()
    if not section:
        return config
    reader = Reader(problem, warn)
    read = reader.read(sections.FAULT_MANAGER, section, PREFIX)
    assert read is not None
    config.thresholds = _thresholds(read, Thresholds())
    for number, node in enumerate(read.get('overrides', [])):
        override = _override(node, (*PREFIX, 'overrides', number), reader, config.thresholds)
        if override is not None:
            config.overrides.append(override)
    _diagnostics(config, read.get('diagnostics'), reader)
    config.conditions = _entries(read.get('conditions', []), 'conditions', _condition, reader)
    if 'correlation' in read.given:
        config.correlation = parse_correlation(section['correlation'], (*PREFIX, 'correlation'), problem,
                                               warn or no_warning)
    if 'snapshots' in read:
        config.snapshots = _snapshots(read.get('snapshots'), (*PREFIX, 'snapshots'), reader)
    config.clears = _entries(read.get('clear', []), 'clear', _clear, reader)
    return config


def _entries(nodes: list[Any], key: str, parse: Callable[[object, tuple[Any, ...], Reader], T | None],
             reader: Reader) -> list[T]:
    """Each entry of the section's list `key`, read by `parse` (an entry it refuses left out)."""
    out = []
    for number, node in enumerate(nodes):
        entry = parse(node, (*PREFIX, key, number), reader)
        if entry is not None:
            out.append(entry)
    return out


def _override(node: object, where: tuple[Any, ...], reader: Reader, default: Thresholds,
              ) -> tuple[str, Thresholds] | None:
    """A per-source override: the source and its thresholds (the global auto_confirm_after_sec, as medkit
    keeps it; one given here is ignored with a warning). None without a source."""
    override = reader.read(sections.OVERRIDE, node, where)
    if override is None:
        return None
    if 'auto_confirm_after_sec' in override.given:
        (reader.warn or reader.problem)(
            (*where, 'auto_confirm_after_sec'), 'ignored, as medkit ignores it: a per-source override carries the '
            "debounce thresholds and healing_enabled only (medkit's EntityThresholdResolver); timed confirmation "
            'uses the global auto_confirm_after_sec')
    if 'source' not in override:
        return None
    thresholds = replace(_thresholds(override, default), auto_confirm_after_sec=default.auto_confirm_after_sec)
    return override.get('source'), thresholds


def _diagnostics(config: FaultManagerConfig, diagnostics: object, reader: Reader) -> None:
    """`diagnostics: true` (on /diagnostics) or `{topic, codes}`: where the fault manager hears diagnostic arrays
    and the codes it maps their names to."""
    if diagnostics is True:
        config.diagnostics_topic = '/diagnostics'
    elif isinstance(diagnostics, dict):
        path: tuple[Any, ...] = (*PREFIX, 'diagnostics')
        block = reader.read(sections.DIAGNOSTICS, diagnostics, path)
        assert block is not None
        config.diagnostics_topic = block.get('topic', '/diagnostics')
        for name, code in block.get('codes', {}).items():
            if not isinstance(code, str) or not valid_code(code):
                reader.problem((*path, 'codes', name), f'{code!r} is not a fault code')
            else:
                config.diagnostics_codes[str(name)] = code
    elif diagnostics not in (None, False):
        reader.problem((*PREFIX, 'diagnostics'), 'must be true or a mapping {topic, codes}')


def _clear(node: object, path: tuple[Any, ...], reader: Reader) -> Clear | None:
    """A scheduled clear of a code, at a time (None when the entry is refused)."""
    clear = reader.read(sections.CLEAR, node, path)
    if clear is None:
        return None
    code = _code(clear, path, reader.problem)
    if 'at' in clear and code:
        return Clear(code, clear.get('at'), clear.get('skip_correlation_auto_clear'))
    return None


def _condition(node: object, path: tuple[Any, ...], reader: Reader) -> Condition | None:
    read = reader.read(sections.CONDITION, node, path)
    if read is None or 'when' not in read or 'topic' not in read:
        return None
    when = reader.read(sections.WHEN, read.get('when'), (*path, 'when'))
    name = _test_name(when, path, reader)
    if when is None or name is None:
        return None
    code = _code(read, path, reader.problem)
    severity = _severity(read, path, reader.problem)
    test = _test(name, when.get(name), path, reader)
    if test is None:
        return None
    topic = read.get('topic')
    source = read.get('source', f'/bagfault/conditions{topic}')
    return Condition(topic, when.get('field'), code, severity, source, **test) if code else None


def _test_name(when: Read | None, path: tuple[Any, ...], reader: Reader) -> str | None:
    """The one test a condition's `when` gives (above, below, outside or not_finite), or None: no field, no test
    or several (a problem), or a test whose value was refused."""
    if when is None or 'field' not in when:
        return None
    tests = [k for k in ('above', 'below', 'outside', 'not_finite') if k in when.given]
    if len(tests) != 1:
        reader.problem((*path, 'when'), 'give exactly one of above, below, outside, not_finite')
        return None
    return tests[0] if tests[0] in when else None


def _test(name: str, value: Any, path: tuple[Any, ...], reader: Reader) -> dict[str, Any] | None:
    """A condition's test as Condition's keyword (`outside` as a (low, high) pair); None when refused."""
    if name != 'outside':
        return {name: value}
    if not (len(value) == 2 and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)):
        reader.problem((*path, 'when', 'outside'), 'must be [low, high]')
        return None
    return {'outside': (float(value[0]), float(value[1]))}


def _snapshots(node: object, path: tuple[Any, ...], reader: Reader) -> Snapshots:
    read = reader.read(sections.SNAPSHOTS, node, path)
    if read is None:
        return Snapshots()
    values: dict[str, Any] = {k: read.get(k) for k in ('enabled', 'duration_sec', 'duration_after_sec',
                                                        'recapture_cooldown_sec') if k in read}
    if 'default_topics' in read:
        values['default_topics'] = _topics(read.get('default_topics'), (*path, 'default_topics'), reader.problem)
    if 'fault_specific' in read:
        values['fault_specific'] = {str(code): _topics(topics, (*path, 'fault_specific', code), reader.problem)
                                    for code, topics in read.get('fault_specific').items()}
    if 'patterns' in read.given:
        values['patterns'] = _snapshot_patterns(read.get('patterns') or [], (*path, 'patterns'), reader.problem,
                                                reader.warn)
    return Snapshots(**values)


@functools.lru_cache(maxsize=256)
def snapshot_regex(pattern: str) -> Any:
    """A snapshot pattern compiled by RE2: time linear in the code's length whatever the pattern (a backtracking
    engine can take forever on `(a+)+$`), so no scenario can hang a run; re2.error for what RE2 cannot compile
    (invalid, or backreferences and lookaround, which need backtracking)."""
    return re2.compile(pattern)


def _pattern_items(node: object, path: tuple[Any, ...], problem: Problem) -> list[tuple[Any, tuple[Any, ...]]]:
    """Each pattern as {match, topics} with where it is, from either layout (none, with a problem, from others)."""
    if isinstance(node, dict):
        return [({'match': key, 'topics': value}, (*path, key)) for key, value in node.items()]
    if isinstance(node, list):
        return [(item, (*path, number)) for number, item in enumerate(node)]
    problem(path, 'must map regular expressions to topic lists')
    return []


def _snapshot_patterns(node: object, path: tuple[Any, ...], problem: Problem, warn: Problem | None = None,
                       ) -> tuple[tuple[str, tuple[str, ...]], ...]:
    """medkit's `{REGEX: [topics]}` map or a list of `{match: REGEX, topics: [...]}`; kept sorted by regex, as
    medkit's std::map holds them, so the lexicographically first matching regex wins."""
    items = _pattern_items(node, path, problem)
    patterns: dict[str, tuple[str, ...]] = {}
    for item, where in items:
        if not isinstance(item, dict) or not isinstance(item.get('match'), str):
            problem(where, 'must be {match: REGEX, topics: [...]}')
            continue
        try:
            snapshot_regex(item['match'])
        except re2.error as exc:  # medkit (snapshot_capture.cpp) logs an invalid regex and ignores the pattern
            (warn or problem)((*where, 'match'), f'invalid regular expression {item["match"]!r} ({exc}) is '
                                                 'ignored, as medkit ignores it')
            continue
        if item['match'] in patterns:
            problem((*where, 'match'), f"duplicate pattern {item['match']!r}")
        patterns[item['match']] = _topics(item.get('topics'), (*where, 'topics'), problem)
    return tuple(sorted(patterns.items()))
