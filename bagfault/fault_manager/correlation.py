"""Fault correlation (ros2_medkit semantics): root cause -> symptoms, and auto-clusters.

On every FAILED report, in this order: expired pending roots are dropped;
the fault is checked as a symptom of a pending root (within window_ms
after it), then as a root cause, then against cluster rules. Patterns use
only `*` as wildcard and match the whole code.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from bagfault.fault_manager.model import CORRELATION_SEVERITY_NAMES, ClusterInfo, MutedFaultInfo
from bagfault.spec import sections
from bagfault.spec.reader import Read, Reader

Problem = Callable[[tuple[Any, ...], str], None]
REPRESENTATIVES = ('first', 'most_recent', 'highest_severity')
# what medkit's string_to_mode / string_to_representative accept (correlation/types.cpp), in any case
MODE_ALIASES = {'hierarchical': 'hierarchical', 'auto_cluster': 'auto_cluster', 'autocluster': 'auto_cluster',
                'cluster': 'auto_cluster'}
REPRESENTATIVE_ALIASES = {'first': 'first', 'most_recent': 'most_recent', 'mostrecent': 'most_recent',
                          'recent': 'most_recent', 'highest_severity': 'highest_severity',
                          'highestseverity': 'highest_severity', 'severity': 'highest_severity'}


@dataclass(frozen=True)
class Wildcard:
    """A code pattern where only * is special (any run of characters), matched whole as medkit's
    pattern_matcher.cpp does (regex_match of the pattern with * as .*), in linear time: the parts between the
    stars are found left to right, so no pattern (`A*A*A*...*B`) makes the match backtrack."""

    text: str

    def match(self, code: str) -> bool:
        """Whether the whole code matches."""
        if '\n' in code:  # a star never spans a newline (regex's `.`): the table below, still no backtracking
            return _stars_within_lines(self.text, code)
        first, *middle, last = self.text.split('*') if '*' in self.text else (self.text, None)
        if last is None:
            return code == first
        if len(code) < len(first) + len(last) or not code.startswith(first) or not code.endswith(last):
            return False
        at, end = len(first), len(code) - len(last)
        for part in middle:
            found = code.find(part, at, end)
            if found < 0:
                return False
            at = found + len(part)
        return True


def _stars_within_lines(pattern: str, code: str) -> bool:
    """The whole-match table, row by row over the pattern: len(pattern) x len(code) steps at most."""
    row = [True] + [False] * len(code)  # the empty pattern matches the empty start of the code
    for char in pattern:
        if char == '*':
            for j in range(1, len(code) + 1):
                row[j] = row[j] or (row[j - 1] and code[j - 1] != '\n')
        else:
            row = [False] + [row[j - 1] and code[j - 1] == char for j in range(1, len(code) + 1)]
    return row[-1]


def wildcard(pattern: str) -> Wildcard:
    """'MOTOR_*' (only * is special)."""
    return Wildcard(pattern)


@dataclass
class Rule:
    """One correlation rule."""

    id: str
    name: str
    mode: str
    window_ms: int
    root_codes: list[Wildcard] = field(default_factory=list)
    symptom_codes: list[Wildcard] = field(default_factory=list)
    mute_symptoms: bool = True
    auto_clear_with_root: bool = True
    match_codes: list[Wildcard] = field(default_factory=list)
    min_count: int = 3
    show_as_single: bool = True
    representative: str = 'highest_severity'


@dataclass
class CorrelationConfig:
    """Parsed `correlation:` block."""

    enabled: bool = True
    default_window_ms: int = 500
    rules: list[Rule] = field(default_factory=list)


def no_warning(path: tuple[Any, ...], message: str) -> None:
    """The default `warn`: nobody listens."""


def _codes(value: object, path: tuple[Any, ...], problem: Problem, empty: Problem | None = None,
           ) -> list[Wildcard]:
    """A list of codes as patterns; an empty list goes to `empty` when given (a warning in medkit)."""
    if empty is not None and value == []:
        empty(path, 'has no codes defined: it matches nothing')
        return []
    if not isinstance(value, list) or not value or not all(isinstance(v, str) for v in value):
        problem(path, 'must be a non-empty list of codes (* is a wildcard)')
        return []
    return [wildcard(v) for v in value]


def parse_correlation(node: object, path: tuple[Any, ...], problem: Problem, warn: Problem = no_warning,
                      ) -> CorrelationConfig | None:
    """Parse and check; every problem reported, and what medkit's validator only warns about to `warn`."""
    read = Reader(problem).read(sections.CORRELATION, node, path)
    if read is None:
        return None
    config = CorrelationConfig(enabled=read.get('enabled', False), default_window_ms=read.get('default_window_ms',
                                                                                             500))
    if 'enabled' not in read.given:
        warn(path, "correlation is off without `enabled: true` (medkit's default); its rules are checked but "
                   'not applied')
    elif config.enabled and not read.get('rules'):
        warn(path, 'correlation is enabled but no rules are defined')
    if not config.enabled:
        problem = warn  # medkit does not validate a disabled block: its mistakes are warnings here
    patterns = _patterns(read.get('patterns') or {}, (*path, 'patterns'), problem, warn)
    config.rules = _rules(read.get('rules', []), (*path, 'rules'), config.default_window_ms,
                          _References(patterns, problem, warn), problem, warn)
    return config


