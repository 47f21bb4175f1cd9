"""Event records and their ros2msg definitions (those of ros2_fault_injection).

The output MCAP carries these on fixed topics with the anchor's type names
and fields, so tools made for ros2_fault_injection read them unchanged.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal, Protocol

from bagfault.units import NS

FaultEventState = Literal['active', 'inactive', 'config_updated']
"""What a FaultEvent reports: the fault switched on or off, or its config changed."""
FaultSource = Literal['startup', 'scheduled', 'manual', 'cli', 'reload']
"""Why: active_on_startup, a schedule, a live parameter or service, `--activate`, a scenario reload."""
AssertionState = Literal['pending', 'passed', 'failed']
ScenarioState = Literal['running', 'passed', 'failed']

TIME_DEFINITION = 'int32 sec\nuint32 nanosec\n'
SEPARATOR = '=' * 80


def with_time(definition: str) -> str:
    """A definition followed by builtin_interfaces/Time, so readers need nothing else."""
    return f'{definition}{SEPARATOR}\nMSG: builtin_interfaces/Time\n{TIME_DEFINITION}'


FAULT_EVENT_TOPIC = '/fault_injection/events'
FAULT_EVENT_TYPE = 'ros2_fault_injection/msg/FaultEvent'
FAULT_EVENT_MSG = with_time(
    'builtin_interfaces/Time stamp\nstring fault_id\nstring injector_id\nstring state\nstring source\nstring details\n'
)

ASSERTION_EVENT_TOPIC = '/fault_injection/assertion_events'
ASSERTION_EVENT_TYPE = 'ros2_fault_injection/msg/AssertionEvent'
ASSERTION_EVENT_MSG = with_time(
    'builtin_interfaces/Time stamp\nstring assertion_id\nstring assertion_type\nstring state\nstring message\n'
)

SCENARIO_STATUS_TOPIC = '/fault_injection/scenario_status'
SCENARIO_STATUS_TYPE = 'ros2_fault_injection/msg/ScenarioStatus'
SCENARIO_STATUS_MSG = with_time(
    'builtin_interfaces/Time stamp\nstring state\nuint32 pending_count\nuint32 passed_count\n'
    'uint32 failed_count\nstring[] failed_assertion_ids\nstring[] failed_messages\n'
)



class EventKind(Protocol):
    """An event record type (the class): its topic, ROS type name and ros2msg definition."""

    @property
    def topic(self) -> str:
        """Topic the events go on."""
        ...

    @property
    def msgtype(self) -> str:
        """ROS type name."""
        ...

    @property
    def definition(self) -> str:
        """ros2msg definition."""
        ...


@dataclass(frozen=True)
class FaultEvent:
    """A fault changed state (`active`/`inactive`) or config, at bag time `time` (ns)."""

    time: int
    fault_id: str
    injector_id: str
    state: FaultEventState
    source: FaultSource
    details: str

    topic: ClassVar[str] = FAULT_EVENT_TOPIC
    msgtype: ClassVar[str] = FAULT_EVENT_TYPE
    definition: ClassVar[str] = FAULT_EVENT_MSG

    @classmethod
    def from_message(cls, time: int, message: Any) -> FaultEvent:
        """The event a recorded ros2_fault_injection/msg/FaultEvent stands for, at its log time."""
        return cls(time, message.fault_id, message.injector_id, message.state, message.source, message.details)

    def to_message(self, store: Any) -> Any:
        """The ros2_fault_injection/msg/FaultEvent object."""
        return to_message(self, store)


@dataclass(frozen=True)
class AssertionEvent:
    """An assertion passed or failed at bag time `time` (ns)."""

    time: int
    assertion_id: str
    assertion_type: str
    state: AssertionState
    message: str

    topic: ClassVar[str] = ASSERTION_EVENT_TOPIC
    msgtype: ClassVar[str] = ASSERTION_EVENT_TYPE
    definition: ClassVar[str] = ASSERTION_EVENT_MSG

    def to_message(self, store: Any) -> Any:
        """The ros2_fault_injection/msg/AssertionEvent object."""
        return to_message(self, store)


@dataclass(frozen=True)
class ScenarioStatus:
    """Summary of all assertions at bag time `time` (ns)."""

    time: int
    state: ScenarioState
    pending_count: int
    passed_count: int
    failed_count: int
    failed_assertion_ids: list[str] = field(default_factory=list)
    failed_messages: list[str] = field(default_factory=list)

    topic: ClassVar[str] = SCENARIO_STATUS_TOPIC
    msgtype: ClassVar[str] = SCENARIO_STATUS_TYPE
    definition: ClassVar[str] = SCENARIO_STATUS_MSG

    def to_message(self, store: Any) -> Any:
        """The ros2_fault_injection/msg/ScenarioStatus object."""
        return to_message(self, store)


class Event(EventKind, Protocol):
    """Any event record: a time, its kind's topic/type/definition, and its message object."""

    @property
    def time(self) -> int:
        """Bag time (ns)."""
        ...

    def to_message(self, store: Any) -> Any:
        """The typestore message object."""
        ...


def to_message(event: FaultEvent | AssertionEvent | ScenarioStatus, store: Any) -> Any:
    """Build the typestore message object of a flat event (stamp + fields)."""
    types = store.types
    stamp = types['builtin_interfaces/msg/Time'](sec=event.time // NS, nanosec=event.time % NS)
    values = {k: v for k, v in event.__dict__.items() if k != 'time'}
    return types[event.msgtype](stamp=stamp, **values)


EVENTS_JSON_TOPIC = '/bagfault/events'


def event_json(event: Event, origin: int | None) -> str:
    """One event as the JSON text published on /bagfault/events (docs/reference/events.md): `topic` (the anchor topic it
    belongs to), `stamp_ns`, `t_s` (from time zero) and the event's own fields."""
    import dataclasses  # noqa: PLC0415
    import json  # noqa: PLC0415

    fields: dict[str, Any] = dataclasses.asdict(event) if dataclasses.is_dataclass(event) else {}
    stamp = fields.pop('time', None)
    body = {'topic': event.topic, 'type': event.msgtype, 'stamp_ns': stamp,
            't_s': None if stamp is None or origin is None else round((stamp - origin) / NS, 9), **fields}
    return json.dumps(body, sort_keys=True, default=str)
