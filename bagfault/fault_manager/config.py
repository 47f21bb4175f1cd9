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
import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import re2  # type: ignore[import-untyped]

from bagfault.fault_manager.correlation import CorrelationConfig, no_warning, parse_correlation
from bagfault.fault_manager.model import severity_value, valid_code

Problem = Callable[[tuple[Any, ...], str], None]
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


THRESHOLD_KEYS = {'confirmation_threshold', 'healing_enabled', 'healing_threshold', 'auto_confirm_after_sec'}
TOP_KEYS = THRESHOLD_KEYS | {'overrides', 'diagnostics', 'conditions', 'correlation', 'snapshots', 'clear'}


def _thresholds(node: dict[str, Any], base: Thresholds, path: tuple[Any, ...], problem: Problem) -> Thresholds:
    values: dict[str, Any] = {}
    for key in ('confirmation_threshold', 'healing_threshold'):
        if key in node:
            value = node[key]
            if isinstance(value, bool) or not isinstance(value, int):
                problem((*path, key), f'{value!r} is not an integer')
                continue
            if key == 'confirmation_threshold':
                values[key] = -1 if value == 0 else -abs(value)
            else:
                values[key] = abs(value)
    if 'healing_enabled' in node:
        if not isinstance(node['healing_enabled'], bool):
            problem((*path, 'healing_enabled'), f"{node['healing_enabled']!r} is not true or false")
        else:
            values['healing_enabled'] = node['healing_enabled']
    if 'auto_confirm_after_sec' in node:
        value = node['auto_confirm_after_sec']
        if isinstance(value, bool) or not isinstance(value, (int, float)) or value < 0:
            problem((*path, 'auto_confirm_after_sec'), f'{value!r} is not a number of seconds >= 0')
        else:
            values['auto_confirm_after_sec'] = float(value)
    return replace(base, **values)


def _severity(node: dict[str, Any], path: tuple[Any, ...], problem: Problem, default: int = 2) -> int:
    if 'severity' not in node:
        return default
    value = severity_value(node['severity'])
    if value is None:
        problem((*path, 'severity'), f"{node['severity']!r} is not INFO, WARN, ERROR, CRITICAL or 0-3")
        return default
    return value


def _code(node: dict[str, Any], path: tuple[Any, ...], problem: Problem) -> str:
    code = node.get('code')
    if not isinstance(code, str) or not valid_code(code):
        problem((*path, 'code'), f'{code!r} is not a fault code (1-128 of A-Z a-z 0-9 _ . -, no "..")')
        return ''
    return code


def _topics(value: object, path: tuple[Any, ...], problem: Problem) -> tuple[str, ...]:
    if not isinstance(value, list) or not all(isinstance(x, str) for x in value):
        problem(path, 'must be a list of topic names')
        return ()
    return tuple(value)


def parse_report(fault_id: str, injector_id: str, node: object, path: tuple[Any, ...],
                 problem: Problem) -> InjectedReport | None:
    """The `report:` block of a fault."""
    if not isinstance(node, dict):
        problem(path, 'must be a mapping {code, severity[, report_period, source]}')
        return None
    for key in node:
        if key not in {'code', 'severity', 'report_period', 'source'}:
            problem((*path, key), f'unknown report key {key!r} (code, severity, report_period, source)')
    code = _code(node, path, problem)
    severity = _severity(node, path, problem)
    period = node.get('report_period')
    if period is not None and (isinstance(period, bool) or not isinstance(period, (int, float)) or period <= 0):
        problem((*path, 'report_period'), f'{period!r} is not a number of seconds > 0')
        period = None
    source = node.get('source', f'/bagfault/{injector_id}')
    if not isinstance(source, str) or not source:
        problem((*path, 'source'), 'must be a non-empty source id')
        source = f'/bagfault/{injector_id}'
    return InjectedReport(fault_id, code, severity, source, float(period) if period else None)


def parse_fault_manager(section: dict[str, Any] | None, problem: Problem,
                        warn: Problem | None = None) -> FaultManagerConfig:
    """Parse and check the whole section; `warn` hears what medkit accepts but the user may not mean."""
    config = FaultManagerConfig()
    if not section:
        return config
    for key in section:
        if key not in TOP_KEYS:
            problem((*PREFIX, key), f'unknown fault_manager key {key!r} (known: {", ".join(sorted(TOP_KEYS))})')
    config.thresholds = _thresholds(section, Thresholds(), PREFIX, problem)
    for number, node in enumerate(section.get('overrides') or []):
        where: tuple[Any, ...] = (*PREFIX, 'overrides', number)
        if not isinstance(node, dict) or not isinstance(node.get('source'), str):
            problem(where, 'must be a mapping with source and thresholds')
            continue
        for key in node:
            if key not in THRESHOLD_KEYS | {'source'}:
                problem((*where, key), f'unknown override key {key!r}')
        config.overrides.append((node['source'], _thresholds(node, config.thresholds, where, problem)))
    diagnostics = section.get('diagnostics')
    if diagnostics is not None:
        path: tuple[Any, ...] = (*PREFIX, 'diagnostics')
        if diagnostics is True:
            config.diagnostics_topic = '/diagnostics'
        elif isinstance(diagnostics, dict):
            config.diagnostics_topic = str(diagnostics.get('topic', '/diagnostics'))
            codes = diagnostics.get('codes', {}) or {}
            if not isinstance(codes, dict):
                problem((*path, 'codes'), 'must map status names to fault codes')
            else:
                for name, code in codes.items():
                    if not isinstance(code, str) or not valid_code(code):
                        problem((*path, 'codes', name), f'{code!r} is not a fault code')
                    else:
                        config.diagnostics_codes[str(name)] = code
        elif diagnostics is not False:
            problem(path, 'must be true or a mapping {topic, codes}')
    for number, node in enumerate(section.get('conditions') or []):
        condition = _condition(node, (*PREFIX, 'conditions', number), problem)
        if condition:
            config.conditions.append(condition)
    if 'correlation' in section:
        node = section['correlation']
        config.correlation = parse_correlation(node, (*PREFIX, 'correlation'), problem, warn or no_warning)
    if 'snapshots' in section:
        config.snapshots = _snapshots(section['snapshots'], (*PREFIX, 'snapshots'), problem, warn)
    for number, node in enumerate(section.get('clear') or []):
        path = (*PREFIX, 'clear', number)
        if not isinstance(node, dict):
            problem(path, 'must be a mapping {code, at}')
            continue
        code = _code(node, path, problem)
        at = node.get('at')
        if isinstance(at, bool) or not isinstance(at, (int, float)) or at < 0:
            problem((*path, 'at'), f'{at!r} is not a number of seconds >= 0')
            continue
        config.clears.append(Clear(code, float(at), bool(node.get('skip_correlation_auto_clear', False))))
    return config


