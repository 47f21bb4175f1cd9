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

from bagfault.engine.merge import COPY_RANK
from bagfault.engine.pipeline import InjectorRuntime
from bagfault.engine.run import OutputChannel
from bagfault.errors import EngineError
from bagfault.injectors.base import Injector
from bagfault.injectors.registry import get_injector_type

if TYPE_CHECKING:
    from bagfault.engine.run import Sink
    from bagfault.io.channel import Channel
    from bagfault.io.sources import InputSet
    from bagfault.io.types import TypeCatalog
    from bagfault.scenario.model import FaultSpec, InjectorSpec, Scenario

ROS_SCHEMA_ENCODINGS = {'', 'ros2msg', 'ros2idl'}


@dataclass
class Routing:
    """The wiring of one run."""

    routes: dict[int, list[InjectorRuntime]] = field(default_factory=dict)
    copies: dict[int, OutputChannel] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    replaced: list[str] = field(default_factory=list)
    schemas: dict[str, tuple[str, str, str]] = field(default_factory=dict)

    def output_types(self) -> dict[str, str]:
        """Type of every topic the output will hold (before event topics)."""
        return {topic: entry[0] for topic, entry in self.schemas.items()}


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


def build_routing(
    inputs: InputSet,
    scenario: Scenario,
    catalog: TypeCatalog,
    sink: Sink,
) -> Routing:
    """Check the scenario against the bag and register every output channel."""
    routing = Routing()
    scenario_name = scenario.name
    for channel in inputs.channels:
        if channel.message_encoding != 'cdr' and channel.schema_encoding in ROS_SCHEMA_ENCODINGS:
            raise EngineError(
                f'topic {channel.topic}: serialization format {channel.message_encoding!r} is not CDR; '
                'bagfault reads ROS 2 CDR data only'
            )

    topics = inputs.topics()
    injectors = []
    for spec in scenario.injectors:
        cls = get_injector_type(spec.type)
        assert cls is not None
        if not issubclass(cls, Injector):
            routing.notes.append(
                f'injector {spec.id!r} ({spec.type}) proxies a service: live mode only, '
                'its faults have no effect offline'
            )
            continue
        assert spec.input_topic is not None and spec.output_topic is not None
        found = topics.get(spec.input_topic)
        if not found:
            raise EngineError(
                f'{scenario_name}: injector {spec.id!r}: input topic {spec.input_topic} is not in the bag; '
                + _topics_listing(inputs)
            )
        if cls.message_types:
            wrong = [c for c in found if c.msgtype not in cls.message_types]
            if wrong:
                raise EngineError(
                    f'{scenario_name}: injector {spec.id!r} ({spec.type}) needs {" or ".join(cls.message_types)} '
                    f'but topic {spec.input_topic} in the bag carries {wrong[0].msgtype or "an unknown type"}'
                )
        expected = spec.options.get('message_type')
        if expected and any(c.msgtype != expected for c in found):
            actual = next(c.msgtype for c in found if c.msgtype != expected)
            raise EngineError(
                f'{scenario_name}: injector {spec.id!r} expects message_type {expected} '
                f'but topic {spec.input_topic} in the bag carries {actual or "an unknown type"}'
            )
        injectors.append((spec, cls, found))

    in_place = {spec.input_topic for spec, _, _ in injectors if spec.input_topic == spec.output_topic}
    written = {spec.output_topic for spec, _, _ in injectors}
    read = {spec.input_topic for spec, _, _ in injectors}
    for spec, _, _ in injectors:
        if spec.output_topic in read and spec.output_topic != spec.input_topic:
            raise EngineError(
                f'{scenario_name}: injector {spec.id!r} writes {spec.output_topic}, which another injector reads; '
                'chained injectors are not supported offline'
            )

    index = {id(c): i for i, c in enumerate(inputs.channels)}
    rank = COPY_RANK
    for channel in inputs.channels:
        number = index[id(channel)]
        if channel.topic in written and channel.topic not in in_place:
            routing.replaced.append(channel.topic)
            routing.notes.append(f'recorded topic {channel.topic} is replaced by the injector that writes it')
        elif channel.topic not in in_place:
            encoding, text = _schema(channel, catalog)
            channel_id = sink.add_channel(channel.topic, channel.msgtype, encoding, text,
                                          channel.message_encoding, dict(channel.metadata))
            routing.copies[number] = OutputChannel(channel_id, channel.topic, channel.msgtype)
            routing.schemas[channel.topic] = (channel.msgtype, encoding, text)
        for spec, _, found in injectors:
            if channel not in found:
                continue
            output_topic = spec.output_topic
            assert output_topic is not None  # topic injectors have both endpoints (validated)
            faults = scenario.faults_of(spec.id)
            injector = build_injector(spec, channel.msgtype, faults, catalog, scenario_name)
            encoding, text = _schema(channel, catalog)
            channel_id = sink.add_channel(output_topic, channel.msgtype, encoding, text,
                                          channel.message_encoding, dict(channel.metadata))
            routing.schemas[output_topic] = (channel.msgtype, encoding, text)
            rank += 1
            runtime = InjectorRuntime(
                spec=spec,
                injector=injector,
                faults=faults,
                channel=OutputChannel(channel_id, output_topic, channel.msgtype),
                rank=rank,
            )
            routing.routes.setdefault(number, []).append(runtime)
    return routing


def build_injector(spec: InjectorSpec, msgtype: str, faults: list[FaultSpec], catalog: TypeCatalog,
                   scenario_name: str) -> Injector:
    """An injector for messages of `msgtype`, with a codec when its faults need one; EngineError if it cannot work."""
    cls = get_injector_type(spec.type)
    assert cls is not None and issubclass(cls, Injector)
    codec = catalog.codec(msgtype) if msgtype else None
    if codec is None and cls.decodes(faults):
        raise EngineError(f'{scenario_name}: injector {spec.id!r}: cannot decode {msgtype} on {spec.input_topic}: '
                          + catalog.why_not(msgtype))
    if codec is not None:
        problems = cls.check_type(msgtype, codec.store, faults)
        if problems:
            raise EngineError(f'{scenario_name}: injector {spec.id!r} on {spec.input_topic}: ' + '; '.join(problems))
    return cls(spec, codec, faults)
