"""medkit's own correlation unit tests, ported: names, YAML and expected values from
selfpatch/ros2_medkit src/ros2_medkit_fault_manager/test/test_correlation_engine.cpp and
test_correlation_config_parser.cpp at commit 505bc2d5.

The engine is bagfault's CorrelationEngine built from the test's YAML by the
scenario parser. medkit's tests without an explicit timestamp report in
quick succession; here they are 1 ms apart. Severities are medkit's names
mapped to the Fault message's numbers (WARNING 1, ERROR 2, CRITICAL 3).
"""

from __future__ import annotations

from typing import Any

import pytest
import yaml

from bagfault.fault_manager.correlation import CorrelationEngine, parse_correlation

MS = 1_000_000
SEVERITY = {'INFO': 0, 'WARNING': 1, 'ERROR': 2, 'CRITICAL': 3}

HIERARCHICAL = """
correlation:
  enabled: true
  default_window_ms: 500
  patterns:
    motor_errors:
      codes: ["MOTOR_COMM_*", "MOTOR_TIMEOUT_*"]
    drive_faults:
      codes: ["DRIVE_*"]
  rules:
    - id: estop_cascade
      name: "E-Stop Cascade"
      mode: hierarchical
      root_cause:
        codes: ["ESTOP_001"]
      symptoms:
        - pattern: motor_errors
        - pattern: drive_faults
      window_ms: 1000
      mute_symptoms: true
      auto_clear_with_root: true
"""

AUTO_CLUSTER = """
correlation:
  enabled: true
  patterns:
    comm_errors:
      codes: ["*_COMM_*", "*_TIMEOUT"]
  rules:
    - id: comm_storm
      name: "Communication Storm"
      mode: auto_cluster
      match:
        - pattern: comm_errors
      min_count: 3
      window_ms: 500
      show_as_single: true
      representative: highest_severity
"""

MIXED = """
correlation:
  enabled: true
  patterns:
    motor_errors:
      codes: ["MOTOR_*"]
    sensor_errors:
      codes: ["SENSOR_*"]
  rules:
    - id: estop_rule
      mode: hierarchical
      root_cause:
        codes: ["ESTOP_001"]
      symptoms:
        - pattern: motor_errors
      window_ms: 500
      mute_symptoms: true
      auto_clear_with_root: true
    - id: sensor_cluster
      mode: auto_cluster
      match:
        - pattern: sensor_errors
      min_count: 2
      window_ms: 500
      representative: first
"""


def cluster_yaml(representative: str, min_count: int = 3) -> str:
    return f"""
correlation:
  enabled: true
  patterns:
    errors:
      codes: ["*_ERROR"]
  rules:
    - id: test_cluster
      mode: auto_cluster
      match:
        - pattern: errors
      min_count: {min_count}
      window_ms: 500
      show_as_single: true
      representative: {representative}
"""


def parse(text: str) -> tuple[Any, list[str], list[str]]:
    errors: list[str] = []
    warnings: list[str] = []
    node = (yaml.safe_load(text) or {}).get('correlation', {})
    config = parse_correlation(node, ('correlation',), lambda p, m: errors.append(m),
                               lambda p, m: warnings.append(m))
    return config, errors, warnings


class Engine:
    """medkit's call shapes over bagfault's engine: process_fault(code, severity[, ms])."""

    def __init__(self, text: str) -> None:
        config, errors, _ = parse(text)
        assert not errors, errors
        self.engine = CorrelationEngine(config)
        self.clock = 0

    def process_fault(self, code: str, severity: str, at_ms: int | None = None) -> bool:
        self.clock = self.clock + 1 if at_ms is None else at_ms
        return self.engine.process_failed(code, SEVERITY[severity], self.clock * MS)

    def muted_count(self) -> int:
        return len(self.engine.muted_faults())

    def cluster_count(self) -> int:
        return len(self.engine.clusters())


# -- hierarchical --------------------------------------------------------------------------------------------

def test_RootCauseRecognized() -> None:
    engine = Engine(HIERARCHICAL)
    assert engine.process_fault('ESTOP_001', 'CRITICAL') is False
    assert [r.code for r in engine.engine.pending_roots] == ['ESTOP_001']


def test_SymptomMuted() -> None:
    engine = Engine(HIERARCHICAL)
    engine.process_fault('ESTOP_001', 'CRITICAL')
    assert engine.process_fault('MOTOR_COMM_FL', 'ERROR') is True
    [muted] = engine.engine.muted_faults()
    assert (muted.fault_code, muted.root_cause_code, muted.rule_id) == ('MOTOR_COMM_FL', 'ESTOP_001', 'estop_cascade')


