"""Fault switches and config keys as ROS parameters, with descriptors from the injector schema.

Every fault gets `<fault_id>.active` (bool) and one parameter per config key
of its injector type (`<fault_id>.<key>`), so `ros2 param list/get/set`,
rqt_reconfigure or any parameter client can see and change them. Keys the
scenario does not set show the schema default; setting one adds it to the
fault's config. Values are checked by the same schema as scenario files.
"""

from __future__ import annotations

import re
import sys
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import yaml
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType

from bagfault.injectors.registry import get_injector_type

if TYPE_CHECKING:
    from bagfault.scenario.model import FaultSpec, Scenario
    from bagfault.schema import ConfigField

NAME = re.compile(r'^[A-Za-z][A-Za-z0-9_]*$')
TYPES = {'double': ParameterType.PARAMETER_DOUBLE, 'special_float': ParameterType.PARAMETER_DOUBLE,
         'int': ParameterType.PARAMETER_INTEGER, 'bool': ParameterType.PARAMETER_BOOL,
         'string': ParameterType.PARAMETER_STRING, 'non_empty_string': ParameterType.PARAMETER_STRING,
         'list': ParameterType.PARAMETER_STRING}
BIG = sys.float_info.max
BIG_INT = 2**63 - 1


@dataclass(frozen=True)
class FaultParameter:
    """One declared parameter: which fault and key (None for `active`) it stands for."""

    name: str
    fault_id: str
    key: str | None
    value: Any
    descriptor: ParameterDescriptor


def _descriptor(name: str, schema: ConfigField) -> ParameterDescriptor:
    descriptor = ParameterDescriptor(name=name, type=TYPES[schema.type], description=schema.description)
    constraints = []
    if schema.type == 'list':
        descriptor.read_only = True
        constraints.append('YAML text; change it by reloading the scenario')
    if schema.choices:
        constraints.append('one of: ' + ', '.join(schema.choices))
    if schema.type == 'double' and (schema.min is not None or schema.max is not None):
        low = schema.min if schema.min is not None else -BIG
        high = schema.max if schema.max is not None else BIG
        descriptor.floating_point_range = [FloatingPointRange(from_value=float(low), to_value=float(high), step=0.0)]
    if schema.type == 'int' and (schema.min is not None or schema.max is not None):
        low = int(schema.min) if schema.min is not None else -BIG_INT
        high = int(schema.max) if schema.max is not None else BIG_INT
        descriptor.integer_range = [IntegerRange(from_value=low, to_value=high, step=0)]
    descriptor.additional_constraints = '; '.join(constraints)
    return descriptor


def _value(schema: ConfigField, fault: FaultSpec) -> Any:
    value = fault.config.get(schema.key, schema.default)
    if schema.type == 'list':
        return yaml.safe_dump(value, default_flow_style=True).strip() if value is not None else '[]'
    if schema.type in ('double', 'special_float'):
        return float(value) if value is not None else 0.0
    if schema.type == 'int':
        return int(value) if value is not None else 0
    if schema.type == 'bool':
        return bool(value)
    return '' if value is None else str(value)


def fault_parameters(scenario: Scenario) -> tuple[list[FaultParameter], list[str]]:
    """Parameters of every fault, and notes on faults whose ids cannot be parameter names."""
    declared, notes = [], []
    for fault in scenario.faults:
        if not NAME.match(fault.id):
            notes.append(f'fault {fault.id!r}: id is not a valid parameter name; no parameters for it')
            continue
        injector = scenario.injector(fault.injector_id)
        cls = get_injector_type(injector.type) if injector is not None else None
        if cls is None:
            continue
        name = f'{fault.id}.active'
        declared.append(FaultParameter(name, fault.id, None, False, ParameterDescriptor(
            name=name, type=ParameterType.PARAMETER_BOOL,
            description=f'Fault {fault.id} of injector {fault.injector_id} is active (set to switch it now).')))
        for schema in cls.fields:
            name = f'{fault.id}.{schema.key}'
            declared.append(FaultParameter(name, fault.id, schema.key, _value(schema, fault),
                                           _descriptor(name, schema)))
    return declared, notes

