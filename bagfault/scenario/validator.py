"""Scenario checks against the injector and assertion schemas, on records resolve.py has read.

Every problem is collected with its YAML location; nothing is changed (the
values were read as their fields say by `scenario/resolve.py`). Warnings
follow the anchor: things it accepts but ignores (`start` with
`active_on_startup`, `duration` without `start`).
"""

from __future__ import annotations

import math
import re
from collections import Counter
from typing import TYPE_CHECKING, Any

from bagfault.assertions.registry import ASSERTION_TYPES
from bagfault.errors import FieldValueError, InjectorConfigError
from bagfault.injectors.base import Injector, ServiceInjector, SystemInjector
from bagfault.injectors.registry import get_injector_type
from bagfault.scenario.resolve import coerce
from bagfault.schema import Key
from bagfault.spec.reader import key_hint
from bagfault.yamlcpp import as_double

if TYPE_CHECKING:
    from bagfault.scenario.loader import _Collector
    from bagfault.spec.model import Explore, ExploreFault, FaultSpec, Scenario
    from bagfault.spec.yamlnodes import PathKey


def check_ids(scenario: Scenario, out: _Collector) -> None:
    """Before the records are resolved (an injector of an unknown type still counts): ids unique."""
    _duplicates(scenario, out)


def validate_scenario(scenario: Scenario, out: _Collector) -> None:
    """Check the resolved records (scenario/resolve.py); append problems and warnings to `out`. Reads only."""
    for injector in scenario.injectors:
        _check_injector(injector, out)
    _check_outputs(scenario, out)
    for fault in scenario.faults:
        _check_fault(scenario, fault, out)
    _check_chains(scenario, out)
    for assertion in scenario.assertions:
        _check_assertion(scenario, assertion, out)
    if scenario.explore is not None:
        _check_explore(scenario, scenario.explore, out)


def _duplicates(scenario: Scenario, out: _Collector) -> None:
    """Injector and assertion ids are unique, as the anchor's validator requires. A fault id defined again is
    loaded by the anchor (scenario_validator.cpp has no such check): its injector keeps faults in a map by id
    (fault_injector_base.cpp add_fault), so the last definition's config is used, and its scheduler sets a
    timer for every definition, so each schedule switches that id. bagfault does the same, with a warning; a
    repeated id on two injectors (two faults of one name, switched independently) is refused."""
    for kind, items in (('injector', scenario.injectors), ('assertion', scenario.assertions)):
        counts = Counter(x.id for x in items if x.id)
        seen: set[str] = set()
        for item in (x for x in items if counts[x.id] > 1):
            if item.id in seen:
                out.add((*item.path, 'id'), f'duplicate {kind} id {item.id!r}')
            seen.add(item.id)
    _redefined_faults(scenario, out)


def _redefined_faults(scenario: Scenario, out: _Collector) -> None:
    """A fault id defined again: refused on another injector, a warning on the same one (see `_duplicates`)."""
    first: dict[str, FaultSpec] = {}
    for fault in scenario.faults:
        earlier = first.setdefault(fault.id, fault) if fault.id else fault
        if earlier is fault:
            continue
        if earlier.injector_id != fault.injector_id:
            out.add((*fault.path, 'id'), f'fault id {fault.id!r} is also a fault of injector {earlier.injector_id!r}: '
                                         'one id on two injectors would be two faults switched apart; rename one')
        else:
            out.warn((*fault.path, 'id'), f'fault id {fault.id!r} is defined again: as the anchor, this last '
                                          "definition's config is used and every definition's schedule switches "
                                          'the fault')


ANCHOR_TYPES = frozenset({'odom', 'scan', 'joint_state', 'imu', 'trigger_service', 'tf'})  # is_known_injector_type
_FROM_CHARS_DOUBLE = re.compile(r'-?(?:(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?|inf(?:inity)?|nan(?:\([\w]*\))?)',
                                re.IGNORECASE)