def test_MultipleSymptomsMuted() -> None:
    engine = Engine(HIERARCHICAL)
    for code, severity in (('ESTOP_001', 'CRITICAL'), ('MOTOR_COMM_FL', 'ERROR'), ('MOTOR_COMM_FR', 'ERROR'),
                           ('DRIVE_FAULT', 'ERROR')):
        engine.process_fault(code, severity)
    assert engine.muted_count() == 3


def test_SymptomBeforeRootCauseNotCorrelated() -> None:
    engine = Engine(HIERARCHICAL)
    assert engine.process_fault('MOTOR_COMM_FL', 'ERROR') is False
    assert engine.muted_count() == 0


def test_SymptomAfterWindowNotCorrelated() -> None:
    engine = Engine(HIERARCHICAL)
    engine.process_fault('ESTOP_001', 'CRITICAL', 0)
    assert engine.process_fault('MOTOR_COMM_FL', 'ERROR', 1500) is False
    assert engine.muted_count() == 0


def test_ClearRootCauseClearsSymptoms() -> None:
    engine = Engine(HIERARCHICAL)
    for code, severity in (('ESTOP_001', 'CRITICAL'), ('MOTOR_COMM_FL', 'ERROR'), ('MOTOR_COMM_FR', 'ERROR')):
        engine.process_fault(code, severity)
    assert engine.muted_count() == 2
    assert sorted(engine.engine.process_clear('ESTOP_001')) == ['MOTOR_COMM_FL', 'MOTOR_COMM_FR']
    assert engine.muted_count() == 0


def test_UnrelatedFaultNotCorrelated() -> None:
    engine = Engine(HIERARCHICAL)
    engine.process_fault('ESTOP_001', 'CRITICAL')
    assert engine.process_fault('SENSOR_TIMEOUT', 'ERROR') is False
    assert engine.muted_count() == 0


def test_InlineSymptomCodesMuted() -> None:
    engine = Engine("""
correlation:
  enabled: true
  rules:
    - id: estop_inline
      mode: hierarchical
      root_cause:
        codes: ["ESTOP_001"]
      symptoms:
        - codes: ["MOTOR_*", "DRIVE_*"]
      window_ms: 1000
      mute_symptoms: true
""")
    assert engine.process_fault('ESTOP_001', 'CRITICAL') is False
    assert engine.process_fault('MOTOR_COMM_FL', 'ERROR') is True
    assert engine.process_fault('DRIVE_FAULT', 'ERROR') is True
    assert engine.process_fault('SENSOR_ERROR', 'ERROR') is False
    assert engine.muted_count() == 2


def test_MixedPatternAndInlineSymptoms() -> None:
    engine = Engine("""
correlation:
  enabled: true
  patterns:
    sensor_errors:
      codes: ["SENSOR_*"]
  rules:
    - id: estop_mixed
      mode: hierarchical
      root_cause:
        codes: ["ESTOP_001"]
      symptoms:
        - pattern: sensor_errors
        - codes: ["MOTOR_*"]
      window_ms: 1000
      mute_symptoms: true
""")
    engine.process_fault('ESTOP_001', 'CRITICAL')
    assert engine.process_fault('SENSOR_TIMEOUT', 'ERROR') is True
    assert engine.process_fault('MOTOR_FAULT', 'ERROR') is True
    assert engine.muted_count() == 2


# -- auto-cluster ----------------------------------------------------------------------------------------------

def test_AutoClusterTriggersAtMinCount() -> None:
    engine = Engine(AUTO_CLUSTER)
    assert engine.process_fault('MOTOR_COMM_FL', 'ERROR') is False
    assert engine.cluster_count() == 0
    assert engine.process_fault('SENSOR_TIMEOUT', 'ERROR') is False
    assert engine.cluster_count() == 0
    assert engine.process_fault('DRIVE_COMM_ERROR', 'WARNING') is True  # third, not the representative
    assert engine.cluster_count() == 1
    assert engine.muted_count() == 0  # a cluster mutes events, it does not list members as muted


def test_AutoClusterNotTriggeredBelowMinCount() -> None:
    engine = Engine(AUTO_CLUSTER)
    engine.process_fault('MOTOR_COMM_FL', 'ERROR')
    engine.process_fault('SENSOR_TIMEOUT', 'ERROR')
    assert engine.cluster_count() == 0


def test_AutoClusterHighestSeverityRepresentative() -> None:
    engine = Engine(AUTO_CLUSTER)
    engine.process_fault('MOTOR_COMM_FL', 'WARNING')
    engine.process_fault('SENSOR_TIMEOUT', 'CRITICAL')
    engine.process_fault('DRIVE_COMM_ERROR', 'ERROR')
    [cluster] = engine.engine.clusters()
    assert (cluster.representative_code, cluster.representative_severity) == ('SENSOR_TIMEOUT', 'CRITICAL')


