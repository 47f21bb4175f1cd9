"""The embedded demo: a synthetic rover bag and a scenario, run by `bagfault demo`."""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from bagfault.demo import synthetic

SCENARIO_NAME = 'demo_scenario.yaml'


def scenario_text() -> str:
    """The demo scenario as shipped in the package."""
    return resources.files('bagfault.demo').joinpath(SCENARIO_NAME).read_text(encoding='utf-8')


def prepare(directory: Path) -> tuple[Path, Path]:
    """Write the demo bag (20 s rover) and scenario into directory; return their paths."""
    directory.mkdir(parents=True, exist_ok=True)
    bag = directory / 'demo_input.mcap'
    scenario = directory / SCENARIO_NAME
    synthetic.write_rover_bag(bag, duration=20.0)
    scenario.write_text(scenario_text(), encoding='utf-8')
    return bag, scenario

__all__ = [  # its own functions, then its public modules
    'SCENARIO_NAME',
    'prepare',
    'scenario_text',
    'synthetic',
    'workloads',
]
