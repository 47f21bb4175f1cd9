"""Router: decides per input channel whether it is copied, injected, or both.

Output semantics (ARCHITECTURE.md): the output is what a recorder would
have captured had the injectors run as proxies. An injector with
input_topic != output_topic leaves its input in the output untouched and
adds the output topic; with input_topic == output_topic the mutated stream
replaces the original. A recorded topic that an injector writes is
replaced by the injector's stream.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from bagfault.engine.build import build_injector
from bagfault.engine.merge import COPY_RANK
from bagfault.engine.pipeline import InjectorRuntime
from bagfault.engine.run import OutputChannel
from bagfault.errors import EngineError
from bagfault.injectors.base import Injector, SystemInjector
from bagfault.injectors.registry import get_injector_type
from bagfault.io.channel import bag_name
from bagfault.spec.names import absolute_topic

if TYPE_CHECKING:
    from collections.abc import Callable

    from bagfault.engine.fault_state import FaultState
    from bagfault.engine.run import Sink
    from bagfault.io.channel import Channel
    from bagfault.io.sources import InputSet
    from bagfault.io.types import TypeCatalog
    from bagfault.spec.model import InjectorSpec, Scenario

ROS_SCHEMA_ENCODINGS = {'', 'ros2msg', 'ros2idl'}


@dataclass
class Routing:
    """The wiring of one run."""

    routes: dict[int, list[InjectorRuntime]] = field(default_factory=dict)
    copies: dict[int, OutputChannel] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    replaced: list[str] = field(default_factory=list)
    schemas: dict[str, tuple[str, str, str]] = field(default_factory=dict)


def _topics_listing(inputs: InputSet) -> str:
    topics = inputs.topics()
    if not topics:
        return 'the bag has no topics'
    listing = ', '.join(f'{t} ({chs[0].msgtype or "?"})' for t, chs in sorted(topics.items())[:12])
    more = len(topics) - 12
    return f'the bag has {listing}' + (f' and {more} more' if more > 0 else '')


def _schema(channel: Channel, catalog: TypeCatalog) -> tuple[str, str]:
    if channel.schema_text:
        return channel.schema_encoding, channel.schema_text
    if channel.schema_encoding and channel.schema_encoding not in ROS_SCHEMA_ENCODINGS:
        return channel.schema_encoding, ''
    return catalog.schema(channel.msgtype)


@dataclass(frozen=True)
class _Wired:
    """A topic injector whose input topic is in the bag, with both topic names as the bag spells them."""

    spec: InjectorSpec
    cls: type[Injector]
    channels: list[Channel]
    input_topic: str
    output_topic: str


def build_routing(inputs: InputSet, scenario: Scenario, catalog: TypeCatalog, sink: Sink,
                  keep: Callable[[int], int | None] | None = None, state: FaultState | None = None,
                  withheld: frozenset[str] = frozenset()) -> Routing:
    """Check the scenario against the bag and register every output channel; `keep(number)` (chunk copy)
    registers an input channel that passes through under its input id, or says None; topics in `withheld`
    (the closed loop's system publishes them) get no output channel: they are neither played nor judged."""
    _check_encodings(inputs)
    routing = Routing()
    wired = _wire(inputs, scenario, routing)
    _check_no_chains(scenario, wired)
    _register(inputs, scenario, catalog, sink, wired, routing, keep, state, withheld)
    return routing


def _check_encodings(inputs: InputSet) -> None:
    for channel in inputs.channels:
        if channel.message_encoding != 'cdr' and channel.schema_encoding in ROS_SCHEMA_ENCODINGS:
            raise EngineError(
                f'topic {channel.topic}: serialization format {channel.message_encoding!r} is not CDR; '
                'bagfault reads ROS 2 CDR data only'
            )


def _wire(inputs: InputSet, scenario: Scenario, routing: Routing) -> list[_Wired]:
    """The topic injectors that can run on this bag; the others are noted (as the anchor runs the rest)."""
    topics = inputs.topics()
    wired = []
    for spec in scenario.injectors:
        cls = get_injector_type(spec.type)
        assert cls is not None
        if issubclass(cls, SystemInjector):
            continue  # the mode that runs a system carries its faults out (the others refuse the scenario)
        if not issubclass(cls, Injector):
            routing.notes.append(f'injector {spec.id!r} ({spec.type}) proxies a service: live mode only, '
                                 'its faults have no effect offline')
            continue
        assert spec.input_topic is not None and spec.output_topic is not None  # validated
        input_topic = bag_name(spec.input_topic, topics)
        found = topics.get(input_topic)
        if not found:
            routing.warnings.append(f'{scenario.name}: injector {spec.id!r}: input topic {spec.input_topic} is not '
                                    f'in the bag, so its faults have no effect; {_topics_listing(inputs)}')
            continue
        _check_types(scenario, spec, cls, found)
        wired.append(_Wired(spec, cls, found, input_topic, bag_name(spec.output_topic, topics)))
    return wired


def _check_types(scenario: Scenario, spec: InjectorSpec, cls: type[Injector], found: list[Channel]) -> None:
    if cls.message_types:
        wrong = [c for c in found if c.msgtype not in cls.message_types]
        if wrong:
            raise EngineError(
                f'{scenario.name}: injector {spec.id!r} ({spec.type}) needs {" or ".join(cls.message_types)} '
                f'but topic {spec.input_topic} in the bag carries {wrong[0].msgtype or "an unknown type"}'
            )
    expected = spec.options.get('message_type')
    if expected and any(c.msgtype != expected for c in found):
        actual = next(c.msgtype for c in found if c.msgtype != expected)
        raise EngineError(
            f'{scenario.name}: injector {spec.id!r} expects message_type {expected} '
            f'but topic {spec.input_topic} in the bag carries {actual or "an unknown type"}'
        )


def _check_no_chains(scenario: Scenario, wired: list[_Wired]) -> None:
    read = {w.input_topic for w in wired}
    for w in wired:
        if w.output_topic in read and w.output_topic != w.input_topic:
            raise EngineError(
                f'{scenario.name}: injector {w.spec.id!r} writes {w.output_topic}, which another injector reads; '
                'chained injectors are not supported offline'
            )


def _register(inputs: InputSet, scenario: Scenario, catalog: TypeCatalog, sink: Sink, wired: list[_Wired],
              routing: Routing, keep: Callable[[int], int | None] | None, state: FaultState | None = None,
              withheld: frozenset[str] = frozenset()) -> None:
    """Output channels in input order: copies of untouched topics, then each injector output of the topic."""
    rank = COPY_RANK
    held = sorted({c.topic for c in inputs.channels if absolute_topic(c.topic) in withheld} |
                  {w.output_topic for w in wired if absolute_topic(w.output_topic) in withheld})
    for topic in held:
        routing.notes.append(f'topic {topic} is not played: the system under test publishes it '
                             "(system_under_test.publishes); what is judged on it is the system's")
    for w in wired:
        if absolute_topic(w.output_topic) in withheld:
            routing.warnings.append(f'{scenario.name}: injector {w.spec.id!r} writes {w.output_topic}, which the '
                                    'system under test publishes (system_under_test.publishes): its faults have '
                                    'no effect')
    wired = [w for w in wired if absolute_topic(w.output_topic) not in withheld]
    in_place = {w.input_topic for w in wired if w.input_topic == w.output_topic}
    written = {w.output_topic for w in wired}
    for number, channel in enumerate(inputs.channels):
        hold = absolute_topic(channel.topic) in withheld  # read by an injector perhaps, but not played as it is
        kept = keep(number) if keep is not None and not hold and \
            (channel.topic not in written or channel.topic in in_place) else None
        if channel.topic in written and channel.topic not in in_place:
            routing.replaced.append(channel.topic)
            routing.notes.append(f'recorded topic {channel.topic} is replaced by the injector that writes it')
        elif channel.topic not in in_place and not hold:
            encoding, text = _schema(channel, catalog)
            channel_id = kept if kept is not None else sink.add_channel(
                channel.topic, channel.msgtype, encoding, text, channel.message_encoding, dict(channel.metadata))
            routing.copies[number] = OutputChannel(channel_id, channel.topic, channel.msgtype)
            routing.schemas[channel.topic] = (channel.msgtype, encoding, text)
        for w in wired:
            if not any(c is channel for c in w.channels):
                continue
            faults = state.faults_of(w.spec.id) if state is not None else scenario.faults_of(w.spec.id)
            injector = build_injector(w.spec, channel.msgtype, faults, catalog, scenario.name)
            encoding, text = _schema(channel, catalog)
            if kept is not None and w.output_topic == channel.topic:
                channel_id, kept = kept, None  # the in-place stream keeps the input's channel
            else:
                channel_id = sink.add_channel(w.output_topic, channel.msgtype, encoding, text,
                                              channel.message_encoding, dict(channel.metadata))
            routing.schemas[w.output_topic] = (channel.msgtype, encoding, text)
            rank += 1
            output = OutputChannel(channel_id, w.output_topic, channel.msgtype)
            routing.routes.setdefault(number, []).append(InjectorRuntime(w.spec, injector, faults, output, rank))