def test_AutoClusterFirstRepresentative() -> None:
    engine = Engine(cluster_yaml('first', min_count=2))
    engine.process_fault('FIRST_ERROR', 'WARNING')
    engine.process_fault('SECOND_ERROR', 'CRITICAL')
    [cluster] = engine.engine.clusters()
    assert cluster.representative_code == 'FIRST_ERROR'


def test_AutoClusterWindowExpires() -> None:
    engine = Engine(AUTO_CLUSTER)
    engine.process_fault('MOTOR_COMM_FL', 'ERROR', 0)
    engine.process_fault('SENSOR_TIMEOUT', 'ERROR', 100)
    engine.process_fault('DRIVE_COMM_ERROR', 'ERROR', 600)
    assert engine.cluster_count() == 0


def test_HierarchicalAndClusterCoexist() -> None:
    engine = Engine(MIXED)
    engine.process_fault('ESTOP_001', 'CRITICAL')
    assert engine.process_fault('MOTOR_COMM_FL', 'ERROR') is True
    assert engine.muted_count() == 1
    engine.process_fault('SENSOR_LIDAR', 'ERROR')
    engine.process_fault('SENSOR_IMU', 'ERROR')
    assert (engine.muted_count(), engine.cluster_count()) == (1, 1)


def test_DuplicateFaultCode() -> None:
    engine = Engine(HIERARCHICAL)
    engine.process_fault('ESTOP_001', 'CRITICAL')
    engine.process_fault('MOTOR_COMM_FL', 'ERROR')
    engine.process_fault('MOTOR_COMM_FL', 'ERROR')
    assert engine.muted_count() >= 1


def test_EmptyEngineQueries() -> None:
    engine = Engine(HIERARCHICAL)
    assert (engine.engine.muted_faults(), engine.engine.clusters()) == ([], [])


def test_ClearNonExistentFault() -> None:
    assert Engine(HIERARCHICAL).engine.process_clear('NONEXISTENT') == []


def test_AutoClusterRetroactiveMuting() -> None:
    engine = Engine(cluster_yaml('first').replace('*_ERROR', 'SENSOR_*'))
    assert engine.process_fault('SENSOR_001', 'ERROR', 0) is False
    assert engine.process_fault('SENSOR_002', 'ERROR', 10) is False
    assert engine.process_fault('SENSOR_003', 'ERROR', 20) is True
    [cluster] = engine.engine.clusters()
    assert (len(cluster.fault_codes), cluster.representative_code) == (3, 'SENSOR_001')


def test_ClearFaultRemovesFromPendingCluster() -> None:
    engine = Engine(AUTO_CLUSTER)
    engine.process_fault('MOTOR_COMM_FL', 'ERROR', 0)
    engine.process_fault('SENSOR_TIMEOUT', 'ERROR', 10)
    engine.engine.process_clear('MOTOR_COMM_FL')
    engine.process_fault('DRIVE_COMM_ERROR', 'ERROR', 20)
    assert engine.cluster_count() == 0


def test_ClearRepresentativeReassignsPendingCluster() -> None:
    engine = Engine(cluster_yaml('first'))
    engine.process_fault('FIRST_ERROR', 'CRITICAL', 0)
    engine.process_fault('SECOND_ERROR', 'ERROR', 10)
    engine.engine.process_clear('FIRST_ERROR')
    engine.process_fault('THIRD_ERROR', 'ERROR', 20)
    engine.process_fault('FOURTH_ERROR', 'ERROR', 30)
    [cluster] = engine.engine.clusters()
    assert (cluster.representative_code, cluster.representative_severity) == ('SECOND_ERROR', 'ERROR')


def test_ClearAllFaultsRemovesPendingCluster() -> None:
    engine = Engine(AUTO_CLUSTER)
    engine.process_fault('MOTOR_COMM_FL', 'ERROR', 0)
    engine.process_fault('SENSOR_TIMEOUT', 'ERROR', 10)
    engine.engine.process_clear('MOTOR_COMM_FL')
    engine.engine.process_clear('SENSOR_TIMEOUT')
    engine.process_fault('DRIVE_COMM_NEW', 'ERROR', 100)
    engine.process_fault('MOTOR_COMM_NEW', 'ERROR', 110)
    assert engine.cluster_count() == 0


