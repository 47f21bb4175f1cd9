"""Link faults between nodes of the system under test (the `link` injector): the subscriber's side remapped.

Before the bag plays, each link's subscriber process is stopped (SIGINT,
as a launch file stops a node) and started again with its command line,
environment and working directory plus `--ros-args -r TOPIC:=/bagfault/link
TOPIC`; bagfault hears TOPIC from its publisher and republishes it on the
remapped name through the `topic` injector's faults, whose activity follows
the fault events on bag time. A message no fault holds back goes out in the
listener's thread as it arrives; a delayed one when the loop's clock
reaches its time. A composable node container cannot be remapped one node
at a time: refused before the run.
"""

from __future__ import annotations

import heapq
import os
import signal
import threading
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from bagfault.closedloop.actions import resolve_target
from bagfault.closedloop.process import command_of, launch_of, processes
from bagfault.errors import ClosedLoopError
from bagfault.faults.active import ActiveFault
from bagfault.faults.rng import FaultRandom
from bagfault.injectors.base import RawMessage
from bagfault.injectors.link import LINK_PREFIX
from bagfault.injectors.topic import TopicInjector
from bagfault.spec.model import InjectorSpec
from bagfault.spec.names import absolute_topic

if TYPE_CHECKING:
    from bagfault.closedloop.process import SystemProcess
    from bagfault.events import FaultEvent
    from bagfault.spec.model import FaultSpec, Scenario

RESOLVE_WAIT = 5.0  # seconds for the subscriber's node to show on the graph
REMAP_WAIT = 30.0  # seconds for a restarted subscriber to subscribe to its remapped topic
CONTAINERS = ('component_container',)  # command lines of composable node containers (rclcpp_components)


@dataclass
class Link:
    """One link: its topic, the remapped name its subscriber reads, the injector and what it holds back."""

    id: str
    topic: str
    subscriber: str | dict[str, str]
    faults: list[FaultSpec]
    injector: TopicInjector
    active: dict[str, ActiveFault] = field(default_factory=dict)
    publisher: Any = None
    count: int = 0

    @property
    def remapped(self) -> str:
        """Where the subscriber reads the topic now."""
        return LINK_PREFIX + self.topic


