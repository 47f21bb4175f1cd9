"""The oracle cases of design/fault_manager.md, with their exact statuses, counts and events; where the design
page and medkit's code differ these follow the code, selfpatch/ros2_medkit at commit 505bc2d5."""

from __future__ import annotations

import pytest

from bagfault.fault_manager.config import FaultManagerConfig, Thresholds, parse_fault_manager
from bagfault.fault_manager.manager import FaultManager
from bagfault.fault_manager.model import CRITICAL, ERROR, FAILED, INFO, PASSED, WARN, Report

NS = 1_000_000_000


def manager(**thresholds) -> FaultManager:
    return FaultManager(FaultManagerConfig(thresholds=Thresholds(**thresholds)))


def failed(fm, code='F', time=0, severity=ERROR, source='/node', description=''):
    assert fm.report(Report(code, FAILED, severity, description, source, time))


def passed(fm, code='F', time=0, source='/node'):
    assert fm.report(Report(code, PASSED, 0, '', source, time))


def test_1_identical_failed_reports_confirm_once():
    fm = manager()
    for i in range(25):
        failed(fm, time=i)
    fault = fm.faults['F']
    assert (fault.status, fault.occurrence_count) == ('CONFIRMED', 1)
    assert [e.event_type for e in fm.events] == ['fault_confirmed'] + ['fault_updated'] * 24


def test_2_threshold_three_any_source():
    fm = manager(confirmation_threshold=-3)
    failed(fm, source='/a')
    failed(fm, source='/b')
    assert fm.faults['F'].status == 'PREFAILED' and not fm.events
    failed(fm, source='/c')
    assert fm.faults['F'].status == 'CONFIRMED'
    assert fm.faults['F'].reporting_sources == ['/a', '/b', '/c']


def test_positive_and_zero_thresholds_are_normalized():
    seen = []
    config = parse_fault_manager({'confirmation_threshold': 3, 'healing_threshold': -2}, lambda p, m: seen.append(m))
    assert (config.thresholds.confirmation_threshold, config.thresholds.healing_threshold) == (-3, 2) and not seen
    assert parse_fault_manager({'confirmation_threshold': 0}, seen.append).thresholds.confirmation_threshold == -1


def test_3_critical_confirms_at_once():
    fm = manager(confirmation_threshold=-5)
    failed(fm, severity=CRITICAL)
    assert fm.faults['F'].status == 'CONFIRMED' and fm.events[0].event_type == 'fault_confirmed'


def test_4_clear_then_failed_reactivates():
    fm = manager()
    failed(fm, time=1 * NS)
    assert fm.clear('F', 2 * NS)
    failed(fm, time=3 * NS)
    fault = fm.faults['F']
    assert (fault.status, fault.occurrence_count, fault.first_occurred) == ('CONFIRMED', 2, 3 * NS)
    assert [e.event_type for e in fm.events] == ['fault_confirmed', 'fault_cleared', 'fault_confirmed']


def test_5_passed_on_cleared_fault_is_ignored():
    fm = manager()
    failed(fm)
    fm.clear('F', 1)
    passed(fm, time=2)
    assert fm.faults['F'].status == 'CLEARED' and fm.faults['F'].last_passed == 0


def test_6_two_failed_three_passed_is_prepassed():
    fm = manager(confirmation_threshold=-3)
    failed(fm)
    failed(fm)
    for _ in range(3):
        passed(fm)
    assert (fm.faults['F'].status, fm.faults['F'].counter) == ('PREPASSED', 1)
    assert not fm.events


def test_7_confirmed_latches_without_healing():
    fm = manager()
    failed(fm, time=1000)
    passed(fm, time=9000)
    fault = fm.faults['F']
    assert (fault.status, fault.last_occurred, fault.last_passed) == ('CONFIRMED', 1000, 9000)


def test_8_healing_clamps_and_latches():
    fm = manager(healing_enabled=True, healing_threshold=3)
    failed(fm)
    for _ in range(4):
        passed(fm)
    assert fm.faults['F'].status == 'HEALED'
    for _ in range(100):
        passed(fm)
    assert (fm.faults['F'].status, fm.faults['F'].counter) == ('HEALED', 3)  # clamped after the step too
    for _ in range(3):
        failed(fm)
    assert fm.faults['F'].status == 'HEALED'
    failed(fm)
    assert fm.faults['F'].status == 'CONFIRMED'