def _rules(items: list[Any], path: tuple[Any, ...], default_window_ms: int, refs: _References, problem: Problem,
           warn: Problem) -> list[Rule]:
    """Each rule of the list that reads, its id unique."""
    rules: list[Rule] = []
    seen: set[str] = set()
    reader = Reader(problem)
    for number, item in enumerate(items):
        where = (*path, number)
        rule_read = reader.read(sections.RULE, item, where)
        if rule_read is None or 'id' not in rule_read:
            continue
        if rule_read.get('id') in seen:
            problem((*where, 'id'), f"duplicate rule id {rule_read.get('id')!r}")
        seen.add(rule_read.get('id'))
        rule = _rule(rule_read, where, default_window_ms, refs, problem, warn)
        if rule is not None:
            rules.append(rule)
    return rules


def _patterns(node: object, path: tuple[Any, ...], problem: Problem, warn: Problem,
              ) -> dict[str, list[Wildcard]]:
    """Named code patterns that rules refer to."""
    patterns: dict[str, list[Wildcard]] = {}
    if not isinstance(node, dict):
        problem(path, 'must be a mapping of pattern ids to {codes: [...]}')
        return patterns
    for pattern_id, pattern in node.items():
        where = (*path, pattern_id)
        if not isinstance(pattern, dict) or 'codes' not in pattern:
            problem(where, 'must be {codes: [...]}')
            continue
        patterns[str(pattern_id)] = _codes(pattern['codes'], (*where, 'codes'), problem, warn)
    return patterns


@dataclass
class _References:
    """Resolves a rule's `symptoms` / `match` list of {pattern: ID} or {codes: [...]}."""

    patterns: dict[str, list[Wildcard]]
    problem: Problem
    warn: Problem

    def __call__(self, items: object, where: tuple[Any, ...], what: str, *,
                 inline: bool = True) -> list[Wildcard]:
        """The patterns of a symptoms or match list; `inline`: `{codes: [...]}` items count (symptoms), or are
        read as medkit's parse_match_refs reads them in an auto_cluster match: not at all."""
        out: list[Wildcard] = []
        if items is None or items == []:
            self.warn(where, f'the rule has no {what} defined: it correlates nothing')
            return out
        if not isinstance(items, list):
            self.problem(where, 'must be a non-empty list of {pattern: ID} or {codes: [...]}')
            return out
        for number, item in enumerate(items):
            out += self._item(item, (*where, number), inline=inline)
        return out

    def _item(self, item: object, where: tuple[Any, ...], *, inline: bool) -> list[Wildcard]:
        """One item of the list: a pattern's codes, or (`inline`) codes of its own."""
        if isinstance(item, dict) and 'pattern' in item:
            if item['pattern'] not in self.patterns:
                self.problem((*where, 'pattern'), f"unknown pattern {item['pattern']!r}")
                return []
            return self.patterns[item['pattern']]
        if isinstance(item, dict) and 'codes' in item:
            if inline:
                return _codes(item['codes'], (*where, 'codes'), self.problem)
            self.warn(where, 'medkit reads only {pattern: ID} items of an auto_cluster match: these codes match '
                             'nothing there (define a pattern for them)')
            return []
        self.problem(where, 'must be {pattern: ID} or {codes: [...]}')
        return []


