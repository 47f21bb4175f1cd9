"""Records of the fault manager, shaped like ros2_medkit_msgs (Fault, FaultEvent, ...)."""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any, ClassVar

from bagfault.events import SEPARATOR, TIME_DEFINITION
from bagfault.units import NS

FAILED, PASSED = 0, 1
INFO, WARN, ERROR, CRITICAL = 0, 1, 2, 3
SEVERITIES = {'INFO': INFO, 'WARN': WARN, 'ERROR': ERROR, 'CRITICAL': CRITICAL}
SEVERITY_NAMES = {v: k for k, v in SEVERITIES.items()}
CORRELATION_SEVERITY_NAMES = {**SEVERITY_NAMES, WARN: 'WARNING'}  # medkit's correlation severity_to_string
PREFAILED, PREPASSED, CONFIRMED, HEALED, CLEARED = 'PREFAILED', 'PREPASSED', 'CONFIRMED', 'HEALED', 'CLEARED'
STATUSES = (PREFAILED, PREPASSED, CONFIRMED, HEALED, CLEARED)
EVENT_CONFIRMED, EVENT_UPDATED, EVENT_CLEARED = 'fault_confirmed', 'fault_updated', 'fault_cleared'

CODE_PATTERN = re.compile(r'[A-Za-z0-9_.\-]{1,128}')  # whole: fullmatch (a $ would let a final newline in)


def valid_code(code: str) -> bool:
    """1-128 characters of [A-Za-z0-9_.-], no '..'."""
    return bool(CODE_PATTERN.fullmatch(code)) and '..' not in code


def severity_value(value: object) -> int | None:
    """'ERROR' or 2 -> 2; None when not a severity."""
    if isinstance(value, str) and value.upper() in SEVERITIES:
        return SEVERITIES[value.upper()]
    if isinstance(value, int) and not isinstance(value, bool) and 0 <= value <= 3:
        return value
    return None


@dataclass(frozen=True)
class Report:
    """One ReportFault call: FAILED (0) or PASSED (1) of a code, at bag time `time`."""

    fault_code: str
    event_type: int
    severity: int
    description: str
    source_id: str
    time: int


@dataclass
class Fault:
    """The aggregated state of one fault code (fields of ros2_medkit_msgs/msg/Fault, plus the counter)."""

    fault_code: str
    severity: int
    description: str
    first_occurred: int
    last_occurred: int
    occurrence_count: int
    status: str
    reporting_sources: list[str] = field(default_factory=list)
    last_passed: int = 0
    counter: int = 0

    def copy(self) -> Fault:
        """Snapshot for an event."""
        return Fault(self.fault_code, self.severity, self.description, self.first_occurred, self.last_occurred,
                     self.occurrence_count, self.status, list(self.reporting_sources), self.last_passed, self.counter)

    def to_dict(self, origin: int | None = None) -> dict[str, Any]:
        """JSON form (times in ns, and seconds from time zero when origin is given)."""
        out: dict[str, Any] = {
            'fault_code': self.fault_code, 'severity': SEVERITY_NAMES[self.severity], 'description': self.description,
            'first_occurred_ns': self.first_occurred, 'last_occurred_ns': self.last_occurred,
            'last_passed_ns': self.last_passed, 'occurrence_count': self.occurrence_count, 'status': self.status,
            'reporting_sources': list(self.reporting_sources),
        }
        if origin is not None:
            out['first_occurred_s'] = round((self.first_occurred - origin) / NS, 9)
            out['last_occurred_s'] = round((self.last_occurred - origin) / NS, 9)
        return out


@dataclass(frozen=True)
class MutedFaultInfo:
    """A correlated symptom (or hidden cluster member) and why it is muted."""

    fault_code: str
    root_cause_code: str
    rule_id: str
    delay_ms: int


@dataclass
class ClusterInfo:
    """An auto-detected cluster of faults."""

    cluster_id: str
    rule_id: str
    rule_name: str
    label: str
    representative_code: str
    representative_severity: str
    fault_codes: list[str]
    first_at: int
    last_at: int

    @property
    def count(self) -> int:
        """Number of faults in the cluster."""
        return len(self.fault_codes)


@dataclass
class ListFaultsResult:
    """Answer of a ListFaults query."""

    faults: list[Fault]
    muted_count: int
    muted_faults: list[MutedFaultInfo]
    cluster_count: int
    clusters: list[ClusterInfo]


FAULT_TYPE = 'ros2_medkit_msgs/msg/Fault'
FAULT_MSG = (
    'string fault_code\nuint8 severity\nstring description\nbuiltin_interfaces/Time first_occurred\n'
    'builtin_interfaces/Time last_occurred\nuint32 occurrence_count\nstring status\nstring[] reporting_sources\n'
    'uint8 SEVERITY_INFO=0\nuint8 SEVERITY_WARN=1\nuint8 SEVERITY_ERROR=2\nuint8 SEVERITY_CRITICAL=3\n'
)
FAULT_EVENT_TOPIC = '/fault_manager/events'
FAULT_EVENT_TYPE = 'ros2_medkit_msgs/msg/FaultEvent'
FAULT_EVENT_MSG = (
    'string event_type\nros2_medkit_msgs/Fault fault\nbuiltin_interfaces/Time timestamp\nstring[] auto_cleared_codes\n'
    f'{SEPARATOR}\nMSG: ros2_medkit_msgs/Fault\n{FAULT_MSG}'
    f'{SEPARATOR}\nMSG: builtin_interfaces/Time\n{TIME_DEFINITION}'
)


@dataclass(frozen=True)
class FaultManagerEvent:
    """A FaultEvent on /fault_manager/events at bag time `time`."""

    time: int
    event_type: str
    fault: Fault
    auto_cleared_codes: tuple[str, ...] = ()

    topic: ClassVar[str] = FAULT_EVENT_TOPIC
    msgtype: ClassVar[str] = FAULT_EVENT_TYPE
    definition: ClassVar[str] = FAULT_EVENT_MSG

    def to_message(self, store: Any) -> Any:
        """The ros2_medkit_msgs/msg/FaultEvent object."""
        types = store.types
        stamp = types['builtin_interfaces/msg/Time']

        def time_of(ns: int) -> Any:
            return stamp(sec=ns // NS, nanosec=ns % NS)

        fault = self.fault
        message = types[FAULT_TYPE](
            fault_code=fault.fault_code, severity=fault.severity, description=fault.description,
            first_occurred=time_of(fault.first_occurred), last_occurred=time_of(fault.last_occurred),
            occurrence_count=fault.occurrence_count, status=fault.status,
            reporting_sources=list(fault.reporting_sources),
        )
        return types[FAULT_EVENT_TYPE](event_type=self.event_type, fault=message, timestamp=time_of(self.time),
                                        auto_cleared_codes=list(self.auto_cleared_codes))
