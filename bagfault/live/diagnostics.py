"""Live status as diagnostic_msgs/msg/DiagnosticArray, so standard ROS monitors show it.

One status per fault (OK while inactive, WARN while active, its config as
key-values) and one per topic injector with its message counters.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

if TYPE_CHECKING:
    from bagfault.live.session import FaultStatus, LiveTopic

PREFIX = 'bagfault'


def _text(value: Any) -> str:
    if isinstance(value, bool):
        return 'true' if value else 'false'
    return str(value)


def diagnostic_array(faults: list[FaultStatus], topics: list[LiveTopic], stamp: Any) -> DiagnosticArray:
    """The status of every fault and topic injector."""
    array = DiagnosticArray()
    array.header.stamp = stamp
    for fault in faults:
        status = DiagnosticStatus()
        status.level = DiagnosticStatus.WARN if fault.active else DiagnosticStatus.OK
        status.name = f'{PREFIX}: fault {fault.fault_id}'
        status.message = 'active' if fault.active else 'inactive'
        status.hardware_id = fault.injector_id
        status.values = [KeyValue(key='injector_id', value=fault.injector_id),
                         KeyValue(key='state', value=status.message)]
        status.values += [KeyValue(key=k, value=_text(v)) for k, v in sorted(fault.config.items())]
        array.status.append(status)
    for topic in topics:
        status = DiagnosticStatus()
        status.level = DiagnosticStatus.WARN if topic.malformed else DiagnosticStatus.OK
        status.name = f'{PREFIX}: injector {topic.spec.id}'
        status.message = f'{topic.input_topic} -> {topic.output_topic}'
        status.hardware_id = topic.spec.id
        status.values = [KeyValue(key='received', value=str(topic.received)),
                         KeyValue(key='forwarded', value=str(topic.forwarded)),
                         KeyValue(key='malformed', value=str(topic.malformed))]
        if topic.last_error:
            status.values.append(KeyValue(key='last_error', value=topic.last_error))
        array.status.append(status)
    return array