def anchor_refusal(field: Key, text: str) -> str | None:
    """What ros2_fault_injection's validate_config_value (fault_config_schema.cpp) says of a config value's
    scalar text, None when it accepts it. Its numbers are std::from_chars over the whole text: no leading '+',
    no hexadecimal, no YAML's '.inf', and an int key takes no decimal point."""
    kind = field.type
    if kind == 'boolean':
        return None if text in ('true', 'false') else f"config '{field.name}' must be 'true' or 'false'"
    if kind == 'integer':
        if re.fullmatch(r'-?\d+', text) is None or not -2**31 <= int(text) < 2**31:
            return f"config '{field.name}' must be an integer"
        return None
    if kind in ('number', 'special_float'):
        return _number_refusal(field.name, text, special=kind == 'special_float')
    return None


def _number_refusal(name: str, text: str, *, special: bool) -> str | None:
    """A double key's text as from_chars reads it; `special`: inf, -inf and nan are named as accepted."""
    if special and text in ('inf', '+inf', '-inf', 'nan'):
        return None
    if _FROM_CHARS_DOUBLE.fullmatch(text) is None:
        tail = ', inf, -inf, or nan' if special else ''
        return f"config '{name}' must be a number{tail}"
    return None


def _check_injector(injector: Any, out: _Collector) -> None:
    if not injector.type:
        return
    cls = get_injector_type(injector.type)
    assert cls is not None  # unknown types were left out
    _check_endpoints(injector, cls, out)
    for field in cls.options:
        if field.required and field.name not in injector.options:
            out.add(injector.path, f'missing required key {field.name!r} for injector type {injector.type!r}')
    try:
        cls.check_options(injector.options)
    except InjectorConfigError as exc:
        out.add(injector.path, str(exc))


def _check_endpoints(injector: Any, cls: Any, out: _Collector) -> None:
    """A topic type with topics, a service type with services, a system type with neither service."""
    is_service_type = issubclass(cls, ServiceInjector)
    if issubclass(cls, SystemInjector):
        if injector.is_service:
            out.add(injector.path, f'injector type {injector.type!r} acts on the running system; it proxies no '
                                   'service')
    elif is_service_type and not injector.is_service:
        out.add(injector.path,
                f'injector type {injector.type!r} proxies a service: give proxy_service and target_service')
    if not is_service_type and injector.is_service:
        out.add(injector.path, f'injector type {injector.type!r} proxies a topic: give input_topic and output_topic')


def _check_outputs(scenario: Scenario, out: _Collector) -> None:
    writers: dict[str, str] = {}
    for injector in scenario.injectors:
        if not injector.output_topic:
            continue
        if injector.output_topic in writers:
            out.add((*injector.path, 'output_topic'),
                    f'output topic {injector.output_topic} is already written by injector '
                    f'{writers[injector.output_topic]!r}')
        writers[injector.output_topic] = injector.id


def _check_fault(scenario: Scenario, fault: Any, out: _Collector) -> None:
    _check_schedule_keys(fault, out)
    if not fault.injector_id:
        return
    injector = scenario.injector(fault.injector_id)
    if injector is None:
        known = ', '.join(dict.fromkeys(x.id for x in scenario.injectors)) or 'none'
        out.add((*fault.path, 'injector_id'), f'unknown injector {fault.injector_id!r} (injectors: {known})')
        return
    cls = get_injector_type(injector.type)
    if cls is not None:
        _check_fault_config(fault, injector, cls, out)


def _check_fault_config(fault: Any, injector: Any, cls: Any, out: _Collector) -> None:
    """Each config value, the required keys, then the whole config as the injector type checks it."""
    for key, coerced in fault.config.items():  # (as resolve.py read them: unknown keys left out)
        field = cls.field(str(key))
        assert field is not None
        _check_config_value(fault, injector.type, field, str(key), coerced, out)
    for field in cls.fields:
        if field.required and field.name not in fault.config:
            out.add((*fault.path, 'config'), f'missing required key {field.name!r} for injector type {injector.type!r}')
    if all(v is not None for v in fault.config.values()):
        _check_config(fault, injector.options, cls, out)


