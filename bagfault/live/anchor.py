"""The anchor's runtime interface, where its interface package (`ros2_fault_injection`) is importable.

ros2_fault_injection's node serves nine services under `fault_injection/`
(relative to the node's namespace) and publishes its events on
`/fault_injection/*`; its RViz panel and scripts use them. The proxy serves
the same services with the same answers (texts included, from
fault_service_manager.cpp), so those tools work against bagfault unchanged.
Events are published by `LiveEvents` on the anchor's topics.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from bagfault.errors import FieldValueError
from bagfault.injectors.registry import get_injector_type
from bagfault.live.ros import has_interface, interface_class

if TYPE_CHECKING:
    from bagfault.live.session import LiveSession
    from bagfault.spec.model import FaultSpec, Scenario

PACKAGE = 'ros2_fault_injection'
SERVICES = ('SetFaultState', 'ListFaults', 'GetFaultStatus', 'SetFaultConfig', 'ReloadScenario', 'GetFaultSchema',
            'GetFaultConfig', 'GetScenario', 'RequestReport')


def available() -> bool:
    """True when the anchor's interface package is importable here."""
    return has_interface(f'{PACKAGE}/srv/ListFaults')


def _name(kind: str) -> str:
    """'SetFaultState' -> 'fault_injection/set_fault_state'."""
    snake = ''.join(f'_{c.lower()}' if c.isupper() else c for c in kind).lstrip('_')
    return f'fault_injection/{snake}'


class AnchorServices:
    """The nine services, answering from the proxy's session."""

    def __init__(self, node: Any, proxy: Any) -> None:
        self.proxy = proxy
        self.services = [node.create_service(interface_class(f'{PACKAGE}/srv/{kind}'), _name(kind),
                                             getattr(self, '_' + _name(kind).split('/')[1]))
                         for kind in SERVICES]

    @property
    def session(self) -> LiveSession:
        session: LiveSession | None = self.proxy.session
        assert session is not None
        return session

    @property
    def scenario(self) -> Scenario:
        return self.session.scenario

    def _fault(self, fault_id: str, response: Any) -> FaultSpec | None:
        if not fault_id:
            response.success, response.message = False, 'fault_id cannot be empty'
            return None
        fault = self.session.state.fault(fault_id)
        if fault is None:
            response.success, response.message = False, f'unknown fault_id: {fault_id}'
        return fault

    def _active(self) -> set[str]:
        return {state.fault_id for state in self.session.faults() if state.active}

    # -- the services ------------------------------------------------------------------------------
    def _set_fault_state(self, request: Any, response: Any) -> Any:
        if self._fault(request.fault_id, response) is None:
            return response
        self.session.set_active(request.fault_id, bool(request.active), 'manual')
        response.success = True
        response.message = f'{"activated" if request.active else "deactivated"} fault: {request.fault_id}'
        return response

    def _list_faults(self, request: Any, response: Any) -> Any:
        active = self._active()
        ordered = [f.id for spec in self.scenario.injectors for f in self.session.state.faults_of(spec.id)]
        response.fault_ids = ordered
        response.active_fault_ids = [f for f in ordered if f in active]
        return response

    def _get_fault_status(self, request: Any, response: Any) -> Any:
        status = interface_class(f'{PACKAGE}/msg/FaultStatus')
        active = self._active()
        response.faults = [
            status(fault_id=f.id, injector_id=f.injector_id, state='active' if f.id in active else 'inactive',
                   details=f.describe_fault())
            for spec in self.scenario.injectors for f in self.session.state.faults_of(spec.id)]
        return response

    def _set_fault_config(self, request: Any, response: Any) -> Any:
        fault = self._fault(request.fault_id, response)
        if fault is None:
            return response
        injector = self.scenario.injector(fault.injector_id)
        assert injector is not None
        cls = get_injector_type(injector.type)
        if cls is None or cls.field(request.key) is None:
            response.success = False
            response.message = f"key '{request.key}' is not valid for injector type '{injector.type}'"
            return response
        try:
            self.proxy.ask(fault.id, request.key, request.value)
        except FieldValueError as exc:
            response.success, response.message = False, str(exc)
            return response
        response.success = True
        response.message = f"updated fault '{fault.id}' config '{request.key}' to '{request.value}'"
        return response

    def _reload_scenario(self, request: Any, response: Any) -> Any:
        response.success, response.message = self.proxy.reload_scenario()
        return response

    def _fault_of(self, request: Any, response: Any) -> tuple[Any, Any] | None:
        """The requested fault and its injector; None with the anchor's answer set for an unknown id."""
        fault = self.session.state.fault(request.fault_id)
        if fault is None:
            response.success, response.message = False, f'unknown fault_id: {request.fault_id}'
            return None
        injector = self.scenario.injector(fault.injector_id)
        assert injector is not None
        response.injector_id, response.injector_type = injector.id, injector.type
        return fault, injector

    def _get_fault_schema(self, request: Any, response: Any) -> Any:
        found = self._fault_of(request, response)
        if found is None:
            return response
        fault, injector = found
        cls = get_injector_type(injector.type)
        fields = sorted(cls.fields if cls is not None else (), key=lambda f: f.name)
        response.success, response.message = True, f'retrieved schema for fault_id: {fault.id}'
        response.keys = [f.name for f in fields]
        response.types = [f.type for f in fields]
        response.descriptions = [f.description for f in fields]
        response.default_values = ['' if f.default is None else _text(f.default) for f in fields]
        response.has_min_values = [f.minimum is not None for f in fields]
        response.min_values = [float(f.minimum) if f.minimum is not None else 0.0 for f in fields]
        response.has_max_values = [f.maximum is not None for f in fields]
        response.max_values = [float(f.maximum) if f.maximum is not None else 0.0 for f in fields]
        return response

    def _get_fault_config(self, request: Any, response: Any) -> Any:
        found = self._fault_of(request, response)
        if found is None:
            return response
        fault, _ = found
        response.success, response.message = True, f'retrieved config for fault_id: {fault.id}'
        keys = sorted(fault.config)
        response.keys = keys
        response.values = [fault.config_text.get(k, _text(fault.config[k])) for k in keys]
        return response

    def _get_scenario(self, request: Any, response: Any) -> Any:
        source = self.scenario.source
        if source is None:
            response.success = False
            response.message = 'No scenario file provided by scenario provider callback'
            return response
        response.success, response.message = True, f'Retrieved scenario: {source}'
        response.scenario_file, response.content = str(source), self.scenario.text
        return response

    def _request_report(self, request: Any, response: Any) -> Any:
        from bagfault.report.markdown import render  # noqa: PLC0415
        from bagfault.report.model import build  # noqa: PLC0415

        result = self.session.run.result('proxy', [], None, self.proxy.seed)
        report = build(result)
        response.success, response.message = True, 'report created'
        response.scenario_file = str(self.scenario.source or self.scenario.name)
        response.final_result = report['verdict'] if result.assertions else 'no assertions'
        response.report_markdown = render(report)
        return response


def _text(value: object) -> str:
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, float) and math.isinf(value):
        return '.inf' if value > 0 else '-.inf'
    return str(value)
