"""Report sources: injected faults, /diagnostics, and field conditions on any topic.

Each turns what it sees in the output (or a recording) into ReportFault
calls, the way a monitoring node would have called the fault manager.
"""

from __future__ import annotations

import re
from typing import TYPE_CHECKING, Any

import numpy as np

from bagfault.fault_manager.model import ERROR, FAILED, PASSED, WARN, Report
from bagfault.units import NS

if TYPE_CHECKING:
    from bagfault.events import FaultEvent
    from bagfault.fault_manager.config import Condition, InjectedReport
    from bagfault.faults.fieldpath import FieldPath
    from bagfault.spec.model import Scenario

_INVALID = re.compile(r'[^A-Za-z0-9_.\-]+')


class InjectedReports:
    """A scenario fault with `report:` reports FAILED while active and PASSED after it ends.

    Without `report_period` a report goes out at every message of the
    injector's input topic (its output topic when injected in place);
    with it, every `report_period` seconds from the change, messages or not.
    """

    def __init__(self, reports: list[InjectedReport], scenario: Scenario, topics: set[str]) -> None:
        self.reports = {r.fault_id: r for r in reports}
        self.active: dict[str, bool] = {}
        self.watch: dict[str, list[InjectedReport]] = {}
        self._next: dict[str, int] = {}
        for report in reports:
            fault = scenario.fault(report.fault_id)
            injector = scenario.injector(fault.injector_id) if fault else None
            if injector is None or report.period is not None:
                continue
            topic = injector.input_topic if injector.input_topic in topics and not injector.is_service else None
            topic = topic if topic and topic != injector.output_topic else injector.output_topic or ''
            self.watch.setdefault(topic, []).append(report)

    def _report(self, report: InjectedReport, time: int) -> Report:
        active = self.active[report.fault_id]
        return Report(report.code, FAILED if active else PASSED, report.severity,
                      f'injected fault {report.fault_id} {"active" if active else "ended"}', report.source, time)

    def on_event(self, event: FaultEvent) -> list[Report]:
        """Track the state; periodic reporters report at once and re-arm."""
        report = self.reports.get(event.fault_id)
        if report is None or event.state not in ('active', 'inactive'):
            return []
        self.active[event.fault_id] = event.state == 'active'
        if report.period is None:
            return []
        self._next[event.fault_id] = event.time + round(report.period * NS)
        return [self._report(report, event.time)]

    def next_due(self) -> int | None:
        """Time of the next periodic report."""
        return min(self._next.values(), default=None)

    def due(self) -> list[Report]:
        """The earliest periodic report; its fault re-arms one period later."""
        fault_id = min(self._next, key=lambda f: (self._next[f], f))
        time = self._next[fault_id]
        period = self.reports[fault_id].period
        assert period is not None  # only periodic reports are scheduled
        self._next[fault_id] = time + round(period * NS)
        return [self._report(self.reports[fault_id], time)]

    def on_message(self, topic: str, time: int) -> list[Report]:
        """Per-message reports of faults watching this topic (once they were ever active)."""
        return [self._report(r, time) for r in self.watch.get(topic, ()) if r.fault_id in self.active]


def diagnostic_code(name: str, codes: dict[str, str]) -> str:
    """Mapped code, or the status name made into a valid code."""
    if name in codes:
        return codes[name]
    code = _INVALID.sub('_', name).strip('_') or 'DIAGNOSTIC'
    while '..' in code:
        code = code.replace('..', '.')
    return code[:128]


def diagnostics_reports(message: Any, time: int, codes: dict[str, str]) -> list[Report]:
    """DiagnosticArray -> reports: ERROR/STALE FAILED (ERROR), WARN FAILED (WARN), OK PASSED."""
    out = []
    for status in message.status:
        level = status.level if isinstance(status.level, int) else int.from_bytes(bytes(status.level), 'little')
        code = diagnostic_code(status.name, codes)
        source = f'/diagnostics/{status.hardware_id or status.name}'
        if level == 0:
            out.append(Report(code, PASSED, 0, status.message, source, time))
        else:
            out.append(Report(code, FAILED, WARN if level == 1 else ERROR, status.message, source, time))
    return out


def condition_report(condition: Condition, path: FieldPath, message: Any, time: int) -> Report:
    """FAILED when any addressed value meets the condition, else PASSED."""
    values = path.read(message)
    if condition.above is not None:
        hit = values > condition.above
    elif condition.below is not None:
        hit = values < condition.below
    elif condition.outside is not None:
        hit = (values < condition.outside[0]) | (values > condition.outside[1])
    else:
        hit = ~np.isfinite(values)
    failed = bool(np.any(hit))
    description = f'{condition.describe()} on {condition.topic}' if failed else ''
    return Report(condition.code, FAILED if failed else PASSED, condition.severity, description, condition.source,
                  time)