def test_9_healed_needs_the_full_confirmation_threshold():
    fm = manager(confirmation_threshold=-3, healing_enabled=True, healing_threshold=3)
    for _ in range(3):
        failed(fm)
    for _ in range(10):
        passed(fm)
    assert fm.faults['F'].status == 'HEALED'
    for _ in range(5):
        failed(fm)
    assert fm.faults['F'].status == 'HEALED'


def test_10_heal_threshold_zero_heals_on_one_passed():
    fm = manager(healing_enabled=True, healing_threshold=0)
    failed(fm)
    passed(fm)
    assert fm.faults['F'].status == 'HEALED'


def test_11_time_confirmation_on_bag_time():
    fm = manager(confirmation_threshold=-3, auto_confirm_after_sec=10)
    failed(fm, time=100 * NS)
    fm.advance(105 * NS)
    assert fm.faults['F'].status == 'PREFAILED'
    statuses = []
    fm.status_listeners.append(lambda code, status, time: statuses.append((code, status, time)))
    fm.advance(115 * NS)
    assert fm.faults['F'].status == 'CONFIRMED'
    assert statuses == [('F', 'CONFIRMED', 110 * NS)]  # assertions see it on bag time
    assert fm.events == []  # medkit's auto-confirm timer changes the status only: no FaultEvent, no snapshot


def test_12_events():
    fm = manager()
    failed(fm, 'A', 1, severity=WARN)
    failed(fm, 'A', 2, severity=ERROR)
    assert fm.faults['A'].severity == ERROR
    assert fm.clear('A', 3)
    assert not fm.clear('UNKNOWN', 4)
    assert [(e.event_type, e.fault.status) for e in fm.events] == [
        ('fault_confirmed', 'CONFIRMED'), ('fault_updated', 'CONFIRMED'), ('fault_cleared', 'CLEARED')]
    heal = manager(confirmation_threshold=-1, healing_enabled=True, healing_threshold=1)
    failed(heal, 'H')
    passed(heal, 'H')
    passed(heal, 'H')
    assert [(e.event_type, e.fault.status) for e in heal.events] == [
        ('fault_confirmed', 'CONFIRMED'), ('fault_updated', 'CONFIRMED'), ('fault_cleared', 'HEALED')]


def test_reports_are_validated():
    fm = manager()
    for report in [Report('bad code', FAILED, ERROR, '', '/n', 0), Report('A..B', FAILED, ERROR, '', '/n', 0),
                   Report('X' * 129, FAILED, ERROR, '', '/n', 0), Report('OK', FAILED, 7, '', '/n', 0),
                   Report('OK', FAILED, ERROR, '', '', 0)]:
        assert not fm.report(report)
    assert not fm.faults and len(fm.rejected) == 5


# medkit test_entity_thresholds.cpp, ResolverTest (global: confirmation -1, healing off, healing threshold 3)
GLOBAL = {'confirmation_threshold': -1, 'healing_threshold': 3}


def resolver(*overrides: dict[str, object]):
    config = parse_fault_manager({**GLOBAL, 'overrides': list(overrides)}, lambda p, m: pytest.fail(m))
    return config.thresholds_for


def test_ResolverTest_EmptyResolverReturnsGlobal():
    result = resolver()('/sensors/lidar')
    assert (result.confirmation_threshold, result.healing_enabled, result.healing_threshold) == (-1, False, 3)


def test_ResolverTest_ExactMatch():
    result = resolver({'source': '/sensors/lidar', 'confirmation_threshold': -1, 'healing_threshold': 1})(
        '/sensors/lidar')
    assert (result.confirmation_threshold, result.healing_threshold) == (-1, 1)


def test_ResolverTest_PrefixMatch():
    assert resolver({'source': '/sensors/lidar', 'healing_threshold': 1})('/sensors/lidar/front').healing_threshold == 1


def test_ResolverTest_LongestPrefixWins():
    resolve = resolver({'source': '/sensors', 'confirmation_threshold': -5},
                       {'source': '/sensors/lidar', 'confirmation_threshold': -1})
    assert resolve('/sensors/lidar/front').confirmation_threshold == -1
    assert resolve('/sensors/camera').confirmation_threshold == -5