def _check_schedule_keys(fault: Any, out: _Collector) -> None:
    """Schedule keys the anchor accepts and ignores."""
    if fault.active_on_startup and fault.start is not None:
        out.ignored((*fault.path, 'start'), f'fault {fault.id!r} has active_on_startup and start; start is ignored')
    if (not fault.active_on_startup and fault.duration is not None and fault.start is None
            and fault.after is None and fault.repeat is None and fault.probability_per_second is None):
        out.ignored((*fault.path, 'duration'), f'fault {fault.id!r} has duration but no start; duration is ignored')


def _check_config_value(fault: Any, injector_type: str, field: Key, key: str, coerced: Any,
                        out: _Collector) -> None:
    """One config value: what the anchor would refuse of its text, what nan and inf do."""
    path = (*fault.path, 'config', key)
    text = fault.config_text.get(key, str(coerced))  # the scalar as the file writes it
    refusal = anchor_refusal(field, text) if injector_type in ANCHOR_TYPES else None
    if coerced is not None and refusal is not None:
        out.warn(path, f"{text!r} is read here, but ros2_fault_injection's "
                       f'validator refuses it ({refusal}): the file would not load in the anchor')
    if isinstance(coerced, float) and not math.isfinite(coerced):
        _non_finite(path, key, field, coerced, refused=refusal is not None, out=out)


def _non_finite(path: PathKey, key: str, field: Key, value: float, *, refused: bool, out: _Collector) -> None:
    """What nan and inf do to a config value (nothing to a level, where the anchor's std::max keeps the other)."""
    if math.isnan(value) and key.endswith(('_stddev', '_probability')):
        out.ignored(path, "nan has no effect: a level is the largest of the active faults' values, and "
                       'ros2_fault_injection folds them with std::max(level, nan), which keeps level')
    elif field.type == 'number' and not refused:
        out.warn(path, f'{value} makes every value it touches {value} or nan (ros2_fault_injection accepts '
                       'it too)')


def _check_config(fault: Any, options: dict[str, Any], cls: Any, out: _Collector) -> None:
    """The whole config, as its injector type checks it (and, acting on the system, its schedule)."""
    try:
        cls.check_fault(fault.config, options)
    except InjectorConfigError as exc:
        out.add((*fault.path, 'config'), str(exc))
    if issubclass(cls, Injector):
        for warning in cls.config_warnings(fault.config):
            out.warn((*fault.path, 'config'), warning)
    if issubclass(cls, SystemInjector):
        has_end = fault.duration is not None or fault.repeat is not None or fault.probability_per_second is not None
        problem = cls.check_schedule(fault.config, has_end)
        if problem is not None:
            out.add(fault.path, problem)


def _check_chains(scenario: Scenario, out: _Collector) -> None:
    """Unknown `after` faults, and each loop of `after` chains once, at its first fault in the file."""
    by_id: dict[str, FaultSpec] = {}
    for fault in scenario.faults:
        by_id.setdefault(fault.id, fault)
    position = {fault.id: number for number, fault in reversed(list(enumerate(scenario.faults)))}
    for fault in scenario.faults:
        if fault.after is not None and fault.after.fault not in by_id:
            out.add((*fault.path, 'after', 'fault'), f'unknown fault {fault.after.fault!r}')
    followed: set[str] = set()  # faults whose chain was walked already (a loop is found once)
    for fault in scenario.faults:
        loop = _loop_from(fault, by_id, followed)
        if not loop:
            continue
        first = min(loop, key=position.__getitem__)
        loop = loop[loop.index(first):] + loop[:loop.index(first)]
        path = (*by_id[first].path, 'after', 'fault')
        if len(loop) == 1:
            out.add(path, 'a fault cannot be chained after itself')
        else:
            out.add(path, f'chain of "after" faults loops: {" -> ".join([*loop, first])}')


