"""YAML loading that remembers where every value came from.

Validation messages name the place of a problem (`faults[2].config.x_bias`,
line and column), so the loader keeps a map from value path to position and
the raw scalar text (the anchor reports config values as written).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any

import yaml

PathKey = tuple[str | int, ...]


def format_path(path: PathKey) -> str:
    """Render ('faults', 2, 'config', 'x') as faults[2].config.x."""
    text = ''
    for part in path:
        if isinstance(part, int):
            text += f'[{part}]'
        else:
            text += f'.{part}' if text else str(part)
    return text or '<top>'


@dataclass
class LocatedYaml:
    """Plain data loaded from YAML plus positions and raw scalar texts."""

    data: Any
    marks: dict[PathKey, tuple[int, int]] = field(default_factory=dict)
    raw: dict[PathKey, str] = field(default_factory=dict)
    warnings: list[tuple[str, PathKey, str]] = field(default_factory=list)  # (line:col, path, message)

    def where(self, path: PathKey) -> str:
        """Line:column of path, or of its closest located parent."""
        probe = tuple(path)
        while probe not in self.marks and probe:
            probe = probe[:-1]
        line, col = self.marks.get(probe, (1, 1))
        return f'{line}:{col}'

    def raw_text(self, path: PathKey, value: object) -> str:
        """The scalar as written in the file, falling back to str(value)."""
        return self.raw.get(tuple(path), str(value))


class YamlSyntaxError(ValueError):
    """YAML could not be parsed or is not plain data; the message carries line and column."""


MAX_DEPTH = 64  # nesting of mappings and lists
MAX_NODES = 1_000_000  # values a file writes out: a scenario is at most this big
MAX_EXPANDED = 100_000  # values reached again through aliases: stops "billion laughs" files
# libyaml's where there is one: 7x faster, the same nodes (but a plain scalar's style is '' there, None in Python's)
COMPOSER = getattr(yaml, 'CSafeLoader', yaml.SafeLoader)
STANDARD_TAGS = {f'tag:yaml.org,2002:{name}' for name in
                 ('str', 'int', 'float', 'bool', 'null', 'map', 'seq', 'timestamp', 'binary', 'merge', 'value')}
FLOAT_12 = re.compile(r'[-+]?(\d+(\.\d*)?|\.\d+)([eE][-+]?\d+)')  # YAML 1.2 floats PyYAML (1.1) reads as text
SEXAGESIMAL = re.compile(r'[-+]?\d+(:[0-5]?\d)+(\.\d*)?')  # YAML 1.1 base 60 (1:30 = 90); text in YAML 1.2


def load_located(text: str) -> LocatedYaml:
    """Parse YAML text into plain Python data with a position map.

    Numbers follow YAML 1.2 (`1e3` is 1000.0, `1:30` is text) as yaml-cpp reads
    them; merge keys (`<<:`) are applied; a key given twice keeps its first value
    (yaml-cpp's lookup) with a warning; a file of more than MAX_NODES values, aliases
    that reach more than MAX_EXPANDED values again, recursive aliases, nesting
    deeper than MAX_DEPTH and non-standard tags are errors.
    """
    try:
        node = yaml.compose(text, Loader=COMPOSER)
    except yaml.YAMLError as exc:
        mark = getattr(exc, 'problem_mark', None)
        problem = getattr(exc, 'problem', None) or str(exc)
        where = f'{mark.line + 1}:{mark.column + 1}: ' if mark else ''
        raise YamlSyntaxError(f'{where}invalid YAML: {problem}') from None
    except RecursionError:
        raise YamlSyntaxError(f'1:1: invalid YAML: nested more than {MAX_DEPTH} levels deep') from None
    result = LocatedYaml(None)
    if node is None:
        return result
    result.data = _Converter(result).convert(node, ())
    return result


class _Converter:
    """Composed YAML nodes to plain data, with positions, raw texts, limits and warnings."""

    def __init__(self, out: LocatedYaml) -> None:
        self.out = out
        self.ctor = yaml.SafeLoader('')
        self.seen: set[int] = set()  # the nodes the file writes (an alias's target counts once here)
        self.expanded = 0
        self.active: set[int] = set()

    def fail(self, node: yaml.Node, message: str) -> YamlSyntaxError:
        return YamlSyntaxError(f'{node.start_mark.line + 1}:{node.start_mark.column + 1}: {message}')

    def count(self, node: yaml.Node) -> None:
        """Count a node the file writes, or one reached again through an alias; YamlSyntaxError past the limits."""
        if id(node) in self.seen:  # reached again through an alias
            self.expanded += 1
            if self.expanded > MAX_EXPANDED:
                raise self.fail(node, f'more than {MAX_EXPANDED} values reached again through aliases (an alias '
                                      'bomb?)')
        else:
            self.seen.add(id(node))
            if len(self.seen) > MAX_NODES:
                raise self.fail(node, f'more than {MAX_NODES} values: a scenario file holds at most that many')

    def convert(self, node: yaml.Node, path: PathKey) -> Any:
        self.count(node)
        if len(path) > MAX_DEPTH:
            raise self.fail(node, f'nested more than {MAX_DEPTH} levels deep')
        if node.tag not in STANDARD_TAGS:
            raise self.fail(node, f'unknown tag {node.tag!r}: a scenario holds plain data only')
        self.out.marks.setdefault(path, (node.start_mark.line + 1, node.start_mark.column + 1))
        if isinstance(node, yaml.ScalarNode):
            return self.scalar(node, path)
        if id(node) in self.active:
            raise self.fail(node, 'recursive alias: a value contains itself')
        self.active.add(id(node))
        try:
            if isinstance(node, yaml.SequenceNode):
                return [self.convert(item, (*path, i)) for i, item in enumerate(node.value)]
            assert isinstance(node, yaml.MappingNode)
            return self.mapping(node, path)
        finally:
            self.active.discard(id(node))

    def scalar(self, node: yaml.ScalarNode, path: PathKey) -> Any:
        self.out.raw[path] = node.value
        if not node.style and node.tag == 'tag:yaml.org,2002:str' and FLOAT_12.fullmatch(node.value):
            return float(node.value)
        if not node.style and SEXAGESIMAL.fullmatch(node.value):
            return node.value
        try:
            return self.ctor.construct_object(node, deep=True)
        except (yaml.YAMLError, ValueError) as exc:
            raise self.fail(node, f'invalid value {node.value!r}: {exc}') from None

    def mapping(self, node: yaml.MappingNode, path: PathKey) -> dict[Any, Any]:
        mapping: dict[Any, Any] = {}
        lines: dict[Any, int] = {}
        merged: list[yaml.MappingNode] = []
        for key_node, value_node in node.value:
            if key_node.tag == 'tag:yaml.org,2002:merge' or (isinstance(key_node, yaml.ScalarNode)
                                                              and key_node.value == '<<' and not key_node.style):
                merged += self.merge_sources(value_node)
                continue
            # Keys stay as written: YAML 1.1 would turn `on:` (repeat: {period, on}) into True.
            key = key_node.value if isinstance(key_node, yaml.ScalarNode) else str(self.convert(key_node, path))
            if key in mapping:
                line = key_node.start_mark.line + 1
                self.out.warnings.append((
                    f'{line}:{key_node.start_mark.column + 1}', (*path, key),
                    f'key given twice (first on line {lines[key]}); the first value is used, as ros2_fault_injection '
                    'reads it'))
                continue
            lines[key] = key_node.start_mark.line + 1
            mapping[key] = self.convert(value_node, (*path, key))
        for source in merged:  # merge keys fill in what the mapping does not set itself
            for key, value in self.mapping(source, path).items():
                mapping.setdefault(key, value)
        return mapping

    def merge_sources(self, node: yaml.Node) -> list[yaml.MappingNode]:
        if isinstance(node, yaml.MappingNode):
            return [node]
        if isinstance(node, yaml.SequenceNode) and all(isinstance(n, yaml.MappingNode) for n in node.value):
            return list(node.value)
        raise self.fail(node, 'a merge key (<<) takes a mapping or a list of mappings')
