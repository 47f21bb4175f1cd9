"""Dotted paths into a scenario (`faults.imu_bias.config.angular_velocity_z_bias`) and the scenario they make.

In `faults`, `injectors` and `assertions` an element is named by its id;
elsewhere a segment is a mapping key. The single-injector layout
(`injector:`) answers to `injectors.<id>` too. Setting a value edits the
scenario's plain data, which is written back as YAML and loaded and
validated like any scenario file (relative paths stay relative to the
original file).
"""

from __future__ import annotations

import copy
from typing import TYPE_CHECKING, Any

import yaml

from bagfault.io.marks import stamp
from bagfault.scenario import parse_scenario
from bagfault.spec.yamlnodes import load_located

if TYPE_CHECKING:
    from pathlib import Path

    from bagfault.spec.model import Scenario

BY_ID = ('faults', 'injectors', 'assertions')


class PathError(ValueError):
    """A dotted path that does not lead anywhere in the scenario."""


def scenario_data(text: str) -> Any:
    """The scenario's plain data, numbers read as the loader reads them."""
    return load_located(text).data


def set_path(data: Any, path: str, value: Any) -> Any:
    """A copy of `data` with the value at `path` set (the last key may be new)."""
    out = copy.deepcopy(data)
    parts = path.split('.')
    node: Any = out
    for depth, part in enumerate(parts[:-1]):
        node = _step(node, part, parts[depth - 1] if depth else None, path)
    last = parts[-1]
    if not isinstance(node, dict):
        raise PathError(f'{".".join(parts[:-1]) or "the scenario"} is not a mapping')
    node[last] = value
    return out


def _step(node: Any, part: str, parent: str | None, path: str) -> Any:
    """The node one step down: an item by id in a list of faults, injectors or assertions, else a mapping's key
    (the anchor's single `injector:` as the list `injectors`); PathError naming what is not there."""
    if parent in BY_ID:
        return _by_id(node, part, parent)
    if not isinstance(node, dict):
        raise PathError(f'{part!r} is not below a mapping')
    if part == 'injectors' and 'injectors' not in node and isinstance(node.get('injector'), dict):
        return [node['injector']]
    if part not in node:
        raise PathError(f'the scenario has no {part!r} here')
    return node[part]


def _by_id(node: Any, part: str, parent: str) -> Any:
    """The item of the list `parent` whose id is `part`; PathError listing the ids there are."""
    if not isinstance(node, list):
        raise PathError(f'{parent} is not a list')
    for item in node:
        if isinstance(item, dict) and item.get('id') == part:
            return item
    known = ', '.join(str(i.get('id')) for i in node if isinstance(i, dict))
    raise PathError(f'no {parent[:-1]} {part!r} (there are: {known or "none"})')


def expanded(data: Any, values: dict[str, Any], source: Path | None) -> tuple[str, Scenario]:
    """The scenario text with `values` set, and that text loaded and validated (ScenarioError if it is not).
    The text carries its mark (io/marks.py): a job runs the very bytes the campaign folder keeps of it."""
    for path, value in values.items():
        data = set_path(data, path, value)
    text = stamp(yaml.safe_dump(data, sort_keys=False, allow_unicode=True).encode(), 'yaml').decode()
    return text, parse_scenario(text, source=source)