def _loop_from(fault: FaultSpec, by_id: dict[str, FaultSpec], followed: set[str]) -> list[str]:
    """The loop the `after` chain from `fault` runs into, if it runs into one not walked before (then `followed`
    holds every fault walked)."""
    walk: list[str] = []
    probe: FaultSpec | None = fault
    while probe is not None and probe.id not in followed and probe.id not in walk:
        walk.append(probe.id)
        probe = by_id.get(probe.after.fault) if probe.after is not None else None
    followed.update(walk)
    if probe is None or probe.id not in walk:
        return []
    return walk[walk.index(probe.id):]


ANCHOR_ASSERTIONS = {'topic_hz', 'fault_event'}  # the assertion types ros2_fault_injection has


def _check_assertion(scenario: Scenario, assertion: Any, out: _Collector) -> None:
    if not assertion.type:
        return
    cls = ASSERTION_TYPES.get(assertion.type)
    if cls is None:
        known = ', '.join(sorted(ASSERTION_TYPES))
        out.add((*assertion.path, 'type'), f'unknown assertion type {assertion.type!r} (known: {known})')
        return
    if assertion.within is not None and not cls.takes_within:
        out.add((*assertion.path, 'within'), f'{assertion.type} has no deadline; within does not apply')
    _check_assertion_params(assertion, cls, out)
    for field in cls.fields:
        if field.required and field.name not in assertion.params:
            out.add(assertion.path, f'missing required key {field.name!r} for assertion type {assertion.type!r}')
    _check_assertion_values(scenario, assertion, cls, out)
    _window_advisory(assertion, out)


def _check_assertion_values(scenario: Scenario, assertion: Any, cls: Any, out: _Collector) -> None:
    """The values together, as the assertion type checks them (once every one could be read)."""
    if all(v is not None for v in assertion.params.values()):
        for key, message in cls.check(assertion, scenario):
            out.add((*assertion.path, key) if key else assertion.path, message)


def _window_advisory(assertion: Any, out: _Collector) -> None:
    """The anchor's advisory (scenario_validator.cpp, validate_assertions): a topic_hz deadline shorter than its
    window may fail before a full window was measured."""
    window = assertion.params.get('window')
    if assertion.type == 'topic_hz' and assertion.within is not None and isinstance(window, (int, float)) \
            and assertion.within < window:
        out.warn((*assertion.path, 'within'), f'assertion {assertion.id!r} has within smaller than window; it may '
                                               'fail before a full measurement window is available')


def _check_assertion_params(assertion: Any, cls: Any, out: _Collector) -> None:
    """Each key the assertion gives: one its type has, and a number the anchor's yaml-cpp reads too."""
    keys = [f.name for f in cls.fields]
    for key, value in list(assertion.params.items()):
        field = cls.field(str(key))
        path = (*assertion.path, key)
        if field is None:
            out.add(path, f'unknown key {key!r} for assertion type {assertion.type!r}{key_hint(str(key), keys)}')
            continue
        raw = out.located.raw_text(path, value)
        if assertion.type in ANCHOR_ASSERTIONS and field.type == 'number' and assertion.params[key] is not None \
                and as_double(raw) is None:  # scenario_config.cpp reads min_hz and window with as<double>()
            out.warn(path, f"{raw!r} is read here, but ros2_fault_injection's yaml-cpp refuses it (as<double>: a "
                           "decimal or .inf/.nan only)")


