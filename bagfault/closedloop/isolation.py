"""Who else is on the leased domain: a node that is neither bagfault's nor the system's makes a run invalid.

A lease keeps bagfault runs and colcon's isolated tests apart, but any ROS
process started with the same ROS_DOMAIN_ID joins the domain. Fast DDS
writes the low 16 bits of its process id into bytes 4-5 of each
participant's GUID prefix (after eProsima's vendor id 01 0f; `GuidUtils`
in Fast DDS), and rmw_fastrtps reports that GUID as each endpoint's gid, so
every publisher on the graph traces to a process: bagfault's, one of the
system's process tree, or a stranger. A stranger that publishes anything
but /rosout and /parameter_events could feed the system (or be heard as
it): the run is invalid. One that only listens (a `ros2 topic echo`
attached to watch) is named in the report. Endpoints of another DDS
vendor carry no process id and are not judged.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from bagfault.errors import ClosedLoopError

if TYPE_CHECKING:
    from collections.abc import Callable, Iterable

EPROSIMA = b'\x01\x0f'
QUIET_TOPICS = frozenset({'/rosout', '/parameter_events'})  # every rclpy node publishes these
NAME_WAIT = 1.0  # seconds an intruder may stay unnamed before the run is stopped without its name
NAME_POLL = 0.05  # seconds between looks meanwhile
UNKNOWN = '_NODE_NAME_UNKNOWN_'  # rmw's name of a node whose participant has not told its nodes yet
PRESTART = 0.4  # seconds a fresh participant looks for others before the system starts (discovery: ~0.2 s)


def gid_pid16(gid: bytes) -> int | None:
    """The low 16 bits of the pid in a Fast DDS endpoint gid; None for another vendor's."""
    return int.from_bytes(gid[4:6], 'little') if gid[:2] == EPROSIMA else None


def pid16(pid: int) -> int:
    """The part of a process id Fast DDS puts into its GUIDs."""
    return pid & 0xFFFF


@dataclass
class Stranger:
    """A node on the domain from a process that is neither bagfault's nor the system's."""

    node: str
    pid: int  # the low 16 bits Fast DDS keeps
    topics: set[str] = field(default_factory=set)  # what it publishes besides /rosout and /parameter_events

    def describe(self) -> str:
        """'/foreign_talker (pid 24792) publishing /imu'."""
        what = f'publishing {", ".join(sorted(self.topics))}' if self.topics else 'listening only'
        node = 'a node not named yet' if UNKNOWN in self.node else self.node
        return f'{node} (pid {_full_pid(self.pid)}) {what}'


def _full_pid(low: int) -> str:
    """The live process id with these low 16 bits when there is exactly one, else 'N mod 65536'."""
    from bagfault.closedloop.process import processes  # noqa: PLC0415

    matches = [p.pid for p in processes() if pid16(p.pid) == low]
    return str(matches[0]) if len(matches) == 1 else f'{low} mod 65536'


def strangers(node: Any, ours: Callable[[int], bool]) -> list[Stranger]:
    """The nodes the graph of `node` shows in processes for which `ours(pid16)` is false."""
    found: dict[tuple[int, str], Stranger] = {}
    for topic, _types in node.get_topic_names_and_types():
        for info in node.get_publishers_info_by_topic(topic):
            low = gid_pid16(bytes(info.endpoint_gid))
            if low is None or ours(low):
                continue
            namespace = info.node_namespace.rstrip('/')
            name = f'{namespace}/{info.node_name}'
            stranger = found.setdefault((low, name), Stranger(name, low))
            if topic not in QUIET_TOPICS:
                stranger.topics.add(topic)
    return sorted(found.values(), key=lambda s: (s.node, s.pid))


def shared(node: Any, topics: Iterable[str], family: set[int], own_pid: int) -> tuple[str, str, int] | None:
    """(topic, node, pid16) of a publisher of the system (processes in `family`, as pid16) on a topic bagfault
    plays, or None: its messages would be heard, recorded and judged with the bag's."""
    own = pid16(own_pid)
    for topic in sorted(set(topics) - QUIET_TOPICS):  # every node publishes those: the bag's are not its data
        for info in node.get_publishers_info_by_topic(topic):
            low = gid_pid16(bytes(info.endpoint_gid))
            if low is None or low == own or low not in family:
                continue
            return topic, f'{info.node_namespace.rstrip("/")}/{info.node_name}', low
    return None