def test_ClearMostRecentRepresentativeReassignsActiveCluster() -> None:
    engine = Engine(cluster_yaml('most_recent'))
    engine.process_fault('FIRST_ERROR', 'WARNING', 0)
    engine.process_fault('SECOND_ERROR', 'ERROR', 10)
    engine.process_fault('THIRD_ERROR', 'CRITICAL', 20)
    [cluster] = engine.engine.clusters()
    assert (cluster.representative_code, cluster.representative_severity) == ('THIRD_ERROR', 'CRITICAL')
    engine.engine.process_clear('THIRD_ERROR')
    [cluster] = engine.engine.clusters()
    assert (cluster.representative_code, cluster.representative_severity) == ('SECOND_ERROR', 'ERROR')


def test_ClearHighestSeverityRepresentativeReassigns() -> None:
    engine = Engine(AUTO_CLUSTER)
    engine.process_fault('MOTOR_COMM_FL', 'WARNING', 0)
    engine.process_fault('SENSOR_TIMEOUT', 'CRITICAL', 10)
    engine.process_fault('DRIVE_COMM_ERROR', 'ERROR', 20)
    assert engine.engine.clusters()[0].representative_code == 'SENSOR_TIMEOUT'
    engine.engine.process_clear('SENSOR_TIMEOUT')
    [cluster] = engine.engine.clusters()
    assert (cluster.representative_code, cluster.representative_severity) == ('DRIVE_COMM_ERROR', 'ERROR')


# -- config parser ---------------------------------------------------------------------------------------------

def test_ParseDisabledConfig() -> None:
    config, errors, warnings = parse('correlation:\n  enabled: false\n')
    assert (config.enabled, errors, warnings) == (False, [], [])


def test_ParseMinimalConfig() -> None:
    config, errors, _ = parse('correlation:\n  enabled: true\n  default_window_ms: 1000\n')
    assert (config.enabled, config.default_window_ms, config.rules, errors) == (True, 1000, [], [])


def test_ValidateValidConfig() -> None:
    _, errors, warnings = parse("""
correlation:
  enabled: true
  patterns:
    motor_errors:
      codes: ["MOTOR_*"]
  rules:
    - id: test_rule
      root_cause:
        codes: ["ESTOP"]
      symptoms:
        - pattern: motor_errors
""")
    assert (errors, warnings) == ([], [])


def test_ValidateUnknownPatternReference() -> None:
    _, errors, _ = parse("""
correlation:
  enabled: true
  patterns:
    motor_errors:
      codes: ["MOTOR_*"]
  rules:
    - id: test_rule
      root_cause:
        codes: ["ESTOP"]
      symptoms:
        - pattern: nonexistent_pattern
""")
    assert len(errors) == 1 and 'nonexistent_pattern' in errors[0]


def test_ValidateDuplicateRuleId() -> None:
    _, errors, _ = parse("""
correlation:
  enabled: true
  rules:
    - id: same_id
      root_cause:
        codes: ["A"]
    - id: same_id
      root_cause:
        codes: ["B"]
""")
    assert errors


def test_ValidateHierarchicalNoRootCause() -> None:
    _, errors, _ = parse('correlation:\n  enabled: true\n  rules:\n    - id: broken_rule\n      mode: hierarchical\n')
    assert errors


def test_ValidateZeroWindowMs() -> None:
    _, errors, _ = parse("""
correlation:
  enabled: true
  rules:
    - id: test_rule
      root_cause:
        codes: ["A"]
      window_ms: 0
""")
    assert errors


def test_ValidateWarningLongWindow() -> None:
    _, errors, warnings = parse("""
correlation:
  enabled: true
  rules:
    - id: test_rule
      root_cause:
        codes: ["A"]
      window_ms: 120000
""")
    assert not errors and any('over 60 s' in w for w in warnings)


def test_ValidateDisabledConfigSkipsValidation() -> None:
    _, errors, warnings = parse('correlation:\n  enabled: false\n')
    assert (errors, warnings) == ([], [])


@pytest.mark.parametrize(('rules', 'warning'), [
    ('    - id: r\n      root_cause:\n        codes: ["A"]\n', 'no symptoms defined'),
    ('    - id: r\n      mode: auto_cluster\n      match: []\n', 'no match patterns defined'),
    ('    - id: r\n      mode: auto_cluster\n      min_count: 1\n      match:\n        - codes: ["A"]\n',
     'under 2'),
])
def test_what_medkit_only_warns_about_is_a_warning(rules: str, warning: str) -> None:
    """config_parser.cpp validate_config: add_warning, not add_error, for these."""
    _, errors, warnings = parse('correlation:\n  enabled: true\n  rules:\n' + rules)
    assert not errors and any(warning in w for w in warnings), warnings


def test_a_pattern_without_codes_is_a_warning() -> None:
    """validate_config: "Pattern '<id>' has no codes defined" is a warning."""
    _, errors, warnings = parse('correlation:\n  enabled: true\n  patterns:\n    empty:\n      codes: []\n'
                                '  rules:\n    - id: r\n      root_cause:\n        codes: ["A"]\n'
                                '      symptoms:\n        - pattern: empty\n')
    assert not errors and any('no codes defined' in w for w in warnings), warnings


