"""CARET architecture files, read the way caret_analyze reads them.

Top level `named_paths`, `executors` and `nodes` are required (an empty
list is fine); a missing or null required key is an error naming the key.
`UNDEFINED` or a missing publish/subscribe topic means none. A problem
inside one node skips that node with a warning, and a path through a
skipped (or missing) node is reported as unusable rather than dropped.
As caret_analyze: an unknown `context_type` drops that context only (a
warning), an `UNDEFINED` one is no context; a node's input/output pair
without a context gets a `callback_chain` when its callbacks and
`variable_passings` lead from the subscription to the publisher; callbacks
other than timer and subscription callbacks are ignored; a duplicate path
name keeps the first; a path over a topic its node does not publish or
subscribe is dropped with a warning; a one-node path runs from the node's
subscription to its publication. caret_analyze reads `callback_type`;
`type:` (as in CARET's documentation sample) is accepted as an alias with a
warning naming the node.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import yaml

from bagfault.errors import LatencyError, one_line
from bagfault.io.regular import read_text
from bagfault.spec import sections
from bagfault.spec.reader import Reader

if TYPE_CHECKING:
    from bagfault.spec.reader import Read
    from bagfault.spec.sections import Section

UNDEFINED = 'UNDEFINED'
CONTEXT_TYPES = ('use_latest_message', 'inherit_unique_stamp', 'callback_chain', 'tilde')
CALLBACK_TYPES = ('timer_callback', 'subscription_callback')


@dataclass(frozen=True)
class MessageContext:
    """How a node's output on publisher_topic relates to its input on subscription_topic."""

    context_type: str
    subscription_topic: str | None
    publisher_topic: str | None


@dataclass
class Node:
    """A node with its callbacks and message contexts."""

    name: str
    callbacks: list[dict[str, Any]] = field(default_factory=list)
    publishes: list[str] = field(default_factory=list)
    subscribes: list[str] = field(default_factory=list)
    contexts: list[MessageContext] = field(default_factory=list)
    publishers: dict[str, list[str]] = field(default_factory=dict)  # topic -> callbacks that publish it
    passings: list[tuple[str, str]] = field(default_factory=list)   # (callback_name_write, callback_name_read)

    def context(self, subscription: str | None, publisher: str | None) -> MessageContext | None:
        """The message context for one input/output topic pair: a declared one, else a callback chain when
        the callbacks lead from the subscription to the publisher, else None (caret has no records then)."""
        declared = next((c for c in self.contexts
                         if c.subscription_topic == subscription and c.publisher_topic == publisher), None)
        if declared is not None or subscription is None or publisher is None:
            return declared
        if self._chained(subscription, publisher):
            return MessageContext('callback_chain', subscription, publisher)
        return None

    def _chained(self, subscription: str, publisher: str) -> bool:
        """True when a callback of the subscription, or one it passes variables to (transitively), publishes."""
        reached = [str(c['callback_name']) for c in self.callbacks
                   if c['callback_type'] == 'subscription_callback' and c.get('topic_name') == subscription]
        seen = set(reached)
        while reached:
            callback = reached.pop()
            if callback in self.publishers.get(publisher, ()):
                return True
            for write, read in self.passings:
                if write == callback and read not in seen:
                    seen.add(read)
                    reached.append(read)
        return False


@dataclass(frozen=True)
class PathNode:
    """One element of a node chain."""

    node_name: str
    subscribe_topic: str | None
    publish_topic: str | None


@dataclass
class NamedPath:
    """A named path: its chain, the topics it runs over, and whether it can be measured."""

    name: str
    chain: list[PathNode]
    problems: list[str] = field(default_factory=list)

    @property
    def topics(self) -> list[str]:
        """The path's topics in order: publish topic of each node but the last (a one-node path: its
        subscribe and publish topics)."""
        if len(self.chain) == 1:
            return [t for t in (self.chain[0].subscribe_topic, self.chain[0].publish_topic) if t]
        return [n.publish_topic for n in self.chain[:-1] if n.publish_topic]

    @property
    def usable(self) -> bool:
        """True when every node and hop is known."""
        return not self.problems


@dataclass
class Architecture:
    """A loaded architecture file."""

    source: Path
    paths: dict[str, NamedPath]
    nodes: dict[str, Node]
    executors: list[dict[str, Any]]
    warnings: list[str] = field(default_factory=list)
    dropped: dict[str, str] = field(default_factory=dict)  # path name -> why caret_analyze would not load it

    def hops(self, path: NamedPath) -> list[tuple[str, str, str, MessageContext | None]]:
        """(node, input topic, output topic, context) for each node between two path topics."""
        out = []
        for element in path.chain if len(path.chain) == 1 else path.chain[1:-1]:
            node = self.nodes.get(element.node_name)
            context = node.context(element.subscribe_topic, element.publish_topic) if node else None
            out.append((element.node_name, element.subscribe_topic or '', element.publish_topic or '', context))
        return out


