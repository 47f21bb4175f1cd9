"""Scenario files: model, loader (all anchor layouts), validator."""

from __future__ import annotations

from dataclasses import dataclass

from bagfault.errors import BagfaultError


@dataclass(frozen=True)
class Problem:
    """One thing wrong in a scenario, with its place in the file."""

    file: str
    where: str
    path: str
    message: str

    def __str__(self) -> str:
        return f'{self.file}:{self.where}: {self.path}: {self.message}'


class ScenarioError(BagfaultError):
    """A scenario cannot be used; carries every problem found."""

    def __init__(self, problems: list[Problem] | str) -> None:
        if isinstance(problems, str):
            problems = [Problem('<scenario>', '1:1', '<top>', problems)]
        self.problems = problems
        super().__init__('\n'.join(str(p) for p in problems))


from bagfault.scenario.loader import load_scenario, parse_scenario  # noqa: E402
from bagfault.scenario.model import AssertionSpec, FaultSpec, InjectorSpec, Scenario  # noqa: E402

__all__ = [
    'AssertionSpec',
    'FaultSpec',
    'InjectorSpec',
    'Problem',
    'Scenario',
    'ScenarioError',
    'load_scenario',
    'parse_scenario',
]