# -- the node around the engine (fault_manager_node.cpp handle_report_fault / handle_clear_fault) ---------------

NS = 1_000_000_000
NODE_YAML = {'correlation': {'enabled': True, 'rules': [
    {'id': 'estop', 'mode': 'hierarchical', 'root_cause': {'codes': ['ESTOP_001']},
     'symptoms': [{'codes': ['MOTOR_*']}], 'window_ms': 1000}]},
    'snapshots': {'default_topics': ['/t'], 'recapture_cooldown_sec': 60}}


def node(section: dict[str, Any] = NODE_YAML) -> Any:
    from bagfault.fault_manager.config import parse_fault_manager
    from bagfault.fault_manager.observer import FaultManagerObserver
    config = parse_fault_manager(section, lambda p, m: pytest.fail(m))
    return FaultManagerObserver(config, None, {'/t': ('std_msgs/msg/Empty', 'ros2msg', '')},  # type: ignore[arg-type]
                                None, lambda event: None)  # type: ignore[arg-type]


def report(observer: Any, code: str, time: int, severity: int = 2, passed: bool = False) -> None:
    from bagfault.fault_manager.model import FAILED, PASSED, Report
    assert observer.manager.report(Report(code, PASSED if passed else FAILED, severity, '', '/n', time))


def test_muting_follows_this_report_not_the_muted_list() -> None:
    """should_mute comes from this report's correlation result; PASSED reports are never muted."""
    observer = node()
    fm = observer.manager
    report(observer, 'ESTOP_001', 0, severity=3)
    report(observer, 'MOTOR_X', 100_000_000)      # symptom: confirmed, muted
    report(observer, 'MOTOR_X', 500_000_000)      # still in the window: muted again
    report(observer, 'MOTOR_X', 2 * NS)           # window over: not a symptom now, its update is published
    report(observer, 'MOTOR_X', 3 * NS, passed=True)  # PASSED (healing off): an update, muted or not
    events = [(e.time, e.event_type, e.fault.fault_code) for e in fm.events]
    assert events == [(0, 'fault_confirmed', 'ESTOP_001'), (2 * NS, 'fault_updated', 'MOTOR_X'),
                      (3 * NS, 'fault_updated', 'MOTOR_X')]
    assert [f.fault_code for f in fm.list_faults().faults] == ['ESTOP_001']  # still in the muted list


def test_a_muted_symptom_that_confirms_is_captured() -> None:
    """handle_report_fault enqueues the capture on just_confirmed, whatever should_mute says."""
    observer = node()
    report(observer, 'ESTOP_001', 0, severity=3)
    report(observer, 'MOTOR_X', 100_000_000)
    assert [(c.code, c.time) for c in observer.snapshots.captures] == [('ESTOP_001', 0), ('MOTOR_X', 100_000_000)]
    assert [e.fault.fault_code for e in observer.manager.events] == ['ESTOP_001']


def test_clear_fault_resets_the_recapture_cooldown_of_the_code_and_its_symptoms() -> None:
    """handle_clear_fault erases last_capture_times_ of the code and of every auto-cleared symptom."""
    observer = node()
    report(observer, 'ESTOP_001', 0, severity=3)
    report(observer, 'MOTOR_X', 100_000_000)
    report(observer, 'OTHER', 200_000_000)
    observer.manager.clear('ESTOP_001', 1 * NS)
    observer.manager.clear('OTHER', 1 * NS)
    report(observer, 'ESTOP_001', 2 * NS, severity=3)
    report(observer, 'MOTOR_X', 2 * NS + 100_000_000)
    report(observer, 'OTHER', 2 * NS + 200_000_000)
    codes = [c.code for c in observer.snapshots.captures]
    assert codes == ['ESTOP_001', 'MOTOR_X', 'OTHER', 'ESTOP_001', 'MOTOR_X', 'OTHER']


def test_a_heal_does_not_reset_the_recapture_cooldown() -> None:
    """Only ClearFault evicts the cooldown; a fault that heals and confirms again within it is not captured."""
    observer = node({'healing_enabled': True, 'healing_threshold': 1,
                     'snapshots': {'default_topics': ['/t'], 'recapture_cooldown_sec': 60}})
    report(observer, 'F', 0)
    report(observer, 'F', 1 * NS, passed=True)
    report(observer, 'F', 2 * NS)
    assert observer.manager.faults['F'].status == 'CONFIRMED'
    assert [c.time for c in observer.snapshots.captures] == [0]