def _condition(node: object, path: tuple[Any, ...], problem: Problem) -> Condition | None:
    if not isinstance(node, dict):
        problem(path, 'must be a mapping {topic, when, code, severity}')
        return None
    topic, when = node.get('topic'), node.get('when')
    if not isinstance(topic, str) or not isinstance(when, dict) or not isinstance(when.get('field'), str):
        problem(path, 'needs topic and when: {field, above|below|outside|not_finite}')
        return None
    tests = [k for k in ('above', 'below', 'outside', 'not_finite') if k in when]
    if len(tests) != 1:
        problem((*path, 'when'), 'give exactly one of above, below, outside, not_finite')
        return None
    code = _code(node, path, problem)
    severity = _severity(node, path, problem)
    kwargs: dict[str, Any] = {}
    value = when[tests[0]]
    if tests[0] == 'outside':
        if not (isinstance(value, list) and len(value) == 2 and all(isinstance(v, (int, float)) for v in value)):
            problem((*path, 'when', 'outside'), 'must be [low, high]')
            return None
        kwargs['outside'] = (float(value[0]), float(value[1]))
    elif tests[0] == 'not_finite':
        kwargs['not_finite'] = bool(value)
    else:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            problem((*path, 'when', tests[0]), f'{value!r} is not a number')
            return None
        kwargs[tests[0]] = float(value)
    source = str(node.get('source', f'/bagfault/conditions{topic}'))
    return Condition(topic, when['field'], code, severity, source, **kwargs) if code else None


def _snapshots(node: object, path: tuple[Any, ...], problem: Problem, warn: Problem | None = None) -> Snapshots:
    if not isinstance(node, dict):
        problem(path, 'must be a mapping')
        return Snapshots()
    values: dict[str, Any] = {}
    known = {'enabled', 'default_topics', 'fault_specific', 'patterns', 'duration_sec', 'duration_after_sec',
             'recapture_cooldown_sec'}
    for key in node:
        if key not in known:
            problem((*path, key), f'unknown snapshots key {key!r}')
    if 'enabled' in node:  # a ROS parameter in medkit (declare_parameter<bool>): rcl's YAML keeps 'false' a string
        if isinstance(node['enabled'], bool):
            values['enabled'] = node['enabled']
        else:
            problem((*path, 'enabled'), f"{node['enabled']!r} must be true or false (medkit declares "
                                        'snapshots.enabled as a bool parameter; a quoted value is a string there)')
    if 'default_topics' in node:
        values['default_topics'] = _topics(node['default_topics'], (*path, 'default_topics'), problem)
    if 'fault_specific' in node:
        specific = node['fault_specific']
        if isinstance(specific, dict):
            values['fault_specific'] = {str(code): _topics(topics, (*path, 'fault_specific', code), problem)
                                        for code, topics in specific.items()}
        else:
            problem((*path, 'fault_specific'), 'must map fault codes to topic lists')
    if 'patterns' in node:
        values['patterns'] = _snapshot_patterns(node['patterns'] or [], (*path, 'patterns'), problem, warn)
    for key in ('duration_sec', 'duration_after_sec', 'recapture_cooldown_sec'):
        if key in node:
            value = node[key]
            if isinstance(value, bool) or not isinstance(value, (int, float)) or value < 0:
                problem((*path, key), f'{value!r} is not a number of seconds >= 0')
            else:
                values[key] = float(value)
    return Snapshots(**values)


@functools.lru_cache(maxsize=256)
def snapshot_regex(pattern: str) -> Any:
    """A snapshot pattern compiled by RE2: time linear in the code's length whatever the pattern (a backtracking
    engine can take forever on `(a+)+$`), so no scenario can hang a run; re2.error for what RE2 cannot compile
    (invalid, or backreferences and lookaround, which need backtracking)."""
    return re2.compile(pattern)


def _snapshot_patterns(node: object, path: tuple[Any, ...], problem: Problem, warn: Problem | None = None,
                       ) -> tuple[tuple[str, tuple[str, ...]], ...]:
    """medkit's `{REGEX: [topics]}` map or a list of `{match: REGEX, topics: [...]}`; kept sorted by regex, as
    medkit's std::map holds them, so the lexicographically first matching regex wins."""
    if isinstance(node, dict):
        items = [({'match': key, 'topics': value}, (*path, key)) for key, value in node.items()]
    elif isinstance(node, list):
        items = [(item, (*path, number)) for number, item in enumerate(node)]
    else:
        problem(path, 'must map regular expressions to topic lists')
        return ()
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
