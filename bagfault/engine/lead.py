"""Where a run's copied leading chunks will land, guessed before the run is set up, and their copy started.

The guess reads only the scenario's YAML and the input's MCAP summary, so
`bagfault run` makes it before its heavy imports (this module imports none:
no numpy, no rosbags, no scenario loader). It mirrors what chunk copy and
routing will decide (`engine/chunk_copy.py`, `engine/routing.py`) on the
cheap and on the safe side: a chunk is guessed copied when it ends before
any fault of its topics' injectors can start, and no assertion, fault manager
or injector that rewrites its topics names them; a long run of them lands
where the writer puts it, after its alignment padding. A wrong guess costs the
copy's time only: the writer takes nothing from a leading copy that is not
byte for byte what it would have written (`io/leading_copy.py`).
"""

from __future__ import annotations

import itertools
import math
import struct
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

from mcap.records import Channel, Header, Schema

from bagfault.errors import BagfaultError
from bagfault.io.channel import bag_name
from bagfault.io.leading_copy import LeadingCopy, Piece
from bagfault.io.mcap_layout import FOOTER_LENGTH, MAGIC, header_library, padding_length, record_bytes
from bagfault.io.mcap_summary import SummaryError, read_summary
from bagfault.units import NS

if TYPE_CHECKING:
    from pathlib import Path

    from mcap.summary import Summary

    from bagfault.engine.activation import Activation
    from bagfault.engine.run import Observer
    from bagfault.io.outputs import PartialFile

MARGIN = 2_000_000  # ns a guessed chunk ends before a fault can start (seconds become ns by rounding)
SCHEDULED = ('active_on_startup', 'active', 'probability_per_second', 'repeat')  # keys of faults on from zero


def start_lead(document: object, source: Path, output: PartialFile, *, start_offset: float = 0.0,
               activations: Sequence[Activation] = (), observed: Sequence[str] = ()) -> LeadingCopy | None:
    """Start copying the input's leading chunks into the output's partial file, or None when no chunk is
    guessed copied (or the guess cannot be made: not an indexed MCAP file, a scenario that is no mapping).
    `document` is the scenario's YAML as the loader parsed it (`ScenarioText.located.data`: parsed once);
    `activations` are the `--activate` requests; `observed` topics that observers need."""
    try:
        with source.open('rb') as stream:
            magic = stream.read(len(MAGIC))
            size = stream.seek(0, 2)
            if magic != MAGIC or size < 2 * len(MAGIC) + FOOTER_LENGTH:
                return None
            _, summary = read_summary(stream, size)
            if summary is None:
                return None
        pieces = leading_pieces(summary, document, start_offset, activations, observed)
        if not pieces:
            return None
        return LeadingCopy(source, pieces, output)
    except (OSError, ValueError, struct.error, SummaryError, BagfaultError, RecursionError):
        return None


def wanted_topics(observers: Sequence[Observer]) -> set[str] | None:
    """The topics the observers need to see; None when one of them needs every topic."""
    wanted: set[str] = set()
    for observer in observers:
        topics = getattr(observer, 'wanted_topics', None)
        found = topics() if topics is not None else None
        if found is None:
            return None
        wanted |= found
    return wanted


def leading_pieces(summary: Summary, document: object, start_offset: float,
                   activations: Sequence[Activation], observed: Sequence[str]) -> list[Piece]:
    """The input bytes of the chunks guessed copied from the start, and where they go in the output."""
    if not isinstance(document, Mapping) or not summary.chunk_indexes:
        return []
    chunks = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
    if any(a.message_end_time > b.message_start_time for a, b in itertools.pairwise(chunks)):
        return []  # chunk copy needs chunks that follow each other in time
    indexed = [c for c in chunks if c.message_index_offsets]
    if not indexed:
        return []
    topics = {c.topic for c in summary.channels.values()}
    injectors = _injectors(document, topics)
    horizons = _horizons(document, injectors, activations)
    named = _named(document) | {_plain(t) for t in observed}
    kept, offset = _kept(summary, injectors)
    origin = indexed[0].message_start_time + round(start_offset * NS)
    passing: dict[int, float] = {}  # channel id -> the bag time before which its chunks are guessed copied
    for channel_id in kept:
        topic = summary.channels[channel_id].topic
        readers = [i for i in injectors if i.input_topic == topic]
        if _plain(topic) in named or len(readers) > 1 or any(not i.in_place or i.freezes for i in readers):
            continue
        horizon = horizons.get(readers[0].id, math.inf) if readers else math.inf
        passing[channel_id] = origin + horizon * NS - MARGIN
    spans: list[tuple[int, int]] = []  # input bytes the writer copies as one span: (start, length)
    for chunk in chunks:
        if any(passing.get(cid, -math.inf) <= chunk.message_end_time for cid in chunk.message_index_offsets):
            break
        length = chunk.chunk_length + chunk.message_index_length
        if chunk.message_index_offsets and \
                min(chunk.message_index_offsets.values()) != chunk.chunk_start_offset + chunk.chunk_length:
            break  # the writer copies a chunk and the message indexes right after it as one span
        if spans and sum(spans[-1]) == chunk.chunk_start_offset:
            spans[-1] = (spans[-1][0], spans[-1][1] + length)
        else:
            spans.append((chunk.chunk_start_offset, length))
    pieces: list[Piece] = []
    for source, length in spans:  # one after the other, each after the padding the writer puts before it
        offset += padding_length(offset, source, length)
        pieces.append(Piece(source, offset, length))
        offset += length
    return pieces


