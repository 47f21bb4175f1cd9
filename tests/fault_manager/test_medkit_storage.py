"""medkit's own FaultStorage unit tests, ported: names and expected values from
selfpatch/ros2_medkit src/ros2_medkit_fault_manager/test/test_fault_manager.cpp at commit 505bc2d5.

Each test names the medkit case it ports; the reports, thresholds and
expected statuses, counts and sources are those of its EXPECT/ASSERT lines.
Time plays no part in these cases; every report is at bag time 0.
"""

from __future__ import annotations

from bagfault.fault_manager.config import FaultManagerConfig, Thresholds
from bagfault.fault_manager.manager import FaultManager
from bagfault.fault_manager.model import CRITICAL, ERROR, FAILED, PASSED, Report


def storage(**thresholds: object) -> FaultManager:
    return FaultManager(FaultManagerConfig(thresholds=Thresholds(**thresholds)))  # type: ignore[arg-type]


def failed(fm: FaultManager, code: str = 'FAULT_1', source: str = '/node1', severity: int = ERROR) -> None:
    assert fm.report(Report(code, FAILED, severity, 'Test', source, 0))


def passed(fm: FaultManager, code: str = 'FAULT_1', source: str = '/node1') -> None:
    assert fm.report(Report(code, PASSED, 0, '', source, 0))


def test_ContinuouslyActiveFaultDoesNotInflateOccurrenceCount() -> None:
    fm = storage()
    for _ in range(25):
        failed(fm, 'TANK_OVERFILL', '/tank')
    fault = fm.faults['TANK_OVERFILL']
    assert (fault.occurrence_count, fault.status) == (1, 'CONFIRMED')


def test_ListFaultsDefaultReturnsConfirmedOnly() -> None:
    fm = storage()
    failed(fm)
    faults = fm.list_faults().faults
    assert [f.status for f in faults] == ['CONFIRMED']


def test_InvalidStatusDefaultsToConfirmed() -> None:
    fm = storage()
    failed(fm)
    faults = fm.list_faults(['INVALID_STATUS']).faults
    assert [f.status for f in faults] == ['CONFIRMED']


def test_FaultStaysPrefailedAboveThreshold() -> None:
    fm = storage(confirmation_threshold=-3)
    failed(fm, source='/node1')
    failed(fm, source='/node2')
    fault = fm.faults['FAULT_1']
    assert (fault.occurrence_count, fault.status) == (1, 'PREFAILED')


def test_FaultConfirmsAtThreshold() -> None:
    fm = storage(confirmation_threshold=-3)
    for source in ('/node1', '/node2', '/node3'):
        failed(fm, source=source)
    fault = fm.faults['FAULT_1']
    assert (fault.occurrence_count, fault.status) == (1, 'CONFIRMED')


def test_ConfirmedFaultStaysConfirmed() -> None:
    fm = storage()
    for i in range(4):
        failed(fm, source=f'/node{i}')
    fault = fm.faults['FAULT_1']
    assert (fault.occurrence_count, fault.status) == (1, 'CONFIRMED')


def test_MultiSourceConfirmsFault() -> None:
    fm = storage()
    for source in ('/sensor3', '/sensor1', '/sensor2'):
        failed(fm, 'MOTOR_OVERHEAT', source)
    fault = fm.faults['MOTOR_OVERHEAT']
    assert fault.status == 'CONFIRMED'
    assert fault.reporting_sources == ['/sensor1', '/sensor2', '/sensor3']  # medkit keeps a std::set: sorted


def test_SameSourceMultipleReportsConfirms() -> None:
    fm = storage()
    for _ in range(3):
        failed(fm)
    fault = fm.faults['FAULT_1']
    assert (fault.occurrence_count, fault.status, len(fault.reporting_sources)) == (1, 'CONFIRMED', 1)


def test_CriticalSeverityBypassesDebounce() -> None:
    fm = storage(confirmation_threshold=-5)
    failed(fm, severity=CRITICAL)
    assert fm.faults['FAULT_1'].status == 'CONFIRMED'