def _rule(read: Read, where: tuple[Any, ...], default_window_ms: int, refs: _References,
          problem: Problem, warn: Problem) -> Rule | None:
    if 'mode' in read.refused:
        return None
    written = read.get('mode')
    mode = MODE_ALIASES.get(str(written).lower())
    if mode is None:
        problem((*where, 'mode'), f"{written!r} is not 'hierarchical' or 'auto_cluster'")
        return None
    window_ms = read.get('window_ms', default_window_ms)
    if window_ms > 60_000:
        warn((*where, 'window_ms'), f'{window_ms} ms is over 60 s, which may be too long')
    rule = Rule(read.get('id'), read.get('name', read.get('id')), mode, window_ms)
    if mode == 'hierarchical':
        _hierarchical(rule, read, where, refs, problem)
    else:
        _auto_cluster(rule, read, where, refs, problem, warn)
    return rule


def _hierarchical(rule: Rule, read: Read, where: tuple[Any, ...], refs: _References, problem: Problem) -> None:
    """A hierarchical rule's root cause and symptoms."""
    root = read.get('root_cause')
    if not isinstance(root, dict) or 'codes' not in root:
        problem((*where, 'root_cause'), 'must be {codes: [...]}')
    else:
        rule.root_codes = _codes(root['codes'], (*where, 'root_cause', 'codes'), problem)
    rule.symptom_codes = refs(read.get('symptoms'), (*where, 'symptoms'), 'symptoms')
    rule.mute_symptoms = read.get('mute_symptoms', True)
    rule.auto_clear_with_root = read.get('auto_clear_with_root', True)


def _auto_cluster(rule: Rule, read: Read, where: tuple[Any, ...], refs: _References, problem: Problem,
                  warn: Problem) -> None:
    """An auto_cluster rule's match patterns, count and representative."""
    rule.match_codes = refs(read.get('match'), (*where, 'match'), 'match patterns', inline=False)
    if 'min_count' in read:
        rule.min_count = read.get('min_count')
        if rule.min_count < 2:
            warn((*where, 'min_count'), f'{rule.min_count} is under 2, which may cause false clusters')
    rule.show_as_single = read.get('show_as_single', True)
    written = read.get('representative')
    representative = REPRESENTATIVE_ALIASES.get(str(written).lower())
    if representative is not None:
        rule.representative = representative
    elif 'representative' not in read.refused:
        problem((*where, 'representative'), f'{written!r} is not one of {", ".join(REPRESENTATIVES)}')


@dataclass
class _PendingRoot:
    code: str
    rule: Rule
    time: int


@dataclass
class _Cluster:
    info: ClusterInfo
    rule: Rule
    severities: dict[str, int]
    active: bool = False


def _matches(code: str, patterns: list[Wildcard]) -> bool:
    return any(p.match(code) for p in patterns)


