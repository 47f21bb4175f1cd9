"""Fault switches and config keys as ROS parameters, with descriptors from the injector schema.

Every fault gets `<fault_id>.active` (bool) and one parameter per config key
of its injector type (`<fault_id>.<key>`), so `ros2 param list/get/set`,
rqt_reconfigure or any parameter client can see and change them. Keys the
scenario does not set show the schema default; setting one adds it to the
fault's config. Values are checked by the same schema as scenario files.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

import yaml
from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
    SetParametersResult,
)
from rclpy.parameter import Parameter

from bagfault.errors import FieldValueError, LiveError
from bagfault.injectors.registry import get_injector_type

if TYPE_CHECKING:
    from collections.abc import Callable

    from bagfault.engine.control import FaultControl
    from bagfault.engine.fault_state import FaultState
    from bagfault.events import FaultSource
    from bagfault.injectors.base import RawMessage
    from bagfault.live.session import FaultStatus, LiveTopic
    from bagfault.schema import Key
    from bagfault.spec.model import FaultSpec, Scenario

NAME = re.compile(r'[A-Za-z][A-Za-z0-9_]*')
TYPES = {'number': ParameterType.PARAMETER_DOUBLE, 'special_float': ParameterType.PARAMETER_DOUBLE,
         'integer': ParameterType.PARAMETER_INTEGER, 'boolean': ParameterType.PARAMETER_BOOL,
         'string': ParameterType.PARAMETER_STRING, 'non_empty_string': ParameterType.PARAMETER_STRING,
         'list': ParameterType.PARAMETER_STRING}
BIG_INT = 2**63 - 1
ROS_OWN = ('use_sim_time', 'qos_overrides.', 'start_type_description_service')  # rclpy's own parameters


@dataclass(frozen=True)
class FaultParameter:
    """One declared parameter: which fault and key (None for `active`) it stands for."""

    name: str
    fault_id: str
    key: str | None
    value: Any
    descriptor: ParameterDescriptor


def _descriptor(name: str, schema: Key) -> ParameterDescriptor:
    descriptor = ParameterDescriptor(name=name, type=TYPES[schema.type], description=schema.description)
    constraints = []
    if schema.type == 'list':
        descriptor.read_only = True
        constraints.append('YAML text; change it by reloading the scenario')
    if schema.choices:
        constraints.append('one of: ' + ', '.join(schema.choices))
    if schema.type == 'number' and (schema.minimum is not None or schema.maximum is not None):
        # an open side stays open: defaults may be inf
        low = schema.minimum if schema.minimum is not None else -math.inf
        high = schema.maximum if schema.maximum is not None else math.inf
        descriptor.floating_point_range = [FloatingPointRange(from_value=float(low), to_value=float(high), step=0.0)]
    if schema.type == 'integer' and (schema.minimum is not None or schema.maximum is not None):
        low = int(schema.minimum) if schema.minimum is not None else -BIG_INT
        high = int(schema.maximum) if schema.maximum is not None else BIG_INT
        descriptor.integer_range = [IntegerRange(from_value=low, to_value=high, step=0)]
    descriptor.additional_constraints = '; '.join(constraints)
    return descriptor


def _value(schema: Key, fault: FaultSpec) -> Any:
    value = fault.config.get(schema.name, schema.default)
    if schema.type == 'list':
        return yaml.safe_dump(value, default_flow_style=True).strip() if value is not None else '[]'
    if schema.type in ('number', 'special_float'):
        return float(value) if value is not None else 0.0
    if schema.type == 'integer':
        return int(value) if value is not None else 0
    if schema.type == 'boolean':
        return bool(value)
    return '' if value is None else str(value)


def fault_parameters(scenario: Scenario) -> tuple[list[FaultParameter], list[str]]:
    """Parameters of every fault, and notes on faults whose ids cannot be parameter names."""
    declared, notes = [], []
    for fault in scenario.faults:
        if not NAME.fullmatch(fault.id):
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
            name = f'{fault.id}.{schema.name}'
            declared.append(FaultParameter(name, fault.id, schema.name, _value(schema, fault),
                                           _descriptor(name, schema)))
    return declared, notes


class FaultTarget(Protocol):
    """Where parameter changes go: the proxy's live session, or the play's fault control."""

    @property
    def scenario(self) -> Scenario: ...

    @property
    def state(self) -> FaultState: ...

    def check_config(self, fault_id: str, key: str, value: object) -> Any: ...

    def set_active(self, fault_id: str, active: bool, source: FaultSource = 'manual') -> None: ...

    def set_config(self, fault_id: str, key: str, value: object) -> list[tuple[LiveTopic, RawMessage]]: ...

    def faults(self) -> list[FaultStatus]: ...


class ControlledFaults:
    """A play's faults as parameters see them: every change is checked and queued on the run's FaultControl,
    which switches it between two messages at bag time (the state itself is the run's, not shown back)."""

    def __init__(self, control: FaultControl) -> None:
        self.control = control

    @property
    def scenario(self) -> Scenario:
        return self.control.scenario

    @property
    def state(self) -> FaultState:
        return self.control.state

    def check_config(self, fault_id: str, key: str, value: object) -> Any:
        return self.control.state.check(fault_id, key, value)

    def set_active(self, fault_id: str, active: bool, source: FaultSource = 'manual') -> None:
        self.control.ask(fault_id, None, active)

    def set_config(self, fault_id: str, key: str, value: object) -> list[tuple[LiveTopic, RawMessage]]:
        self.control.ask(fault_id, key, value)
        return []

    def faults(self) -> list[FaultStatus]:
        return []


class FaultParameters:
    """Faults as ROS parameters: declared from the schema, checked, applied, kept in sync. A `-p` override of
    a name that is no parameter here is refused (LiveError naming the faults and keys there are)."""

    def __init__(self, node: Any, session: FaultTarget,
                 publish: Callable[[LiveTopic, bytes | memoryview], None]) -> None:
        self.node = node
        self.session = session
        self.publish = publish
        self.parameters: dict[str, FaultParameter] = {}
        self.overrides: list[Parameter] = []  # values given at start (-p, params files), applied once started
        self._syncing = False
        self.declare()
        given = getattr(node, '_parameter_overrides', {})  # -p and params files (rclpy keeps them here)
        unknown = [n for n in given if n not in self.parameters and not n.startswith(ROS_OWN)]
        if unknown:
            raise LiveError(f'--ros-args -p {self.unknown(unknown[0])}')
        node.add_pre_set_parameters_callback(self.widen)
        node.add_on_set_parameters_callback(self.check)
        node.add_post_set_parameters_callback(self.apply)

    def declare(self) -> None:
        """Declare the parameters of every fault of the current scenario; undeclare those of removed faults."""
        declared, notes = fault_parameters(self.session.scenario)
        for note in notes:
            self.node.get_logger().warning(note)
        wanted = {p.name: p for p in declared}
        for name in [n for n in self.parameters if n not in wanted]:
            self.node.undeclare_parameter(name)
            del self.parameters[name]
        for name, parameter in wanted.items():
            if name not in self.parameters:
                self._syncing = True
                try:
                    declared = self.node.declare_parameter(name, parameter.value, parameter.descriptor)
                except Exception as exc:  # noqa: BLE001 - an override of the wrong type or out of range
                    raise LiveError(f'parameter {name}: {exc}') from None
                finally:
                    self._syncing = False
                if declared.value != parameter.value:
                    self.overrides.append(declared)
            self.parameters[name] = parameter

    def apply_overrides(self) -> None:
        """Values given at start (`-p <fault>.active:=true`, params files): checked and applied once the
        session has started; LiveError with the schema's reason for a value it refuses."""
        overrides, self.overrides = self.overrides, []
        refused = self.check(overrides)
        if not refused.successful:
            raise LiveError(f'--ros-args: {refused.reason}')
        self.apply(overrides)

    def sync(self) -> None:
        """Parameters show the session's state (after scheduled changes, events, reloads)."""
        if self._syncing:
            return
        updates = []
        for state in self.session.faults():
            name = f'{state.fault_id}.active'
            if name in self.parameters and self.node.get_parameter(name).value != state.active:
                updates.append(Parameter(name, Parameter.Type.BOOL, state.active))
            for key, value in state.config.items():
                name = f'{state.fault_id}.{key}'
                declared = self.parameters.get(name)
                if declared is None or declared.descriptor.read_only:
                    continue
                if self.node.get_parameter(name).value != value:
                    updates.append(Parameter(name, value=value))
        if updates:
            self._syncing = True
            try:
                self.node.set_parameters(updates)
            finally:
                self._syncing = False

    def widen(self, parameters: list[Parameter]) -> list[Parameter]:
        """An integer for a floating-point key is that number (`ros2 param set /bagfault f.x_bias 1`)."""
        out = []
        for parameter in parameters:
            declared = self.parameters.get(parameter.name)
            if declared is not None and declared.descriptor.type == ParameterType.PARAMETER_DOUBLE \
                    and parameter.type_ == Parameter.Type.INTEGER:
                parameter = Parameter(parameter.name, Parameter.Type.DOUBLE, float(parameter.value))
            out.append(parameter)
        return out

    def check(self, parameters: list[Parameter]) -> SetParametersResult:
        """Refuse values the schema refuses, and names that are not parameters here, with the reason."""
        if self._syncing:
            return SetParametersResult(successful=True)
        for parameter in parameters:
            declared = self.parameters.get(parameter.name)
            if declared is None:
                if parameter.name.startswith(ROS_OWN):
                    continue
                return SetParametersResult(successful=False, reason=self.unknown(parameter.name))
            if declared.key is None:
                continue
            try:
                self.session.check_config(declared.fault_id, declared.key, parameter.value)
            except FieldValueError as exc:
                return SetParametersResult(successful=False, reason=f'{parameter.name}: {exc}')
        return SetParametersResult(successful=True)

    def unknown(self, name: str) -> str:
        """Why a name is not a parameter here, and what is."""
        fault_id, _, key = name.partition('.')
        faults = sorted({p.fault_id for p in self.parameters.values()})
        if fault_id not in faults:
            return (f'{name}: no fault {fault_id!r} here (faults: {", ".join(faults) or "none"}); '
                    'parameters are <fault>.active and <fault>.<config key>')
        keys = sorted(p.key or 'active' for p in self.parameters.values() if p.fault_id == fault_id)
        return f'{name}: {key!r} is not a key of fault {fault_id!r} (keys: {", ".join(keys)})'

    def apply(self, parameters: list[Parameter]) -> None:
        """Switch faults and change config values now."""
        if self._syncing:
            return
        self._syncing = True
        try:
            for parameter in parameters:
                declared = self.parameters.get(parameter.name)
                if declared is None:
                    continue
                if declared.key is None:
                    self.session.set_active(declared.fault_id, bool(parameter.value), 'manual')
                else:
                    for topic, message in self.session.set_config(declared.fault_id, declared.key, parameter.value):
                        self.publish(topic, message.data)
        finally:
            self._syncing = False
        self.sync()