def shared_error(topic: str, name: str, low: int) -> ClosedLoopError:
    """The one-line error of a system that publishes a topic bagfault plays."""
    who = 'a node not named yet' if UNKNOWN in name else name
    return ClosedLoopError(
        f'the system under test publishes {topic} ({who}, pid {_full_pid(low)}), which bagfault plays from the '
        "bag: the system's messages would be judged as the bag's; the run is invalid, nothing judged (if the "
        f'system owns the topic, declare it: system_under_test: {{publishes: [{topic}]}}, and bagfault does not '
        'play it)')


def invalid(domain: int, intruders: Iterable[Stranger], system_pid: int | None) -> ClosedLoopError:
    """The one-line error of a run whose domain was shared."""
    names = '; '.join(s.describe() for s in intruders)
    system = f'the system under test (pid {system_pid} and its descendants)' if system_pid else 'the system under test'
    return ClosedLoopError(f"ROS domain {domain} is not isolated: {names}, in a process neither bagfault's nor of "
                           f'{system}; the run is invalid, nothing judged')


class CrowdedDomainError(ClosedLoopError):
    """Other processes have nodes on the leased domain, seen in its first moments: the run moves on to another."""

    def __init__(self, domain: int, found: list[Stranger]) -> None:
        super().__init__(f'ROS domain {domain} has nodes of other processes')
        self.domain = domain
        self.found = found


class DomainWatch:
    """Looks at the graph now and then for strangers: those publishing make the run invalid, listeners are noted."""

    def __init__(self, node: Any, domain: int, own_pid: int, system: Callable[[], set[int]],
                 system_pid: int | None = None, period: float = 0.5, quiet_until: float | None = None,
                 on_quiet: Callable[[], None] | None = None) -> None:
        self.node = node
        self.domain = domain
        self.own_pid = own_pid
        self.own = pid16(own_pid)
        self.system = system
        self.system_pid = system_pid
        self.period = period
        self.quiet_until = quiet_until  # the first look lasts until then (None: no first look)
        self.on_quiet = on_quiet  # called when the first look found the domain quiet
        self.listeners: dict[str, str] = {}  # node -> description, of strangers that published nothing
        self._last = 0.0
        self._cleared: set[int] = set()
        self._unnamed_since: float | None = None  # when an intruder was first seen without its node's name

    def first_look(self) -> None:
        """CrowdedDomainError when other processes show nodes before `quiet_until` (PRESTART after this participant
        started: discovery takes ~0.2 s); the system under test starts meanwhile and is not a stranger."""
        if self.quiet_until is None:
            return
        found = first_strangers(self.node, self.own_pid, self.quiet_until, self.system)
        self.quiet_until = None
        if found:
            raise CrowdedDomainError(self.domain, found)
        if self.on_quiet is not None:
            self.on_quiet()

    def _ours(self, low: int) -> bool:
        return low == self.own or low in self._cleared

    def look(self, *, now: bool = False) -> None:
        """Raise ClosedLoopError naming every stranger that publishes (at most once a period unless `now`)."""
        moment = time.monotonic()
        if not now and moment - self._last < self.period:
            return
        self._last = moment
        found = strangers(self.node, self._ours)
        if not found:
            return
        family = {pid16(pid) for pid in self.system()}  # refreshed: a child may have started since
        self._cleared |= family & {s.pid for s in found}
        found = [s for s in found if s.pid not in self._cleared]
        intruders = [s for s in found if s.topics]
        for stranger in found:
            if not stranger.topics:
                self.listeners[stranger.node] = stranger.describe()
        if intruders and not now and any(UNKNOWN in s.node for s in intruders):
            # the endpoints come before the node names: wait a moment to say which node it is
            self._unnamed_since = self._unnamed_since or moment
            if moment - self._unnamed_since < NAME_WAIT:
                self._last = moment - self.period + NAME_POLL
                return
        if intruders:
            raise invalid(self.domain, intruders, self.system_pid)


def first_strangers(node: Any, own_pid: int, until: float, system: Callable[[], set[int]] = set) -> list[Stranger]:
    """Nodes of other processes than bagfault's and the system's (`system()`: its process ids, looked at each
    time: it starts meanwhile) that the graph shows before the monotonic time `until` (empty: the domain is
    theirs alone)."""
    own = pid16(own_pid)
    while True:
        ours = {own, *(pid16(pid) for pid in system())}
        found = strangers(node, ours.__contains__)
        named = all(UNKNOWN not in s.node for s in found)  # the endpoints come before the node names
        if (found and named) or time.monotonic() >= until + (1.0 if found else 0.0):
            return found
        time.sleep(0.05)