def _check_explore(scenario: Scenario, explore: Explore, out: _Collector) -> None:
    """The fault space: unique candidates on known injectors, config keys their type has, each dimension numeric
    and within the key's schema range at both ends, at least one dimension, max_faults within the candidates."""
    faults = {f.id for f in scenario.faults}
    seen: set[str] = set()
    for fault in explore.faults:
        if fault.id in faults or fault.id in seen:
            out.add((*fault.path, 'id'), f"fault id {fault.id!r} is taken: candidates and the scenario's faults each "
                                         'need their own')
        seen.add(fault.id)
        _check_candidate(scenario, fault, out)
    if explore.faults and not any(f.dimensions for f in explore.faults):
        out.add(('explore', 'faults'), 'no dimension to explore: give at least one [low, high] (a numeric config '
                                       'key, start or duration)')
    if explore.faults and explore.max_faults > len(explore.faults):
        out.add(('explore', 'max_faults'), f'{explore.max_faults} is more than the {len(explore.faults)} candidate '
                                           'faults')


def _check_candidate(scenario: Scenario, fault: ExploreFault, out: _Collector) -> None:
    if not fault.injector_id:
        return
    injector = scenario.injector(fault.injector_id)
    if injector is None:
        known = ', '.join(dict.fromkeys(x.id for x in scenario.injectors)) or 'none'
        out.add((*fault.path, 'injector_id'), f'unknown injector {fault.injector_id!r} (injectors: {known})')
        return
    cls = get_injector_type(injector.type)
    assert cls is not None  # unknown types were left out
    corners = _candidate_config(fault, injector.type, cls, out)
    for dimension in fault.dimensions:
        if dimension.name.startswith('config.'):
            _check_config_dimension(fault, injector.type, cls, dimension, corners, out)
    _check_corners(fault, injector.options, cls, corners, out)


def _check_corners(fault: ExploreFault, options: dict[str, Any], cls: Any, corners: list[dict[str, Any]],
                   out: _Collector) -> None:
    """The config at both corners of the space, as the injector type checks a config (the first problem only)."""
    for corner in corners:
        if all(v is not None for v in corner.values()):
            try:
                cls.check_fault(corner, options)
            except InjectorConfigError as exc:
                out.add((*fault.path, 'config'), str(exc))
                return


def _candidate_config(fault: ExploreFault, injector_type: str, cls: Any, out: _Collector) -> list[dict[str, Any]]:
    """The candidate's fixed config keys, each one its type has, read into the two corners of the space: the
    config with every dimension at its low end, and at its high end (the dimensions are added after)."""
    keys = [f.name for f in cls.fields]
    corners: list[dict[str, Any]] = [{}, {}]
    for key, value in fault.config.items():
        field = cls.field(str(key))
        if field is None:
            out.add((*fault.path, 'config', key), f'injector type {injector_type!r} has no config key {key!r}'
                                                  f'{key_hint(str(key), keys)}')
            continue
        for corner in corners:
            corner[key] = coerce(field, value, (*fault.path, 'config', key), out)
    return corners


def _check_config_dimension(fault: ExploreFault, injector_type: str, cls: Any, dimension: Any,
                            corners: list[dict[str, Any]], out: _Collector) -> None:
    """A dimension over a config key: a numeric key of the type, each end within its range (put in `corners`)."""
    key = dimension.name.removeprefix('config.')
    path = (*fault.path, 'config', key)
    field = cls.field(key)
    if field is None:
        out.add(path, f'a dimension on {key!r}, a key injector type {injector_type!r} lacks'
                      f'{key_hint(key, [f.name for f in cls.fields])}')
        return
    if field.type not in ('number', 'integer', 'special_float'):
        out.add(path, f'{key!r} is a {field.type}: only a number can be a dimension')
        return
    for corner, end, which in ((corners[0], dimension.low, 'low'), (corners[1], dimension.high, 'high')):
        try:
            corner[key] = field.coerce(round(end) if field.type == 'integer' else end)
        except FieldValueError as exc:
            out.add(path, f'the {which} end {end:g}: {exc}')
        if field.type == 'integer' and end != round(end):
            out.add(path, f'the {which} end {end:g} is not whole, and {key!r} takes whole numbers')