class Links:
    """The links of a scenario on one running system."""

    def __init__(self, scenario: Scenario, seed: int) -> None:
        self.seed = seed
        self.links: dict[str, Link] = {}
        for spec in scenario.injectors:
            if spec.type != 'link':
                continue
            topic = absolute_topic(str(spec.options['link_topic']))
            faults = [f for f in scenario.faults if f.injector_id == spec.id]
            injector = TopicInjector(InjectorSpec(spec.id, 'topic', topic, LINK_PREFIX + topic), None, faults)
            self.links[topic] = Link(spec.id, topic, spec.options['subscriber'], faults, injector)
        self._by_injector = {link.id: link for link in self.links.values()}
        self._held: list[tuple[int, int, str, bytes]] = []  # (due bag time, order, topic, data)
        self._lock = threading.Lock()
        self._order = 0

    def __bool__(self) -> bool:
        return bool(self.links)

    # -- before the bag ---------------------------------------------------------------------------------
    def remap(self, process: SystemProcess, listener: Any, publisher_node: Any, stop_timeout: float) -> list[str]:
        """Each subscriber started again with its link's topic remapped, and bagfault's publisher on that name
        matched by it; what was done, one line per link. ClosedLoopError if a subscriber cannot be remapped."""
        from bagfault.live.ros import adapted_qos, interface_class  # noqa: PLC0415

        said = []
        for link in self.links.values():
            deadline = time.monotonic() + RESOLVE_WAIT  # the graph may not show every node of a fresh process yet
            pids = resolve_target(link.subscriber, process, listener)
            while len(pids) != 1 and time.monotonic() < deadline:
                time.sleep(0.05)
                pids = resolve_target(link.subscriber, process, listener)
            if len(pids) != 1:
                raise ClosedLoopError(f'link {link.id!r}: subscriber {_describe(link.subscriber)} is '
                                      f'{"no process" if not pids else f"{len(pids)} processes"} of the system '
                                      '(name one)')
            [pid] = pids
            if any(name in command_of(pid) for name in CONTAINERS):
                raise ClosedLoopError(f'link {link.id!r}: the subscriber runs in a composable node container '
                                      f'(pid {pid}: {command_of(pid)}); a remap there would move every node it '
                                      'hosts, so bagfault cannot fault this link')
            types = dict(listener.get_topic_names_and_types()).get(link.topic)
            if not types:
                raise ClosedLoopError(f'link {link.id!r}: nothing publishes {link.topic} on the graph')
            infos = listener.get_publishers_info_by_topic(link.topic)
            link.publisher = publisher_node.create_publisher(interface_class(types[0]), link.remapped,
                                                             adapted_qos(10, infos))
            launch = launch_of(pid)
            if launch is None:
                raise ClosedLoopError(f'link {link.id!r}: the subscriber (pid {pid}) ended before it was remapped')
            _stop(pid, stop_timeout)
            popen = process.start_again(launch, ['--ros-args', '-r', f'{link.topic}:={link.remapped}'])
            deadline = time.monotonic() + REMAP_WAIT
            while link.publisher.get_subscription_count() == 0:
                if popen.poll() is not None:
                    raise ClosedLoopError(f'link {link.id!r}: the remapped subscriber exited with code '
                                          f'{popen.returncode}', tail=process.tail())
                if time.monotonic() > deadline:
                    raise ClosedLoopError(f'link {link.id!r}: the restarted subscriber (pid {popen.pid}) did not '
                                          f'subscribe to {link.remapped} within {REMAP_WAIT:g} s',
                                          tail=process.tail())
                time.sleep(0.02)
            said.append(f'link {link.id!r}: pid {pid} started again as pid {popen.pid} with {link.topic} remapped '
                        f'to {link.remapped}')
        return said

    # -- during the run ------------------------------------------------------------------------------
    def act(self, event: FaultEvent) -> str:
        """A link fault switched: its injector sees it from now on (main thread)."""
        link = self._by_injector.get(event.injector_id)
        if link is None or event.state not in ('active', 'inactive'):
            return ''
        with self._lock:
            if event.state == 'inactive':
                link.active.pop(event.fault_id, None)
                return ''
            spec = next(f for f in link.faults if f.id == event.fault_id)
            link.active[event.fault_id] = ActiveFault(spec, event.time, FaultRandom(self.seed, spec.id))
        return f'on {link.topic} -> {link.remapped}'

    def heard(self, topic: str, bag_time: int | None, data: bytes) -> list[tuple[str, bytes]]:
        """A message of a link's topic arrived (listener thread): what goes out now (remapped topic, bytes);
        delayed ones are held for `due`."""
        link = self.links[topic]
        with self._lock:
            active = [link.active[f.id] for f in link.faults if f.id in link.active]
            if bag_time is None or not active:
                outputs = [RawMessage(bag_time or 0, bag_time or 0, data, link.count)]
            else:
                outputs = link.injector.process(RawMessage(bag_time, bag_time, data, link.count), active)
            link.count += 1
            now = []
            for message in outputs:
                payload = bytes(message.data)
                if bag_time is None or message.log_time <= bag_time:
                    now.append((link.remapped, payload))
                else:
                    self._order += 1
                    heapq.heappush(self._held, (message.log_time, self._order, topic, payload))
        for _, payload in now:
            link.publisher.publish(payload)
        return now

    def due(self, bag_time: int) -> list[tuple[str, bytes]]:
        """Held messages whose time has come, published now (main thread)."""
        out = []
        with self._lock:
            while self._held and self._held[0][0] <= bag_time:
                _, _, topic, payload = heapq.heappop(self._held)
                out.append((self.links[topic], payload))
        for link, payload in out:
            link.publisher.publish(payload)
        return [(link.remapped, payload) for link, payload in out]


def _describe(target: str | dict[str, str]) -> str:
    return target if isinstance(target, str) else ', '.join(f'{k}: {v}' for k, v in target.items())


def _stop(pid: int, timeout: float) -> None:
    """SIGINT (a node's clean stop), SIGKILL after `timeout`; returns once the process has ended."""
    for number, wait in ((signal.SIGINT, timeout), (signal.SIGKILL, 5.0)):
        try:
            os.kill(pid, number)
        except ProcessLookupError:
            return
        deadline = time.monotonic() + wait
        while time.monotonic() < deadline:
            if not any(p.pid == pid and p.state != 'Z' for p in processes()):
                return
            time.sleep(0.02)
