"""The loader's records read as their types say, before they are checked and sealed.

Once the injector and assertion types are known (the plugin registries):
an injector of an unknown type is left out with its faults (as the anchor
does), each injector's options, fault's config and assertion's parameters
become their fields' values (`'inf'` -> float('inf'), `"2"` -> 2: the engine
never parses text; an unknown config key is left out with a warning), and
the fault manager section becomes its config, read by the fault manager.
The validator then only reads.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from bagfault.assertions.registry import ASSERTION_TYPES
from bagfault.errors import FieldValueError
from bagfault.fault_manager.config import scenario_config
from bagfault.injectors.registry import get_injector_type, injector_types
from bagfault.spec.reader import key_hint

if TYPE_CHECKING:
    from bagfault.scenario.loader import _Collector
    from bagfault.schema import Key
    from bagfault.spec.model import AssertionSpec, FaultSpec, InjectorSpec, Scenario


def resolve_scenario(scenario: Scenario, out: _Collector) -> None:
    """Read every record as its type says (see the module's docstring); problems and warnings to `out`."""
    _skip_unknown_types(scenario, out)
    for injector in scenario.injectors:
        _options(injector, out)
    for fault in scenario.faults:
        _config(scenario, fault, out)
    for assertion in scenario.assertions:
        _params(assertion, out)
    scenario.fault_manager_config = scenario_config(scenario, out.add, out.ignored)


def coerce(field: Key, value: Any, path: tuple[Any, ...], out: _Collector) -> Any:
    """The value as the field reads it; None (and the problem said) when it cannot."""
    try:
        return field.coerce(value)
    except FieldValueError as exc:
        out.add(path, str(exc))
        return None


def _options(injector: InjectorSpec, out: _Collector) -> None:
    cls = get_injector_type(injector.type) if injector.type else None
    for field in cls.options if cls is not None else ():
        if field.name in injector.options:
            path = (*injector.path, field.name)
            injector.options[field.name] = coerce(field, injector.options[field.name], path, out)


def _config(scenario: Scenario, fault: FaultSpec, out: _Collector) -> None:
    injector = scenario.injector(fault.injector_id) if fault.injector_id else None
    cls = get_injector_type(injector.type) if injector is not None else None
    if injector is None or cls is None:
        return  # an unknown injector: the validator says so
    keys = [f.name for f in cls.fields]
    for key, value in list(fault.config.items()):
        path = (*fault.path, 'config', key)
        field = cls.field(str(key))
        if field is None:
            out.ignored(path, f'unknown config key {key!r} for injector type {injector.type!r} is ignored'
                              f'{key_hint(str(key), keys)}')
            del fault.config[key]  # still shown in the fault's event details, as the anchor shows it
            continue
        fault.config[key] = coerce(field, value, path, out)


def _params(assertion: AssertionSpec, out: _Collector) -> None:
    cls = ASSERTION_TYPES.get(assertion.type) if assertion.type else None
    if cls is None:
        return  # (an unknown type is the validator's error)
    for key, value in list(assertion.params.items()):
        field = cls.field(str(key))
        if field is not None:  # (an unknown key is the validator's error)
            assertion.params[key] = coerce(field, value, (*assertion.path, key), out)


def _skip_unknown_types(scenario: Scenario, out: _Collector) -> None:
    """An injector type neither built in nor given by an installed plugin: the anchor's validator warns
    ('assuming external plugin'), its controller creates no injector and skips that injector's faults, and the
    other injectors run. So here: a warning (an error under --strict), the injector and its faults left out."""
    unknown = _of_unknown_type(scenario)
    if not unknown:
        return
    kept = [i for i in scenario.injectors if all(i is not u for u in unknown)]
    gone = {u.id for u in unknown} - {i.id for i in kept}  # (a duplicate id of a known type keeps its faults)
    for injector in unknown:  # one warning, as the anchor's validator gives one (its faults named in it)
        _skipped(scenario, injector, gone, out)
    _leave_out(scenario, kept, gone)


def _of_unknown_type(scenario: Scenario) -> list[InjectorSpec]:
    """The injectors whose type is neither built in nor given by a plugin."""
    return [i for i in scenario.injectors if i.type and get_injector_type(i.type) is None]


def _leave_out(scenario: Scenario, kept: list[InjectorSpec], gone: set[str]) -> None:
    """Only the injectors kept, and only the faults of injectors not gone (the others' ids noted as skipped)."""
    scenario.skipped_faults = [f.id for f in scenario.faults if f.injector_id in gone]
    scenario.injectors = kept
    scenario.faults = [f for f in scenario.faults if f.injector_id not in gone]


def _skipped(scenario: Scenario, injector: InjectorSpec, gone: set[str], out: _Collector) -> None:
    """The warning of an injector of an unknown type, naming the faults skipped with it."""
    faults = [f.id for f in scenario.faults if f.injector_id == injector.id and injector.id in gone]
    which = f' ({", ".join(dict.fromkeys(faults))})' if faults else ''
    known_types = ', '.join(sorted(injector_types()))
    out.ignored((*injector.path, 'type'), f'unknown injector type {injector.type!r}: not built in and no '
                f'installed plugin provides it, so injector {injector.id!r} and its faults{which} are skipped '
                f'and the others run, as the anchor does ("assuming external plugin"; known: {known_types})')