def test_ResolverTest_NoMatchReturnsGlobal():
    assert resolver({'source': '/sensors/lidar', 'confirmation_threshold': -5})(
        '/powertrain/motor').confirmation_threshold == -1


def test_ResolverTest_PrefixMatchRequiresPathBoundary():
    resolve = resolver({'source': '/sensors/lid', 'confirmation_threshold': -5})
    assert resolve('/sensors/lidar').confirmation_threshold == -1
    assert resolve('/sensors/lid/front').confirmation_threshold == -5


def test_ResolverTest_PartialOverrideMergesWithGlobal():
    result = resolver({'source': '/safety', 'healing_enabled': False})('/safety/estop')
    assert (result.confirmation_threshold, result.healing_enabled, result.healing_threshold) == (-1, False, 3)


def test_prefixes_are_compared_as_written():
    """From EntityThresholdResolver::resolve: the source must start with the prefix and end there or at '/'."""
    resolve = resolver({'source': '/powertrain/', 'confirmation_threshold': -5},
                       {'source': '/', 'confirmation_threshold': -7})
    assert resolve('/powertrain/motor').confirmation_threshold == -1  # next character 'm': no boundary
    assert resolve('/powertrain/').confirmation_threshold == -5
    assert resolve('/').confirmation_threshold == -7
    assert resolve('/x').confirmation_threshold == -1


def test_correlation_is_off_unless_enabled():
    """config_parser.cpp: enabled = get_bool(node, "enabled", false); the scenario says so as a warning."""
    section = {k: v for k, v in CORRELATION['correlation'].items() if k != 'enabled'}
    warnings: list[str] = []
    config = parse_fault_manager({'correlation': section}, lambda p, m: pytest.fail(m),
                                 lambda p, m: warnings.append(m))
    assert config.correlation is not None and not config.correlation.enabled
    assert warnings == ["correlation is off without `enabled: true` (medkit's default); its rules are checked but "
                        'not applied']
    fm = FaultManager(config)
    failed(fm, 'ESTOP_001', 0, severity=CRITICAL)
    failed(fm, 'MOTOR_A', 100 * MS)
    assert fm.list_faults().muted_count == 0 and [f.fault_code for f in fm.list_faults().faults] == [
        'ESTOP_001', 'MOTOR_A']


def test_an_override_carries_no_timed_confirmation_as_in_medkit():
    """medkit's EntityDebounceOverride has confirmation_threshold, healing_enabled and healing_threshold only; the
    resolver copies the global config and overrides those: an override's auto_confirm_after_sec is ignored (a
    warning here) and a source under it confirms after the global time."""
    warnings: list[tuple[object, str]] = []
    config = parse_fault_manager({'confirmation_threshold': -3, 'auto_confirm_after_sec': 10.0, 'overrides': [
        {'source': '/powertrain', 'confirmation_threshold': -2, 'auto_confirm_after_sec': 1.0}]},
        lambda p, m: pytest.fail(m), lambda p, m: warnings.append((p, m)))
    [(path, message)] = warnings
    assert path == ('fault_manager', 'overrides', 0, 'auto_confirm_after_sec') and 'ignored, as medkit' in message
    thresholds = config.thresholds_for('/powertrain/motor')
    assert (thresholds.confirmation_threshold, thresholds.auto_confirm_after_sec) == (-2, 10.0)
    fm = FaultManager(config)
    failed(fm, 'M', 0, source='/powertrain/motor')
    fm.advance(5 * NS)
    assert fm.faults['M'].status == 'PREFAILED'  # not confirmed after the override's 1 s
    fm.advance(11 * NS)
    assert fm.faults['M'].status == 'CONFIRMED'  # after the global 10 s


