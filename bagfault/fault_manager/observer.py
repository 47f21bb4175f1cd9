"""The fault manager running inside the engine: reports in, FaultEvents out, on bag time.

It sees every output record and fault event before it is written, turns
them into reports (injected faults, /diagnostics, field conditions), runs
the fault manager, writes /fault_manager/events and cuts snapshots.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from bagfault.errors import FaultManagerError, FieldPathError
from bagfault.fault_manager.manager import FaultManager
from bagfault.fault_manager.model import CLEARED, EVENT_CLEARED, FaultManagerEvent
from bagfault.fault_manager.reporters import InjectedReports, condition_report, diagnostics_reports
from bagfault.fault_manager.snapshots import SnapshotRecorder
from bagfault.faults.fieldpath import FieldPath
from bagfault.units import NS

if TYPE_CHECKING:
    from collections.abc import Callable
    from pathlib import Path

    from bagfault.events import FaultEvent
    from bagfault.fault_manager.config import FaultManagerConfig
    from bagfault.io.types import TypeCatalog
    from bagfault.spec.model import Scenario

DIAGNOSTICS_TYPE = 'diagnostic_msgs/msg/DiagnosticArray'


class FaultManagerObserver:
    """Pipeline observer that hosts the fault manager oracle."""

    def __init__(
        self,
        config: FaultManagerConfig,
        scenario: Scenario,
        channels: dict[str, tuple[str, str, str]],
        catalog: TypeCatalog,
        emit: Callable[[FaultManagerEvent], None],
        blackbox_base: Path | None = None,
        blackbox_numbers: dict[str, int] | None = None,
    ) -> None:
        self.config = config
        self.manager = FaultManager(config)
        self.emit = emit
        self.catalog = catalog
        self.origin = 0
        self.manager.listeners.append(self._on_fault_manager_event)
        self.manager.confirm_listeners.append(self._on_confirmed)
        self.status_changes: list[tuple[int, str, str]] = []  # (time, code, status): the report's state timeline
        self.manager.status_listeners.append(lambda code, status, time: self.status_changes.append((time, code,
                                                                                                      status)))
        self.event_listeners: list[Callable[[FaultManagerEvent], None]] = []
        self.status_listeners = self.manager.status_listeners
        types = {topic: entry[0] for topic, entry in channels.items()}
        self.injected = InjectedReports(config.reports, scenario, set(types))
        self.snapshots = SnapshotRecorder(config.snapshots, channels, catalog, blackbox_base, blackbox_numbers)
        self._codecs: dict[str, Any] = {}
        self.undecodable: dict[str, int] = {}  # topic -> messages the oracle could not decode (skipped)
        self._conditions: dict[str, list[tuple[Any, FieldPath]]] = {}
        self._clears = sorted(config.clears, key=lambda c: c.at)
        if config.diagnostics_topic and config.diagnostics_topic in types:
            if types[config.diagnostics_topic] != DIAGNOSTICS_TYPE:
                raise FaultManagerError(f'fault_manager.diagnostics: {config.diagnostics_topic} carries '
                                  f'{types[config.diagnostics_topic]}, not {DIAGNOSTICS_TYPE}')
            self._codec(config.diagnostics_topic, types)
        for condition in config.conditions:
            if condition.topic not in types:
                continue
            codec = self._codec(condition.topic, types)
            try:
                path = FieldPath.parse(condition.field).resolve(types[condition.topic], codec.store)
            except FieldPathError as exc:
                raise FaultManagerError(f'fault_manager.conditions on {condition.topic}: {exc}') from None
            self._conditions.setdefault(condition.topic, []).append((condition, path))

    def _codec(self, topic: str, types: dict[str, str]) -> Any:
        codec = self.catalog.codec(types[topic])
        if codec is None:
            raise FaultManagerError(f'fault_manager: cannot decode {types[topic]} on {topic}: '
                              f'{self.catalog.why_not(types[topic])}')
        self._codecs[topic] = codec
        return codec

    def wanted_topics(self) -> set[str]:
        """Topics the oracle reads: snapshots, diagnostics, conditions, injected reports' topics."""
        return set(self.snapshots.topics) | set(self._codecs) | set(self.injected.watch)

    # -- time ---------------------------------------------------------------------
    def start(self, origin: int) -> None:
        """Bag time zero."""
        self.origin = origin

    def advance(self, time: int) -> None:
        """Run every timed action due before `time`, earliest first."""
        while True:
            candidates = []
            manager_due = self.manager.next_timer()
            if manager_due is not None and manager_due < time:
                candidates.append((manager_due, 0))
            report_due = self.injected.next_due()
            if report_due is not None and report_due < time:
                candidates.append((report_due, 1))
            if self._clears and self.origin + round(self._clears[0].at * NS) < time:
                candidates.append((self.origin + round(self._clears[0].at * NS), 2))
            if not candidates:
                return
            due, kind = min(candidates)
            if kind == 0:
                self.manager.advance(due + 1)
            elif kind == 1:
                for report in self.injected.due():
                    self.manager.report(report)
            else:
                clear = self._clears.pop(0)
                self.manager.clear(clear.code, due, skip_correlation_auto_clear=clear.skip_correlation_auto_clear)

    # -- records ------------------------------------------------------------------
    def on_event(self, event: FaultEvent) -> None:
        """A scenario fault changed state."""
        self.advance(event.time)
        for report in self.injected.on_event(event):
            self.manager.report(report)

    def on_message(self, topic: str, time: int, data: bytes | memoryview) -> None:
        """An output message: buffered for snapshots (so a freeze frame holds it), then reports."""
        self.advance(time)
        self.snapshots.on_message(topic, time, time, data)
        for report in self.injected.on_message(topic, time):
            self.manager.report(report)
        codec = self._codecs.get(topic)
        if codec is not None:
            try:
                message = codec.decode(data)
            except Exception:  # noqa: BLE001 - a malformed message cannot be judged: counted, not a report
                self.undecodable[topic] = self.undecodable.get(topic, 0) + 1
                return
            if topic == self.config.diagnostics_topic:
                for report in diagnostics_reports(message, time, self.config.diagnostics_codes):
                    self.manager.report(report)
            for condition, path in self._conditions.get(topic, ()):
                self.manager.report(condition_report(condition, path, message, time))

    def finish(self, time: int) -> None:
        """End of the bag: actions due at or before it, then close snapshots."""
        self.advance(time + 1)
        self.snapshots.finish()

    def _on_fault_manager_event(self, event: FaultManagerEvent) -> None:
        self.emit(event)
        if event.event_type == EVENT_CLEARED and event.fault.status == CLEARED:  # ClearFault, not a heal
            self.snapshots.forget((event.fault.fault_code, *event.auto_cleared_codes))
        for listener in self.event_listeners:
            listener(event)

    def _on_confirmed(self, code: str, time: int) -> None:
        self.snapshots.on_confirmed(code, time)

    # -- results ------------------------------------------------------------------
    def summary(self) -> dict[str, Any]:
        """Final fault table, events, clusters, muted faults and snapshots, JSON-ready."""
        everything = self.manager.list_faults(['PREFAILED', 'PREPASSED', 'CONFIRMED', 'HEALED', 'CLEARED'],
                                              include_muted=True, include_clusters=True)
        origin = self.origin

        def seconds(time: int) -> float:
            return round((time - origin) / NS, 9)

        return {
            'faults': [f.to_dict(origin) for f in sorted(everything.faults, key=lambda f: f.fault_code)],
            'confirmed': [f.fault_code for f in self.manager.list_faults().faults],
            'muted': [m.__dict__ for m in everything.muted_faults],
            'muted_count': everything.muted_count,
            'clusters': [{**c.__dict__, 'count': c.count, 'first_at_s': seconds(c.first_at),
                          'last_at_s': seconds(c.last_at)} for c in everything.clusters],
            'cluster_count': everything.cluster_count,
            'events': [{'t_s': seconds(e.time), 'event_type': e.event_type, 'fault_code': e.fault.fault_code,
                        'status': e.fault.status, 'auto_cleared_codes': list(e.auto_cleared_codes)}
                       for e in self.manager.events],
            'rejected_reports': [{'fault_code': r.fault_code, 'reason': why} for r, why in self.manager.rejected],
            'status_changes': [{'t_s': seconds(t), 'fault_code': code, 'status': status}
                               for t, code, status in self.status_changes],
            'snapshots': [{'fault_code': c.code, 't_s': seconds(c.time), 'topics': list(c.topics),
                           'freeze_frame': c.freeze_frame, 'black_box': str(c.path) if c.path else None,
                           'black_box_messages': len(c.messages)} for c in self.snapshots.captures],
        }
