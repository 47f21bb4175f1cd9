"""Fault parameters on a real rclpy node: every key of every injector type declares with its default and takes
its default back (the class of problem where a default such as `inf` lies outside the declared range)."""

from __future__ import annotations

import math

import pytest

pytest.importorskip('rclpy')

import rclpy
import rclpy.context
from rclpy.node import Node
from rclpy.parameter import Parameter

from bagfault.injectors.registry import injector_types
from bagfault.live.params import fault_parameters
from bagfault.scenario import parse_scenario

pytestmark = pytest.mark.live  # needs rclpy


SYSTEM_TYPES = {'process': ', target: system', 'clock': '', 'link': ', link_topic: /a, subscriber: {node: /b}'}


def scenario_with_every_type() -> str:
    injectors, faults = [], []
    for name in injector_types():
        if name == 'trigger_service':
            injectors.append(f'  - {{id: {name}, type: {name}, proxy_service: /s, target_service: /s_raw}}')
        elif name in SYSTEM_TYPES:  # they act on a running system: no topics
            injectors.append(f'  - {{id: {name}, type: {name}{SYSTEM_TYPES[name]}}}')
        else:
            injectors.append(f'  - {{id: {name}, type: {name}, input_topic: /{name}_raw, output_topic: /{name}}}')
        config = '{parent_frame: odom, child_frame: base_link}' if name == 'tf' else '{}'
        faults.append(f'  - {{id: {name}_fault, injector_id: {name}, config: {config}}}')
    return 'injectors:\n' + '\n'.join(injectors) + '\nfaults:\n' + '\n'.join(faults) + '\n'


@pytest.fixture
def node():
    context = rclpy.context.Context()
    rclpy.init(context=context)
    made = Node('parameters_under_test', context=context)
    yield made
    made.destroy_node()
    rclpy.shutdown(context=context)


def test_every_key_of_every_type_declares_and_takes_its_default(node) -> None:
    scenario = parse_scenario(scenario_with_every_type(), validate=False)
    declared, notes = fault_parameters(scenario)
    assert notes == []
    assert {p.fault_id for p in declared} == {f'{name}_fault' for name in injector_types()}
    infinite = []
    for parameter in declared:
        node.declare_parameter(parameter.name, parameter.value, parameter.descriptor)  # raised for pointcloud2
        if parameter.descriptor.read_only:
            continue
        [result] = node.set_parameters([Parameter(parameter.name, value=parameter.value)])
        assert result.successful, (parameter.name, result.reason)
        if isinstance(parameter.value, float) and math.isinf(parameter.value):
            infinite.append(parameter.name)
    assert 'pointcloud2_fault.sector_max_range' in infinite  # the case that crashed the proxy at start
    assert len(declared) > 100