def _read(section: Section, node: object, where: str, required: tuple[str, ...] = ()) -> Read:
    """A mapping of the file read by its declaration (spec/sections.py); LatencyError with caret_analyze's words
    at the first missing or null required key."""
    def fail(_path: object, message: str) -> None:
        raise LatencyError(f'{where}: {message}')

    read = Reader(fail).read(section, node, (), required=required)
    assert read is not None  # (fail raised)
    return read


def _topic(value: object) -> str | None:
    return None if value is None or value == UNDEFINED else str(value)


def _node(raw: object, warnings: list[str]) -> Node:
    """Parse one node; raise LatencyError for anything that makes caret_analyze reject it."""
    read = _read(sections.NODE, raw, 'node')
    name = str(read.get('node_name'))
    where = f'node {name}'
    node = Node(name)
    for number, callback in enumerate(read.get('callbacks')):
        _callback(node, callback, where, number, warnings)
    for number, group in enumerate(read.get('callback_groups')):
        _read(sections.CALLBACK_GROUP, group, f'{where}: callback_groups[{number}]')
    _links(node, read, where)
    for number, context in enumerate(read.get('message_contexts')):
        found = _context(node, context, f'{where}: message_contexts[{number}]', warnings)
        if found is not None:
            node.contexts.append(found)
    return node


def _links(node: Node, read: Read, where: str) -> None:
    """The node's variable passings, publishers and subscriptions."""
    for number, passing in enumerate(read.get('variable_passings')):
        link = _read(sections.VARIABLE_PASSING, passing, f'{where}: variable_passings[{number}]')
        write, reader = str(link.get('callback_name_write')), str(link.get('callback_name_read'))
        if UNDEFINED not in (write, reader):
            node.passings.append((write, reader))
    for number, publish in enumerate(read.get('publishes')):
        publisher = _read(sections.PUBLISH, publish, f'{where}: publishes[{number}]')
        topic = str(publisher.get('topic_name'))
        node.publishes.append(topic)
        node.publishers.setdefault(topic, []).extend(str(n) for n in publisher.get('callback_names') or [])
    for number, subscribe in enumerate(read.get('subscribes')):
        node.subscribes.append(str(_read(sections.SUBSCRIBE, subscribe,
                                         f'{where}: subscribes[{number}]').get('topic_name')))


def _callback(node: Node, callback: Any, where: str, number: int, warnings: list[str]) -> None:
    """The node's callback `number`, kept when it is a timer or subscription callback (all caret_analyze reads);
    'type:' is taken for 'callback_type:' with a warning."""
    if isinstance(callback, dict) and 'callback_type' not in callback and 'type' in callback:
        warnings.append(f"{where}: callback {callback.get('callback_name', number)!r} says 'type:'; "
                        "caret_analyze reads 'callback_type:' (accepted here as an alias)")
        callback = {**callback, 'callback_type': callback['type']}
    written = callback.get('callback_type') if isinstance(callback, dict) else None
    needed: tuple[str, ...] = ('callback_name', 'symbol',
                               'period_ns' if written == 'timer_callback' else 'topic_name')
    kind = _read(sections.CALLBACK, callback, f'{where}: callbacks[{number}]',
                 needed if written in CALLBACK_TYPES else ()).get('callback_type')
    if kind in CALLBACK_TYPES:  # (service callbacks are ignored)
        node.callbacks.append({**callback, 'construction_order': callback.get('construction_order', 0)})


def _context(node: Node, context: Any, where: str, warnings: list[str]) -> MessageContext | None:
    """One declared message context, or None when caret_analyze would not make it (no context, an unknown type,
    a topic the node does not have: the last two with a warning)."""
    written = context.get('context_type') if isinstance(context, dict) else None
    needed = ('subscription_topic_name', 'publisher_topic_name') if written in CONTEXT_TYPES else ()
    block = _read(sections.MESSAGE_CONTEXT, context, where, needed)
    kind = block.get('context_type')
    if kind == UNDEFINED:
        return None  # no context: a callback chain may take its place
    if kind not in CONTEXT_TYPES:
        warnings.append(f'{where}: unknown context_type {kind!r} (known: {", ".join(CONTEXT_TYPES)}); '
                        'context dropped')
        return None
    subscribed, published = _topic(block.get('subscription_topic_name')), _topic(block.get('publisher_topic_name'))
    missing = [f'{role} {topic}' for role, topic, known in (('subscribe to', subscribed, node.subscribes),
                                                              ('publish', published, node.publishes))
               if topic is not None and topic not in known]
    if missing:  # caret finds no subscription or publisher struct for it, and the context is not made
        warnings.append(f'{where}: the node does not {" or ".join(missing)}; context dropped')
        return None
    return MessageContext(kind, subscribed, published)