class _Injector:
    """An injector the scenario wires to a topic of the bag."""

    def __init__(self, name: str, endpoints: Mapping[object, object], topics: set[str]) -> None:
        self.id = name
        self.input_topic = bag_name(str(endpoints.get('input_topic')), topics)
        self.output_topic = bag_name(str(endpoints.get('output_topic')), topics)
        self.in_place = self.input_topic == self.output_topic
        self.freezes = False  # a fault of it freezes the stream: the injector sees every message


def _injectors(document: Mapping[object, object], topics: set[str]) -> list[_Injector]:
    """The topic injectors of every anchor layout (a list under `injectors:`, endpoints flat or under `topic:`,
    or one `injector:`) whose input topic the bag has."""
    found = []
    for spec in [*_list(document.get('injectors')), document.get('injector')]:
        if not isinstance(spec, Mapping):
            continue
        nested = spec.get('topic')
        endpoints = nested if isinstance(nested, Mapping) else spec
        if isinstance(endpoints.get('input_topic'), str) and isinstance(endpoints.get('output_topic'), str):
            injector = _Injector(str(spec.get('id')), endpoints, topics)
            if injector.input_topic in topics:
                found.append(injector)
    by_id = {i.id: i for i in found}
    for fault in _list(document.get('faults')):
        if not isinstance(fault, Mapping):
            continue
        config, target = fault.get('config'), by_id.get(str(fault.get('injector_id')))
        if isinstance(config, Mapping) and config.get('freeze') and target is not None:
            target.freezes = True
    return found


def _horizons(document: Mapping[object, object], injectors: list[_Injector],
              activations: Sequence[Activation]) -> dict[str, float]:
    """Injector id -> the earliest second from time zero at which one of its faults, or a fault one of them
    follows, can start (0 when unsure)."""
    faults = {str(f.get('id')): f for f in _list(document.get('faults')) if isinstance(f, Mapping)}
    asked: dict[str, float] = {}
    for activation in activations:
        asked[activation.fault_id] = min(asked.get(activation.fault_id, math.inf), activation.start)

    def earliest(fault_id: str, seen: frozenset[str]) -> float:
        fault = faults.get(fault_id)
        if fault is None or fault_id in seen:
            return 0.0
        own = asked.get(fault_id, math.inf)
        after = fault.get('after')
        if isinstance(after, Mapping):
            return min(own, earliest(str(after.get('fault')), seen | {fault_id}))
        if any(fault.get(key) not in (None, False) for key in SCHEDULED):
            return 0.0
        if 'start' not in fault:
            return own  # started by a trigger only: never offline unless asked
        start = _seconds(fault.get('start'))
        return min(own, start)

    horizons: dict[str, float] = {}
    for fault_id, fault in faults.items():
        injector = str(fault.get('injector_id'))
        horizons[injector] = min(horizons.get(injector, math.inf), earliest(fault_id, frozenset()))
    return {i.id: horizons.get(i.id, math.inf) for i in injectors}


def _kept(summary: Summary, injectors: list[_Injector]) -> tuple[list[int], int]:
    """The input channels routing registers under their input ids (in its order), and the output offset
    right after them: the magic, the header, their schemas and their records."""
    replaced = {i.output_topic for i in injectors if not i.in_place}
    kept, schemas = [], set()
    offset = len(MAGIC) + len(record_bytes(Header(profile='ros2', library=header_library())))
    for channel_id in sorted(summary.channels):
        channel = summary.channels[channel_id]
        schema = summary.schemas.get(channel.schema_id)
        if channel.topic in replaced or schema is None or not schema.data:
            continue
        if schema.id not in schemas:
            schemas.add(schema.id)
            offset += len(record_bytes(Schema(id=schema.id, name=schema.name, encoding=schema.encoding,
                                              data=schema.data)))
        offset += len(record_bytes(Channel(id=channel.id, topic=channel.topic,
                                           message_encoding=channel.message_encoding, schema_id=channel.schema_id,
                                           metadata=dict(channel.metadata))))
        kept.append(channel_id)
    return kept, offset


def _seconds(value: object) -> float:
    """A fault's start as the anchor reads it (the scalar as written); 0 when it is not a number."""
    try:
        seconds = float(str(value))
    except ValueError:
        return 0.0
    return seconds if math.isfinite(seconds) and seconds > 0 else 0.0


INJECTOR_OWN = frozenset(('id', 'type', 'input_topic', 'output_topic', 'topic'))  # names of its own, not topics
OWN = {'injectors': INJECTOR_OWN, 'injector': INJECTOR_OWN, 'faults': frozenset(('id', 'injector_id'))}


def _named(document: Mapping[object, object]) -> set[str]:
    """Every string of a scenario but the names injectors and faults give themselves and their own topics (a
    `type: imu` is not the topic `imu`), as topics are spelled in the root namespace."""
    return {_plain(s) for key, value in document.items() for s in _strings(value, OWN.get(str(key), frozenset()))}


def _strings(node: object, skip: frozenset[str]) -> list[str]:
    """The strings in a YAML node, but those under keys in `skip` (of the node, or of the mappings of a list)."""
    if isinstance(node, str):
        return [node]
    if isinstance(node, Mapping):
        return [s for key, value in node.items() if key not in skip for s in _strings(value, frozenset())]
    if isinstance(node, list):
        return [s for item in node for s in _strings(item, skip)]
    return []


def _list(node: object) -> list[object]:
    return node if isinstance(node, list) else []


def _plain(topic: str) -> str:
    return topic.lstrip('/')
