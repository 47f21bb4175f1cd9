"""A table of types by name whose modules are imported the first time a name is looked up.

The registries of injector and assertion types list every built-in, but a
run needs only the types its scenario names: a run with no assertion loads no
assertion module (their imports were 0.03 s of a no-fault run's CPU). Modeled
on rosbags' storage plugins, chosen from a table rather than imported up front.
"""

from __future__ import annotations

import importlib
from collections.abc import Iterator, Mapping
from typing import Generic, TypeVar

T = TypeVar('T')


class TypesByName(Mapping[str, T], Generic[T]):
    """name -> 'module:attribute', read as name -> the attribute (its module imported on first use)."""

    def __init__(self, places: Mapping[str, str]) -> None:
        self.places = dict(places)
        self._loaded: dict[str, T] = {}

    def __getitem__(self, name: str) -> T:
        found = self._loaded.get(name)
        if found is None:
            module, _, attribute = self.places[name].partition(':')
            found = self._loaded[name] = getattr(importlib.import_module(module), attribute)
        return found

    def __iter__(self) -> Iterator[str]:
        return iter(self.places)

    def __len__(self) -> int:
        return len(self.places)