class CorrelationEngine:
    """Keeps pending roots, symptoms, clusters and the muted set."""

    def __init__(self, config: CorrelationConfig) -> None:
        self.config = config
        self.pending_roots: list[_PendingRoot] = []
        self.symptoms: dict[str, list[str]] = {}
        self.muted: dict[str, MutedFaultInfo] = {}
        self.pending_clusters: dict[str, _Cluster] = {}
        self.active_clusters: dict[str, _Cluster] = {}
        self.member_of: dict[str, str] = {}
        self._cluster_counter = 0

    def process_failed(self, code: str, severity: int, time: int) -> bool:
        """Correlate one FAILED report; True when this report is muted (medkit's should_mute)."""
        if not self.config.enabled:
            return False
        self.pending_roots = [r for r in self.pending_roots if (time - r.time) // 1_000_000 <= r.rule.window_ms]
        symptom = self._as_symptom(code, time)
        if symptom is not None:
            return symptom
        if self._as_root(code, time) is not None:
            return False
        return self._as_cluster(code, severity, time)

    def _as_symptom(self, code: str, time: int) -> bool | None:
        """None when no pending root claims the code, else whether its rule mutes it."""
        for root in self.pending_roots:
            rule = root.rule
            if not _matches(code, rule.symptom_codes):
                continue
            elapsed = (time - root.time) // 1_000_000
            if elapsed > rule.window_ms:
                continue
            symptoms = self.symptoms.setdefault(root.code, [])
            if code not in symptoms:
                symptoms.append(code)
            if rule.mute_symptoms:
                self.muted[code] = MutedFaultInfo(code, root.code, rule.id, int(elapsed))
            return rule.mute_symptoms
        return None

    def _as_root(self, code: str, time: int) -> Rule | None:
        for rule in self.config.rules:
            if rule.mode == 'hierarchical' and _matches(code, rule.root_codes):
                self.pending_roots.append(_PendingRoot(code, rule, time))
                self.symptoms[code] = []
                return rule
        return None

    def _as_cluster(self, code: str, severity: int, time: int) -> bool:
        """Add to the first matching rule's pending cluster; True when this report is hidden behind the
        representative (show_as_single, cluster at min_count)."""
        for rule in self.config.rules:
            if rule.mode != 'auto_cluster' or not _matches(code, rule.match_codes):
                continue
            cluster = self.pending_clusters.get(rule.id)
            if cluster is not None and (time - cluster.info.first_at) // 1_000_000 > rule.window_ms:
                del self.pending_clusters[rule.id]
                cluster = None
            if cluster is None:
                self._cluster_counter += 1
                info = ClusterInfo(f'{rule.id}_{self._cluster_counter}', rule.id, rule.name, rule.name, code,
                                   CORRELATION_SEVERITY_NAMES[severity], [code], time, time)
                self.pending_clusters[rule.id] = _Cluster(info, rule, {code: severity})
                self.member_of[code] = info.cluster_id
                return False
            info = cluster.info
            if code not in info.fault_codes:
                self._join(cluster, code, severity, time)
            return (rule.show_as_single and code != info.representative_code
                    and len(info.fault_codes) >= rule.min_count)
        return False

    def _join(self, cluster: _Cluster, code: str, severity: int, time: int) -> None:
        """A new member of a pending cluster: perhaps its representative, and the cluster active at min_count."""
        info, rule = cluster.info, cluster.rule
        info.fault_codes.append(code)
        info.last_at = time
        cluster.severities[code] = severity
        self.member_of[code] = info.cluster_id
        if rule.representative == 'most_recent' or (
            rule.representative == 'highest_severity'
            and severity > cluster.severities[info.representative_code]
        ):
            info.representative_code = code
            info.representative_severity = CORRELATION_SEVERITY_NAMES[severity]
        if len(info.fault_codes) >= rule.min_count:
            cluster.active = True
            self.active_clusters[info.cluster_id] = cluster

    def muted_faults(self) -> list[MutedFaultInfo]:
        """Muted symptoms of hierarchical rules (cluster members are never listed as muted), by code."""
        return sorted(self.muted.values(), key=lambda m: m.fault_code)

    def process_clear(self, code: str) -> list[str]:
        """Forget a cleared fault; return the symptoms to clear with it (auto_clear_with_root)."""
        cleared = self._clear_root(code)
        self.pending_roots = [r for r in self.pending_roots if r.code != code]
        cluster_id = self.member_of.pop(code, None)
        if cluster_id is not None:
            self._leave(cluster_id, code)
        self.muted.pop(code, None)
        for symptom in cleared:
            self.muted.pop(symptom, None)
        return cleared

    def _clear_root(self, code: str) -> list[str]:
        """A cleared root's symptoms unmuted; those to clear with it. medkit's process_clear: the pending root's
        own rule, then any hierarchical rule on this root with auto_clear_with_root (correlation_engine.cpp:95-119):
        one such rule is enough."""
        symptoms = self.symptoms.pop(code, None)
        if symptoms is None:
            return []
        for symptom in symptoms:
            self.muted.pop(symptom, None)
        if any(r.mode == 'hierarchical' and r.auto_clear_with_root and _matches(code, r.root_codes)
               for r in self.config.rules):
            return list(symptoms)
        return []

    def _leave(self, cluster_id: str, code: str) -> None:
        """A cleared code out of its cluster, pending or active: the cluster gone when empty, a new
        representative when it was the representative."""
        for table in (self.pending_clusters, self.active_clusters):
            for key, cluster in list(table.items()):
                if cluster.info.cluster_id != cluster_id or code not in cluster.info.fault_codes:
                    continue
                cluster.info.fault_codes.remove(code)
                cluster.severities.pop(code, None)
                if not cluster.info.fault_codes:
                    del table[key]
                elif cluster.info.representative_code == code:
                    _promote(cluster)

    def clusters(self) -> list[ClusterInfo]:
        """Active clusters."""
        return [c.info for c in self.active_clusters.values()]


def _promote(cluster: _Cluster) -> None:
    info = cluster.info
    codes = info.fault_codes
    choice = codes[0]
    if cluster.rule.representative == 'most_recent':
        choice = codes[-1]
    elif cluster.rule.representative == 'highest_severity':
        choice = max(codes, key=lambda c: cluster.severities.get(c, 0))
    info.representative_code = choice
    info.representative_severity = CORRELATION_SEVERITY_NAMES[cluster.severities.get(choice, 0)]