def test_ClearedFaultReactivationRestartsDebounce() -> None:
    fm = storage(confirmation_threshold=-3)
    for source in ('/node1', '/node2', '/node3'):
        failed(fm, source=source)
    assert fm.faults['FAULT_1'].status == 'CONFIRMED'
    assert fm.clear('FAULT_1', 0)
    failed(fm, source='/node4')
    assert fm.faults['FAULT_1'].status == 'PREFAILED'  # needs 2 more FAILED
    failed(fm, source='/node5')
    failed(fm, source='/node6')
    assert fm.faults['FAULT_1'].status == 'CONFIRMED'


def test_PassedEventIncrementsCounter() -> None:
    fm = storage(confirmation_threshold=-3, healing_threshold=3)
    failed(fm, source='/node1')
    failed(fm, source='/node2')
    for _ in range(3):
        passed(fm)
    assert fm.faults['FAULT_1'].status == 'PREPASSED'  # -2 + 3 = +1


def test_HeartbeatHealClampedAndStatusLatched() -> None:
    fm = storage(confirmation_threshold=-1, healing_enabled=True, healing_threshold=3)
    failed(fm)
    assert fm.faults['FAULT_1'].status == 'CONFIRMED'
    for _ in range(100):
        passed(fm)
    assert fm.faults['FAULT_1'].status == 'HEALED'
    for _ in range(3):  # the counter walks 3 -> 0: still latched
        failed(fm)
        assert fm.faults['FAULT_1'].status == 'HEALED'
    failed(fm)
    assert fm.faults['FAULT_1'].status == 'CONFIRMED'


def test_ConfirmedLatchSurvivesFailedAtPositiveCounter() -> None:
    fm = storage(confirmation_threshold=-3, healing_threshold=3)
    failed(fm, 'F', '/n', CRITICAL)
    assert fm.faults['F'].status == 'CONFIRMED'
    for _ in range(3):
        passed(fm, 'F', '/n')
    assert fm.faults['F'].status == 'CONFIRMED'
    failed(fm, 'F', '/n')
    assert fm.faults['F'].status == 'CONFIRMED'


def test_HealedLatchSurvivesPassedAtNegativeCounter() -> None:
    fm = storage(confirmation_threshold=-3, healing_enabled=True, healing_threshold=3)
    failed(fm, 'F', '/n')
    for _ in range(4):
        passed(fm, 'F', '/n')
    assert fm.faults['F'].status == 'HEALED'
    for i in range(5):  # +3 -> -2, latched HEALED
        failed(fm, 'F', '/n')
        assert fm.faults['F'].status == 'HEALED', f'latch broke after {i + 1}'
    passed(fm, 'F', '/n')
    assert fm.faults['F'].status == 'HEALED'


def test_HealingThresholdZeroHealsOnSinglePassed() -> None:
    fm = storage(confirmation_threshold=-1, healing_enabled=True, healing_threshold=0)
    failed(fm, 'F', '/n')
    assert fm.faults['F'].status == 'CONFIRMED'
    passed(fm, 'F', '/n')
    assert fm.faults['F'].status == 'HEALED'


def test_ClampDebounceCounterBounds() -> None:
    """DebounceHelpers.ClampDebounceCounterBounds, through reports: the counter stays in [-2, 2]."""
    fm = storage(confirmation_threshold=-2, healing_threshold=2)
    for _ in range(100):
        failed(fm)
    assert fm.faults['FAULT_1'].counter == -2
    for _ in range(100):
        passed(fm)
    assert fm.faults['FAULT_1'].counter == 2
    passed(fm)
    failed(fm)
    assert fm.faults['FAULT_1'].counter == 1


def test_TimeBasedConfirmationDisabledByDefault() -> None:
    fm = storage(confirmation_threshold=-3)
    failed(fm)
    fm.advance(20 * 1_000_000_000)
    assert fm.faults['FAULT_1'].status == 'PREFAILED'


def test_TimeBasedConfirmationWhenEnabled() -> None:
    fm = storage(confirmation_threshold=-3, auto_confirm_after_sec=10.0)
    failed(fm)
    fm.advance(5 * 1_000_000_000)
    assert fm.faults['FAULT_1'].status == 'PREFAILED'
    fm.advance(15 * 1_000_000_000)
    assert fm.faults['FAULT_1'].status == 'CONFIRMED'
    assert fm.events == []  # fault_manager_node's timer publishes no FaultEvent for it
