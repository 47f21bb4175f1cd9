"""Scenario files: model, loader (all anchor layouts), validator."""

from __future__ import annotations

from bagfault.errors import Problem, ScenarioError
from bagfault.scenario.loader import load_scenario, parse_scenario
from bagfault.spec.model import AssertionSpec, FaultSpec, InjectorSpec, Scenario

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
