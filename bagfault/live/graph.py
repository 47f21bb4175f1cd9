"""What the proxy learns from the ROS graph before it starts: topic types, and the topics its oracles watch."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any

from bagfault.errors import LiveError
from bagfault.injectors.base import Injector
from bagfault.injectors.registry import get_injector_type

if TYPE_CHECKING:
    from bagfault.engine.stop import StopFlag
    from bagfault.spec.model import InjectorSpec, Scenario

OBSERVE_WAIT = 5.0  # seconds to wait for publishers of watched topics whose type is not known
DIAGNOSTICS_TYPE = 'diagnostic_msgs/msg/DiagnosticArray'
OWN_PREFIXES = ('/fault_injection/', '/fault_manager/', '/bagfault/')  # bagfault's own topics, never the system's


def _message_type(spec: InjectorSpec) -> str | None:
    cls = get_injector_type(spec.type)
    if cls is not None and issubclass(cls, Injector) and len(cls.message_types) == 1:
        return cls.message_types[0]
    return spec.options.get('message_type') or None


def resolve_types(node: Any, scenario: Scenario, executor: Any, stop: StopFlag) -> dict[str, str]:
    """Message type per topic injector: from its injector type, `message_type`, or the graph."""
    types: dict[str, str] = {}
    waiting: dict[str, str] = {}
    for spec in scenario.injectors:
        if spec.is_service:
            continue
        if spec.input_topic == spec.output_topic:
            raise LiveError(f'{scenario.name}: injector {spec.id!r} reads and writes {spec.input_topic}; '
                            'a live proxy needs distinct input_topic and output_topic (/x_raw -> /x)')
        known = _message_type(spec)
        if known:
            types[spec.id] = known
        else:
            assert spec.input_topic is not None
            waiting[spec.id] = spec.input_topic
    if waiting:
        node.get_logger().info('waiting for publishers to learn the type of ' + ', '.join(sorted(waiting.values()))
                         + " (or set the injector's message_type)")
    while waiting and not stop.is_set():
        graph = dict(node.get_topic_names_and_types())
        for injector_id, topic in list(waiting.items()):
            found = graph.get(topic)
            if found:
                if len(found) > 1:
                    raise LiveError(f'topic {topic} carries several types ({", ".join(found)}); '
                                    f'set message_type on injector {injector_id!r}')
                types[injector_id] = found[0]
                del waiting[injector_id]
        executor.spin_once(timeout_sec=0.1)
    return types

def oracle_topics(scenario: Scenario) -> dict[str, str | None]:
    """Topics the oracles read (FM diagnostics and conditions, asserted topics), with their type when the
    scenario says it."""
    wanted: dict[str, str | None] = {}
    config = scenario.fault_manager_config
    if config is not None:
        if config.diagnostics_topic:
            wanted[config.diagnostics_topic] = DIAGNOSTICS_TYPE
        for condition in config.conditions:
            wanted.setdefault(condition.topic, None)
    for assertion in scenario.assertions:
        for key in ('topic', 'input_topic'):
            name = assertion.params.get(key)
            if isinstance(name, str) and name:
                known = assertion.params.get('message_type') if key == 'topic' else None
                wanted[name] = wanted.get(name) or known
    return wanted


def watched_topics(node: Any, scenario: Scenario, stop: StopFlag, *, own: set[str],
                   executor: Any = None, wait: float = OBSERVE_WAIT) -> tuple[dict[str, str], list[str]]:
    """Oracle topics besides `own` with their types (from the scenario, else from the graph within `wait`
    seconds); and the topics left unwatched because no publisher told their type."""
    wanted = {t: m for t, m in oracle_topics(scenario).items() if t not in own and not t.startswith(OWN_PREFIXES)}
    deadline = time.monotonic() + wait
    while any(m is None for m in wanted.values()) and time.monotonic() < deadline and not stop.is_set():
        graph = dict(node.get_topic_names_and_types())
        for name in [t for t, m in wanted.items() if m is None]:
            if graph.get(name):
                wanted[name] = graph[name][0]
        if executor is not None:
            executor.spin_once(timeout_sec=0.1)
        else:
            stop.wait(0.05)
    watched = {name: msgtype for name, msgtype in wanted.items() if msgtype is not None}
    return watched, sorted(name for name, msgtype in wanted.items() if msgtype is None)