def load_architecture(path: str | Path) -> Architecture:
    """Read and check an architecture file; LatencyError names the file and the problem."""
    file = Path(path)
    try:
        top = _read(sections.ARCHITECTURE, _load_yaml(file), 'architecture')
    except LatencyError as exc:
        raise LatencyError(f'{file}: {one_line(exc)}') from None
    named_paths, executors, raw_nodes = top.get('named_paths'), top.get('executors'), top.get('nodes')
    warnings: list[str] = []
    nodes, skipped = _nodes(raw_nodes, warnings)
    paths: dict[str, NamedPath] = {}
    dropped: dict[str, str] = {}
    for number, raw in enumerate(named_paths):
        try:
            name, chain = _named_path(raw, number)
        except LatencyError as exc:
            raise LatencyError(f'{file}: {one_line(exc)}') from None
        if name in paths:
            warnings.append(f'path {name} is defined more than once; the first is used')
            continue
        foreign = _foreign_topic(chain, nodes)
        if foreign:
            warnings.append(f'path {name}: {foreign}; path dropped')
            dropped[name] = foreign
            continue
        paths[name] = NamedPath(name, chain, _problems(chain, nodes, skipped))
    return Architecture(file, paths, nodes, list(executors), warnings, dropped)


def _load_yaml(file: Path) -> dict[str, Any]:
    """The file's YAML mapping; LatencyError naming the file when it cannot be read or is no mapping."""
    try:
        data = yaml.safe_load(read_text(file))
    except FileNotFoundError:
        raise LatencyError(f'{file}: architecture file not found') from None
    except (OSError, UnicodeDecodeError) as exc:
        raise LatencyError(f'{file}: cannot read: {one_line(exc)}') from None
    except yaml.YAMLError as exc:
        raise LatencyError(f'{file}: invalid YAML: {one_line(exc)}') from None
    if not isinstance(data, dict):
        raise LatencyError(f'{file}: Failed to parse yaml: not a mapping')
    return data


def _nodes(raw_nodes: list[Any], warnings: list[str]) -> tuple[dict[str, Node], dict[str, str]]:
    """The nodes by name, and those skipped (one caret_analyze rejects, or a name defined twice) with why."""
    nodes: dict[str, Node] = {}
    skipped: dict[str, str] = {}
    names = [n.get('node_name') for n in raw_nodes if isinstance(n, dict)]
    for raw in raw_nodes:
        try:
            node = _node(raw, warnings)
        except LatencyError as exc:
            name = raw.get('node_name') if isinstance(raw, dict) else None
            skipped[str(name)] = str(exc)
            warnings.append(f'{one_line(exc)}; node skipped')
            continue
        if names.count(node.name) > 1:
            skipped[node.name] = f'node {node.name} is defined {names.count(node.name)} times'
            warnings.append(f'{skipped[node.name]}; node skipped')
            continue
        nodes[node.name] = node
    return nodes, skipped


def _named_path(raw: object, number: int) -> tuple[str, list[PathNode]]:
    """A named path's name and node chain; LatencyError at a missing key."""
    named = _read(sections.NAMED_PATH, raw, f'named_paths[{number}]')
    name = str(named.get('path_name'))
    links = [_read(sections.CHAIN_NODE, e, f'path {name}: node_chain[{i}]')
             for i, e in enumerate(named.get('node_chain'))]
    return name, [PathNode(str(link.get('node_name')), _topic(link.get('subscribe_topic_name')),
                           _topic(link.get('publish_topic_name'))) for link in links]


def _foreign_topic(chain: list[PathNode], nodes: dict[str, Node]) -> str | None:
    """A topic the chain puts on a known node that the node does not publish or subscribe (caret drops the
    path), or None."""
    for element in chain:
        node = nodes.get(element.node_name)
        if node is None:
            continue
        if element.publish_topic is not None and element.publish_topic not in node.publishes:
            return f'node {node.name} does not publish {element.publish_topic}'
        if element.subscribe_topic is not None and element.subscribe_topic not in node.subscribes:
            return f'node {node.name} does not subscribe {element.subscribe_topic}'
    return None


def _problems(chain: list[PathNode], nodes: dict[str, Node], skipped: dict[str, str]) -> list[str]:
    """Why a path cannot be measured: skipped or missing nodes, broken links, a one-node path without both
    topics."""
    problems = []
    for element in chain:
        if element.node_name in skipped:
            problems.append(f'node {element.node_name} was skipped ({skipped[element.node_name]})')
        elif element.node_name not in nodes:
            problems.append(f'path goes through node {element.node_name}, which is not in nodes')
    if not chain:
        problems.append('a path needs at least one node')
    elif len(chain) == 1 and (chain[0].subscribe_topic is None or chain[0].publish_topic is None):
        problems.append('a one-node path needs its subscribe and publish topics')
    return problems + _broken_links(chain)


def _broken_links(chain: list[PathNode]) -> list[str]:
    """Each pair of neighbours where the first's publish topic is not the next's subscribe topic."""
    return [f'{before.node_name} publishes {before.publish_topic} but {after.node_name} '
            f'subscribes {after.subscribe_topic}'
            for before, after in itertools.pairwise(chain)
            if before.publish_topic is None or before.publish_topic != after.subscribe_topic]