def test_per_source_overrides_longest_prefix_wins():
    config = parse_fault_manager({'confirmation_threshold': -3, 'overrides': [
        {'source': '/powertrain', 'confirmation_threshold': -1},
        {'source': '/powertrain/motor', 'confirmation_threshold': -2}]}, lambda p, m: pytest.fail(m))
    assert config.thresholds_for('/powertrain/temp').confirmation_threshold == -1
    assert config.thresholds_for('/powertrain/motor/left').confirmation_threshold == -2
    assert config.thresholds_for('/powertrainx').confirmation_threshold == -3
    fm = FaultManager(config)
    failed(fm, 'T', source='/powertrain/temp')
    assert fm.faults['T'].status == 'CONFIRMED'


CORRELATION = {
    'correlation': {
        'enabled': True,
        'default_window_ms': 500,
        'patterns': {'motor': {'codes': ['MOTOR_*']}, 'comm': {'codes': ['COMM_*']}},
        'rules': [
            {'id': 'estop', 'mode': 'hierarchical', 'root_cause': {'codes': ['ESTOP_001']},
             'symptoms': [{'pattern': 'motor'}, {'codes': ['DRIVE_FAULT']}]},
            {'id': 'storm', 'name': 'Communication storm', 'mode': 'auto_cluster', 'match': [{'pattern': 'comm'}],
             'min_count': 3, 'representative': 'highest_severity'},
        ],
    },
}


def correlated() -> FaultManager:
    return FaultManager(parse_fault_manager(CORRELATION, lambda p, m: pytest.fail(m)))


MS = 1_000_000


def test_13_symptoms_within_the_window_are_muted_and_cleared_with_root():
    fm = correlated()
    failed(fm, 'ESTOP_001', 0, severity=CRITICAL)
    failed(fm, 'MOTOR_COMM_FL', 100 * MS)
    failed(fm, 'DRIVE_FAULT', 400 * MS)
    result = fm.list_faults(include_muted=True)
    assert result.muted_count == 2
    assert {(m.fault_code, m.root_cause_code, m.delay_ms) for m in result.muted_faults} == {
        ('MOTOR_COMM_FL', 'ESTOP_001', 100), ('DRIVE_FAULT', 'ESTOP_001', 400)}
    assert [f.fault_code for f in fm.list_faults().faults] == ['ESTOP_001']
    assert [e.fault.fault_code for e in fm.events if e.event_type == 'fault_confirmed'] == ['ESTOP_001']
    fm.clear('ESTOP_001', 1 * NS)
    assert fm.events[-1].auto_cleared_codes == ('MOTOR_COMM_FL', 'DRIVE_FAULT')
    assert {c: f.status for c, f in fm.faults.items()} == dict.fromkeys(('ESTOP_001', 'MOTOR_COMM_FL', 'DRIVE_FAULT'), 'CLEARED')
    assert fm.list_faults().muted_count == 0


def test_13_symptom_before_root_or_after_window_is_not_muted():
    fm = correlated()
    failed(fm, 'MOTOR_EARLY', 0)
    failed(fm, 'ESTOP_001', 100 * MS)
    failed(fm, 'MOTOR_LATE', 700 * MS)
    assert fm.list_faults().muted_count == 0
    assert {f.fault_code for f in fm.list_faults().faults} == {'MOTOR_EARLY', 'ESTOP_001', 'MOTOR_LATE'}


def test_13_skip_correlation_auto_clear():
    fm = correlated()
    failed(fm, 'ESTOP_001', 0)
    failed(fm, 'MOTOR_X', 10 * MS)
    fm.clear('ESTOP_001', 1 * NS, skip_correlation_auto_clear=True)
    assert fm.events[-1].auto_cleared_codes == () and fm.faults['MOTOR_X'].status == 'CONFIRMED'
    # medkit skips the correlation engine entirely then: the symptom stays muted
    assert [m.fault_code for m in fm.list_faults(include_muted=True).muted_faults] == ['MOTOR_X']


def test_13_cluster_keeps_the_critical_one_as_representative():
    fm = correlated()
    failed(fm, 'COMM_A', 0, severity=ERROR)
    failed(fm, 'COMM_B', 100 * MS, severity=CRITICAL)
    failed(fm, 'COMM_C', 200 * MS, severity=WARN)
    result = fm.list_faults(include_clusters=True, include_muted=True)
    assert result.cluster_count == 1
    [cluster] = result.clusters
    assert (cluster.cluster_id, cluster.representative_code, cluster.count) == ('storm_1', 'COMM_B', 3)
    assert cluster.representative_severity == 'CRITICAL'
    # medkit mutes a cluster member's event only; ListFaults lists all three and counts none as muted
    assert (result.muted_count, result.muted_faults) == (0, [])
    assert [f.fault_code for f in fm.list_faults().faults] == ['COMM_A', 'COMM_B', 'COMM_C']
    assert [e.fault.fault_code for e in fm.events if e.event_type == 'fault_confirmed'] == ['COMM_A', 'COMM_B']


