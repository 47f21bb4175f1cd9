"""The fault manager: debounce per fault code, correlation, events, ListFaults.

Semantics are those of ros2_medkit's fault manager (see
design/fault_manager.md), evaluated on bag time: every report carries its
bag time, and time-based confirmation fires exactly at
last_failed + auto_confirm_after_sec.
"""

from __future__ import annotations

import heapq
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

from bagfault.fault_manager.correlation import CorrelationEngine
from bagfault.fault_manager.model import (
    CLEARED,
    CONFIRMED,
    CRITICAL,
    EVENT_CLEARED,
    EVENT_CONFIRMED,
    EVENT_UPDATED,
    FAILED,
    HEALED,
    PASSED,
    PREFAILED,
    PREPASSED,
    STATUSES,
    Fault,
    FaultManagerEvent,
    ListFaultsResult,
    Report,
    valid_code,
)
from bagfault.units import NS

if TYPE_CHECKING:
    from bagfault.fault_manager.config import FaultManagerConfig, Thresholds



def reject_reason(report: Report) -> str | None:
    """Why a report is invalid, or None."""
    if not valid_code(report.fault_code):
        return f'invalid fault code {report.fault_code!r}'
    if report.event_type not in (FAILED, PASSED):
        return f'invalid event type {report.event_type}'
    if report.event_type == FAILED and not 0 <= report.severity <= CRITICAL:
        return f'invalid severity {report.severity}'
    if not report.source_id:
        return 'empty source_id'
    return None