def test_snapshot_skip_clear_keeps_the_symptom_muted_and_its_cooldown() -> None:
    """skip_correlation_auto_clear: the engine is not asked, the symptom stays muted and on cooldown."""
    observer = node()
    report(observer, 'ESTOP_001', 0, severity=3)
    report(observer, 'MOTOR_X', 100_000_000)
    observer.manager.clear('ESTOP_001', 1 * NS, skip_correlation_auto_clear=True)
    assert [m.fault_code for m in observer.manager.list_faults(include_muted=True).muted_faults] == ['MOTOR_X']
    observer.manager.clear('MOTOR_X', 1 * NS, skip_correlation_auto_clear=True)
    report(observer, 'MOTOR_X', 2 * NS)  # cleared itself: its own cooldown went with it
    assert [c.code for c in observer.snapshots.captures] == ['ESTOP_001', 'MOTOR_X', 'MOTOR_X']


@pytest.mark.parametrize('patterns', [
    [{'match': 'MOTOR_A.*', 'topics': ['/a']}, {'match': 'MOTOR_.*', 'topics': ['/any']}],
    {'MOTOR_A.*': ['/a'], 'MOTOR_.*': ['/any']},  # medkit's own map form (config/snapshots.yaml)
])
def test_the_lexicographically_first_matching_regex_wins(patterns: Any) -> None:
    """SnapshotConfig::patterns is a std::map: 'MOTOR_.*' sorts before 'MOTOR_A.*' ('.' < 'A')."""
    from bagfault.fault_manager.config import parse_fault_manager
    config = parse_fault_manager({'snapshots': {'patterns': patterns, 'default_topics': ['/d']}},
                                 lambda p, m: pytest.fail(m))
    assert config.snapshots.topics_for('MOTOR_A1') == ('/any',)
    assert config.snapshots.topics_for('SENSOR') == ('/d',)


INLINE_CLUSTER = """
correlation:
  enabled: true
  rules:
    - id: inline_cluster
      mode: auto_cluster
      match:
        - codes: [SENSOR_A, SENSOR_B, SENSOR_C]
      min_count: 2
      window_ms: 500
"""


def test_an_inline_codes_item_of_an_auto_cluster_match_matches_nothing() -> None:
    """medkit's parse_match_refs (config_parser.cpp:111-121) keeps only `{pattern: ...}` items of a match list:
    `{codes: [...]}` there gives a rule that matches nothing, so three failures form no cluster and mute none."""
    _, errors, warnings = parse(INLINE_CLUSTER)
    assert errors == [] and any('only {pattern: ID} items of an auto_cluster match' in w for w in warnings)
    engine = Engine(INLINE_CLUSTER)
    assert [engine.process_fault(code, 'ERROR') for code in ('SENSOR_A', 'SENSOR_B', 'SENSOR_C')] == [False] * 3
    assert engine.cluster_count() == 0 and engine.muted_count() == 0


TWO_RULES_ON_ONE_ROOT = """
correlation:
  enabled: true
  rules:
    - id: keep_symptoms
      mode: hierarchical
      root_cause: {codes: [ESTOP_001]}
      symptoms: [{codes: [MOTOR_COMM_FL]}]
      window_ms: 500
      auto_clear_with_root: false
    - id: clear_symptoms
      mode: hierarchical
      root_cause: {codes: [ESTOP_001]}
      symptoms: [{codes: [DRIVE_FAULT]}]
      window_ms: 500
      auto_clear_with_root: true
"""


def test_any_rule_on_the_root_with_auto_clear_clears_its_symptoms() -> None:
    """medkit's process_clear (correlation_engine.cpp:95-119) asks the pending root's rule first and then every
    hierarchical rule on that root: the second rule's auto_clear_with_root: true clears the symptom the first
    rule muted, where bagfault used to consult only the first rule."""
    engine = Engine(TWO_RULES_ON_ONE_ROOT)
    engine.process_fault('ESTOP_001', 'CRITICAL')
    assert engine.process_fault('MOTOR_COMM_FL', 'ERROR') is True
    assert engine.engine.process_clear('ESTOP_001') == ['MOTOR_COMM_FL']
    assert engine.muted_count() == 0


# -- config parser: type conversions and parsing (test_correlation_config_parser.cpp:32-304) -----------------
# medkit keeps pattern ids and wildcard strings; bagfault resolves them into patterns when it parses. So where
# medkit's test compares a stored wildcard, this compares what that wildcard matches: codes it must match and
# a code it must not, taken from the wildcard itself.

def matches(patterns: list[Any], code: str) -> list[bool]:
    return [p.match(code) for p in patterns]


