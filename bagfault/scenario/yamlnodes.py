"""YAML loading that remembers where every value came from.

Validation messages name the place of a problem (`faults[2].config.x_bias`,
line and column), so the loader keeps a map from value path to position and
the raw scalar text (the anchor reports config values as written).
"""

from __future__ import annotations

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
    """YAML could not be parsed; message carries line and column."""


def load_located(text: str) -> LocatedYaml:
    """Parse YAML text into plain Python data with a position map."""
    try:
        node = yaml.compose(text, Loader=yaml.SafeLoader)
    except yaml.YAMLError as exc:
        mark = getattr(exc, 'problem_mark', None)
        problem = getattr(exc, 'problem', None) or str(exc)
        where = f'{mark.line + 1}:{mark.column + 1}: ' if mark else ''
        raise YamlSyntaxError(f'{where}invalid YAML: {problem}') from None
    result = LocatedYaml(None)
    if node is None:
        return result
    constructor = yaml.SafeLoader('')
    result.data = _convert(node, (), result, constructor)
    return result


def _convert(node: yaml.Node, path: PathKey, out: LocatedYaml, ctor: yaml.SafeLoader) -> Any:
    out.marks[path] = (node.start_mark.line + 1, node.start_mark.column + 1)
    if isinstance(node, yaml.MappingNode):
        mapping: dict[Any, Any] = {}
        for key_node, value_node in node.value:
            # Keys stay as written: YAML 1.1 would turn `on:` (repeat: {period, on}) into True.
            key = key_node.value if isinstance(key_node, yaml.ScalarNode) else str(ctor.construct_object(key_node))
            if key == '<<':
                continue
            mapping[key] = _convert(value_node, (*path, key), out, ctor)
        return mapping
    if isinstance(node, yaml.SequenceNode):
        return [_convert(item, (*path, i), out, ctor) for i, item in enumerate(node.value)]
    out.raw[path] = node.value
    return ctor.construct_object(node, deep=True)