class FaultManager:
    """Aggregates reports into faults and emits FaultEvents."""

    def __init__(self, config: FaultManagerConfig) -> None:
        self.config = config
        self.faults: dict[str, Fault] = {}
        self.correlation = CorrelationEngine(config.correlation) if config.correlation else None
        self.events: list[FaultManagerEvent] = []
        self.rejected: list[tuple[Report, str]] = []
        self.listeners: list[Callable[[FaultManagerEvent], None]] = []
        self.status_listeners: list[Callable[[str, str, int], None]] = []
        self.confirm_listeners: list[Callable[[str, int], None]] = []  # a report confirmed a fault, muted or not
        self._timers: list[tuple[int, int, str, int]] = []
        self._counter = 0

    # -- time -----------------------------------------------------------------
    def advance(self, time: int) -> None:
        """Fire time-based confirmations due before `time`."""
        timers = self._timers
        while timers and timers[0][0] < time:
            due, _, code, wait = heapq.heappop(timers)
            fault = self.faults.get(code)
            if fault is None or fault.status != PREFAILED:
                continue
            if due - fault.last_occurred >= wait:  # a later FAILED re-armed the timer
                self._set(fault, CONFIRMED, due)  # as medkit's timer: the status only, no FaultEvent, no snapshot

    def next_timer(self) -> int | None:
        """Bag time of the next pending time-based confirmation."""
        return self._timers[0][0] if self._timers else None

    # -- reports ----------------------------------------------------------------
    def report(self, report: Report) -> bool:
        """Apply a ReportFault; return False when it is rejected."""
        reason = reject_reason(report)
        if reason:
            self.rejected.append((report, reason))
            return False
        self.advance(report.time)
        thresholds = self.config.thresholds_for(report.source_id)
        fault = self.faults.get(report.fault_code)
        if report.event_type == PASSED:
            if fault is None or fault.status == CLEARED:
                return True
            self._passed(fault, report, thresholds)
            return True
        muted = False
        if self.correlation is not None:
            muted = self.correlation.process_failed(report.fault_code, report.severity, report.time)
        self._failed(fault, report, thresholds, muted)
        return True

    def _status(self, fault: Fault, thresholds: Thresholds) -> str:
        conf, heal = thresholds.confirmation_threshold, thresholds.healing_threshold
        if fault.counter <= conf:
            return CONFIRMED
        if thresholds.healing_enabled and fault.counter >= heal:
            return HEALED
        if fault.status in (CONFIRMED, HEALED):
            return fault.status
        if fault.counter < 0:
            return PREFAILED
        if fault.counter > 0:
            return PREPASSED
        return fault.status

    def _failed(self, fault: Fault | None, report: Report, thresholds: Thresholds, muted: bool) -> None:
        time = report.time
        if fault is None or fault.status == CLEARED:
            fault = self._occurred(fault, report)
            self._set(fault, CONFIRMED if report.severity == CRITICAL else self._status(fault, thresholds), time)
            if fault.status == CONFIRMED:
                self._confirmed(fault, time, muted)
            self._arm(fault, thresholds)
            return
        before = fault.status
        fault.counter = _clamp(_clamp(fault.counter, thresholds) - 1, thresholds)
        fault.last_occurred = time
        _reported(fault, report)
        self._set(fault, CONFIRMED if report.severity == CRITICAL else self._status(fault, thresholds), time)
        if fault.status == CONFIRMED and before != CONFIRMED:
            self._confirmed(fault, time, muted)
        elif fault.status == CONFIRMED and not muted:
            self._emit(time, EVENT_UPDATED, fault)
        self._arm(fault, thresholds)

    def _occurred(self, fault: Fault | None, report: Report) -> Fault:
        """A fault's first occurrence, or a cleared one's new occurrence: PREFAILED, its counter at -1."""
        time = report.time
        if fault is None:
            fault = Fault(report.fault_code, report.severity, report.description, time, time, 1, '',
                          [report.source_id], counter=-1)
            self.faults[report.fault_code] = fault
            return fault
        fault.counter, fault.first_occurred, fault.last_occurred = -1, time, time
        fault.occurrence_count += 1
        _reported(fault, report)
        fault.status = PREFAILED
        return fault

    def _confirmed(self, fault: Fault, time: int, muted: bool) -> None:
        """A report confirmed the fault: the event unless this report was muted, the capture either way (medkit)."""
        if not muted:
            self._emit(time, EVENT_CONFIRMED, fault)
        for listener in self.confirm_listeners:
            listener(fault.fault_code, time)

    def _passed(self, fault: Fault, report: Report, thresholds: Thresholds) -> None:
        before = fault.status
        fault.counter = _clamp(_clamp(fault.counter, thresholds) + 1, thresholds)
        fault.last_passed = report.time
        self._set(fault, self._status(fault, thresholds), report.time)
        if fault.status == HEALED and before != HEALED:
            self._emit(report.time, EVENT_CLEARED, fault)
        elif before == CONFIRMED and fault.status == CONFIRMED:  # muting applies to FAILED reports only (medkit)
            self._emit(report.time, EVENT_UPDATED, fault)

    def _arm(self, fault: Fault, thresholds: Thresholds) -> None:
        if fault.status == PREFAILED and thresholds.auto_confirm_after_sec > 0:
            self._counter += 1
            wait = round(thresholds.auto_confirm_after_sec * NS)
            heapq.heappush(self._timers, (fault.last_occurred + wait, self._counter, fault.fault_code, wait))

    def clear(self, code: str, time: int, *, skip_correlation_auto_clear: bool = False) -> bool:
        """ClearFault: status CLEARED, symptoms with it unless skipped; False for an unknown code."""
        self.advance(time)
        fault = self.faults.get(code)
        if fault is None:
            return False
        cleared: list[str] = []
        if self.correlation is not None and not skip_correlation_auto_clear:  # skipped: symptoms stay muted
            cleared = [s for s in self.correlation.process_clear(code) if s in self.faults]
        self._set(fault, CLEARED, time)
        for symptom in cleared:
            self._set(self.faults[symptom], CLEARED, time)
            if self.correlation is not None:
                self.correlation.process_clear(symptom)
        self._emit(time, EVENT_CLEARED, fault, tuple(cleared))
        return True

    def _set(self, fault: Fault, status: str, time: int) -> None:
        """Change a status and tell status listeners (assertions see PREFAILED too)."""
        if fault.status != status:
            fault.status = status
            for listener in self.status_listeners:
                listener(fault.fault_code, status, time)

    def _emit(self, time: int, kind: str, fault: Fault, cleared: Sequence[str] = ()) -> None:
        event = FaultManagerEvent(time, kind, fault.copy(), tuple(cleared))
        self.events.append(event)
        for listener in self.listeners:
            listener(event)

    # -- queries ------------------------------------------------------------------
    def _listed(self, wanted: set[str], hidden: set[str], severity: int | None) -> list[Fault]:
        """Copies of the faults in a wanted status, not hidden, of the severity (any when None), by code."""
        return [f.copy() for _, f in sorted(self.faults.items())
                if f.status in wanted and f.fault_code not in hidden and severity in (None, f.severity)]

    def list_faults(
        self,
        statuses: Sequence[str] = (),
        *,
        filter_by_severity: bool = False,
        severity: int = 0,
        include_muted: bool = False,
        include_clusters: bool = False,
    ) -> ListFaultsResult:
        """ListFaults: empty statuses (or only unknown names) means CONFIRMED only; muted symptoms hidden unless
        asked for (cluster members never are); in fault code order (medkit keeps faults in a std::map)."""
        muted = self.correlation.muted_faults() if self.correlation else []
        hidden = set() if include_muted else {m.fault_code for m in muted}
        faults = self._listed(_wanted(statuses), hidden, severity if filter_by_severity else None)
        clusters = self.correlation.clusters() if self.correlation else []
        return ListFaultsResult(faults, len(muted), muted if include_muted else [], len(clusters),
                                clusters if include_clusters else [])


def _wanted(statuses: Sequence[str]) -> set[str]:
    """The statuses asked for (unknown names left out); CONFIRMED when none is left."""
    return {s for s in statuses if s in STATUSES} or {CONFIRMED}


def _reported(fault: Fault, report: Report) -> None:
    """A report's source, severity and description into the fault (sources as medkit's std::set keeps them)."""
    if report.source_id not in fault.reporting_sources:
        fault.reporting_sources = sorted([*fault.reporting_sources, report.source_id])
    fault.severity = max(fault.severity, report.severity)
    if report.description:
        fault.description = report.description


def _clamp(counter: int, thresholds: Thresholds) -> int:
    """The debounce counter within [confirmation_threshold, healing_threshold] (medkit's clamp_debounce_counter)."""
    return max(thresholds.confirmation_threshold, min(thresholds.healing_threshold, counter))


__all__ = ['PASSED', 'PREPASSED', 'FaultManager', 'reject_reason']