def mode_of(written: str) -> tuple[str | None, list[str]]:
    config, errors, _ = parse(f"""
correlation:
  enabled: true
  rules:
    - id: r
      mode: "{written}"
      root_cause: {{codes: [R]}}
      symptoms: [{{codes: [S]}}]
      match: [{{codes: [S]}}]
""")
    return (config.rules[0].mode if config and config.rules else None), errors


def representative_of(written: str) -> tuple[str | None, list[str]]:
    config, errors, _ = parse(f"""
correlation:
  enabled: true
  patterns: {{p: {{codes: [S_*]}}}}
  rules:
    - {{id: r, mode: auto_cluster, match: [{{pattern: p}}], representative: "{written}"}}
""")
    return (config.rules[0].representative if config and config.rules else None), errors


def test_StringToModeHierarchical() -> None:
    assert [mode_of(w)[0] for w in ('hierarchical', 'HIERARCHICAL', 'Hierarchical')] == ['hierarchical'] * 3


def test_StringToModeAutoCluster() -> None:
    assert [mode_of(w)[0] for w in ('auto_cluster', 'autocluster', 'cluster')] == ['auto_cluster'] * 3


def test_StringToModeInvalid() -> None:
    for written in ('invalid', ''):
        mode, errors = mode_of(written)
        assert mode is None and len(errors) == 1  # medkit: std::invalid_argument


def test_StringToRepresentative() -> None:
    assert [representative_of(w)[0] for w in ('first', 'most_recent', 'recent', 'highest_severity', 'severity')] \
        == ['first', 'most_recent', 'most_recent', 'highest_severity', 'highest_severity']


def test_StringToRepresentativeInvalid() -> None:
    _, errors = representative_of('invalid')
    assert len(errors) == 1


def test_ParseEmptyConfig() -> None:
    config, errors, _ = parse('# Empty config - no correlation section\n')
    assert (config.enabled, errors) == (False, [])


def test_ParsePatterns() -> None:
    """Two patterns, motor_errors with MOTOR_COMM_* then MOTOR_TIMEOUT_*; a rule using each shows them."""
    config, errors, _ = parse("""
correlation:
  enabled: true
  patterns:
    motor_errors:
      codes: ["MOTOR_COMM_*", "MOTOR_TIMEOUT_*"]
    sensor_issues:
      codes: ["SENSOR_*"]
  rules:
    - {id: a, root_cause: {codes: [R]}, symptoms: [{pattern: motor_errors}]}
    - {id: b, root_cause: {codes: [R]}, symptoms: [{pattern: sensor_issues}]}
""")
    assert (config.enabled, errors) == (True, [])
    motor, sensor = (rule.symptom_codes for rule in config.rules)
    assert len(motor) == 2 and len(sensor) == 1
    assert matches(motor, 'MOTOR_COMM_1') == [True, False] and matches(motor, 'MOTOR_TIMEOUT_1') == [False, True]
    assert matches(sensor, 'SENSOR_LIDAR') == [True] and matches(sensor, 'MOTOR_COMM_1') == [False]


def test_ParseHierarchicalRule() -> None:
    config, errors, _ = parse("""
correlation:
  enabled: true
  patterns:
    motor_errors:
      codes: ["MOTOR_COMM_*"]
  rules:
    - id: estop_cascade
      name: "E-Stop Cascade"
      mode: hierarchical
      root_cause:
        codes: ["ESTOP_001"]
      symptoms:
        - pattern: motor_errors
      window_ms: 1000
      mute_symptoms: true
      auto_clear_with_root: true
""")
    assert (config.enabled, errors, len(config.rules)) == (True, [], 1)
    rule = config.rules[0]
    assert (rule.id, rule.name, rule.mode, rule.window_ms) == ('estop_cascade', 'E-Stop Cascade', 'hierarchical',
                                                               1000)
    assert matches(rule.root_codes, 'ESTOP_001') == [True] and matches(rule.root_codes, 'ESTOP_0010') == [False]
    assert matches(rule.symptom_codes, 'MOTOR_COMM_3') == [True]
    assert (rule.mute_symptoms, rule.auto_clear_with_root) == (True, True)


def test_ParseHierarchicalRuleWithInlineCodes() -> None:
    config, errors, warnings = parse("""
correlation:
  enabled: true
  rules:
    - id: inline_test
      name: "Inline Codes Test"
      mode: hierarchical
      root_cause:
        codes: ["ESTOP_001"]
      symptoms:
        - codes: ["MOTOR_COMM_*", "MOTOR_TIMEOUT_*"]
        - codes: ["DRIVE_*"]
      window_ms: 1000
""")
    rule = config.rules[0]
    assert (rule.id, rule.mode, len(rule.symptom_codes)) == ('inline_test', 'hierarchical', 3)
    assert [matches(rule.symptom_codes, code) for code in ('MOTOR_COMM_1', 'MOTOR_TIMEOUT_1', 'DRIVE_1')] == [
        [True, False, False], [False, True, False], [False, False, True]]
    assert (errors, warnings) == ([], [])  # inline codes count as symptoms: valid