def test_13_cluster_window_is_fixed_from_the_first_fault():
    fm = correlated()
    failed(fm, 'COMM_A', 0)
    failed(fm, 'COMM_B', 100 * MS)
    failed(fm, 'COMM_C', 600 * MS)
    assert fm.list_faults(include_clusters=True).cluster_count == 0


@pytest.mark.parametrize(('section', 'problem'), [
    ({'correlation': {'rules': [{'id': 'a', 'mode': 'hierarchical', 'root_cause': {'codes': ['X']},
                                 'symptoms': [{'pattern': 'nope'}]}]}}, "unknown pattern 'nope'"),
    ({'correlation': {'rules': [{'id': 'a', 'mode': 'auto_cluster', 'match': [{'codes': ['X']}]},
                                {'id': 'a', 'mode': 'auto_cluster', 'match': [{'codes': ['Y']}]}]}},
     "duplicate rule id 'a'"),
    ({'correlation': {'rules': [{'id': 'a', 'mode': 'auto_cluster', 'window_ms': 0, 'match': [{'codes': ['X']}]}]}},
     '0 is not an integer from 1 to 4294967295'),
    ({'correlation': {'rules': [{'id': 'a', 'mode': 'auto_cluster', 'min_count': 0, 'match': [{'codes': ['X']}]}]}},
     '0 is not an integer from 1'),
    ({'correlation': {'rules': [{'id': 'a', 'mode': 'sideways'}]}}, "'sideways' is not"),
])
def test_correlation_config_errors(section, problem):
    section['correlation']['enabled'] = True  # a disabled block's mistakes are only warnings, as medkit skips it
    seen = []
    parse_fault_manager(section, lambda path, message: seen.append(message))
    assert any(problem in message for message in seen), seen


def test_list_faults_filters():
    fm = manager(confirmation_threshold=-2)
    failed(fm, 'A', severity=INFO)
    failed(fm, 'B', severity=CRITICAL)
    assert [f.fault_code for f in fm.list_faults().faults] == ['B']
    assert {f.fault_code for f in fm.list_faults(['CONFIRMED', 'PREFAILED']).faults} == {'A', 'B'}
    assert [f.fault_code for f in fm.list_faults(['PREFAILED', 'CONFIRMED'], filter_by_severity=True,
                                                 severity=INFO).faults] == ['A']


def test_a_warning_representative_is_written_as_medkit_writes_it():
    """medkit's correlation severity_to_string (correlation/types.cpp) writes severity 1 as WARNING."""
    fm = correlated()
    for offset, code in enumerate(('COMM_A', 'COMM_B', 'COMM_C')):
        failed(fm, code, offset * 100 * MS, severity=WARN)
    [cluster] = fm.list_faults(include_clusters=True, include_muted=True).clusters
    assert cluster.representative_severity == 'WARNING'


@pytest.mark.parametrize(('mode', 'representative', 'expected'), [
    ('Cluster', 'Severity', 'highest_severity'), ('AUTOCLUSTER', 'recent', 'most_recent'),
    ('auto_cluster', 'MostRecent', 'most_recent'), ('cluster', 'FIRST', 'first'),
])
def test_rule_names_are_read_as_medkit_reads_them(mode, representative, expected):
    """correlation/types.cpp string_to_mode and string_to_representative: lower-cased, with aliases."""
    section = {'correlation': {'enabled': True, 'rules': [
        {'id': 'storm', 'mode': mode, 'match': [{'codes': ['COMM_*']}], 'min_count': 2,
         'representative': representative}]}}
    config = parse_fault_manager(section, lambda p, m: pytest.fail(m))
    [rule] = config.correlation.rules
    assert (rule.mode, rule.representative) == ('auto_cluster', expected)