def test_ParseHierarchicalRuleMixedSymptoms() -> None:
    config, errors, warnings = parse("""
correlation:
  enabled: true
  patterns:
    sensor_errors:
      codes: ["SENSOR_*"]
  rules:
    - id: mixed_test
      mode: hierarchical
      root_cause:
        codes: ["ESTOP_001"]
      symptoms:
        - pattern: sensor_errors
        - codes: ["MOTOR_*", "DRIVE_*"]
""")
    (rule,) = config.rules
    assert [matches(rule.symptom_codes, code) for code in ('SENSOR_1', 'MOTOR_1', 'DRIVE_1')] == [
        [True, False, False], [False, True, False], [False, False, True]]
    assert (errors, warnings) == ([], [])


def test_ParseAutoClusterRule() -> None:
    config, errors, _ = parse("""
correlation:
  enabled: true
  patterns:
    comm_errors:
      codes: ["*_COMM_*", "*_TIMEOUT"]
  rules:
    - id: comm_storm
      name: "Communication Storm"
      mode: auto_cluster
      match:
        - pattern: comm_errors
      min_count: 3
      window_ms: 500
      show_as_single: true
      representative: highest_severity
""")
    (rule,) = config.rules
    assert (rule.id, rule.mode, rule.min_count, rule.window_ms, rule.show_as_single, rule.representative) == (
        'comm_storm', 'auto_cluster', 3, 500, True, 'highest_severity')
    assert matches(rule.match_codes, 'MOTOR_COMM_FAIL') == [True, False]
    assert matches(rule.match_codes, 'LIDAR_TIMEOUT') == [False, True] and errors == []


def test_ParseMultipleRules() -> None:
    config, errors, _ = parse("""
correlation:
  enabled: true
  default_window_ms: 500
  patterns:
    motor_errors:
      codes: ["MOTOR_*"]
    sensor_issues:
      codes: ["SENSOR_*"]
  rules:
    - id: rule1
      mode: hierarchical
      root_cause:
        codes: ["ROOT1"]
      symptoms:
        - pattern: motor_errors
    - id: rule2
      mode: auto_cluster
      match:
        - pattern: sensor_issues
      min_count: 2
""")
    assert [(r.id, r.mode) for r in config.rules] == [('rule1', 'hierarchical'), ('rule2', 'auto_cluster')]
    assert errors == []


def test_ParseDefaultValues() -> None:
    config, _, _ = parse("""
correlation:
  enabled: true
  rules:
    - id: minimal_rule
      root_cause:
        codes: ["TEST"]
""")
    (rule,) = config.rules
    assert (rule.mode, rule.window_ms, rule.mute_symptoms, rule.auto_clear_with_root) == ('hierarchical', 500,
                                                                                          True, True)


def test_ParseFullExampleConfig() -> None:
    config, errors, warnings = parse("""
correlation:
  enabled: true
  default_window_ms: 500

  patterns:
    motor_errors:
      codes: ["MOTOR_COMM_*", "MOTOR_TIMEOUT_*"]
    sensor_issues:
      codes: ["SENSOR_*_TIMEOUT", "SENSOR_*_DISCONNECT"]
    drive_faults:
      codes: ["DRIVE_*"]

  rules:
    - id: estop_cascade
      name: "E-Stop Cascade"
      mode: hierarchical
      root_cause:
        codes: ["ESTOP_001"]
      symptoms:
        - pattern: motor_errors
        - pattern: drive_faults
      window_ms: 1000
      mute_symptoms: true
      auto_clear_with_root: true

    - id: ota_expected
      name: "OTA Expected Timeouts"
      mode: hierarchical
      root_cause:
        codes: ["OTA_UPDATE_ACTIVE"]
      symptoms:
        - pattern: motor_errors
        - pattern: sensor_issues
      window_ms: 5000
      mute_symptoms: true

    - id: comm_storm
      name: "Communication Storm"
      mode: auto_cluster
      match:
        - pattern: motor_errors
        - pattern: sensor_issues
      min_count: 3
      window_ms: 500
      show_as_single: true
      representative: highest_severity
""")
    assert (config.enabled, config.default_window_ms, len(config.rules)) == (True, 500, 3)
    assert (errors, warnings) == ([], [])  # valid
    ota = config.rules[1]
    assert matches(ota.symptom_codes, 'SENSOR_LIDAR_TIMEOUT') == [False, False, True, False]
    assert matches(ota.symptom_codes, 'SENSOR_LIDAR_STALE') == [False] * 4
