"""Read a scenario file in any of the anchor's layouts into the model.

Layouts of ros2_fault_injection, all accepted unchanged:
- `injectors:` list whose entries nest endpoints under `topic:`;
- `injectors:` list with flat `input_topic`/`output_topic` keys;
- a single `injector:` mapping.
Structural problems are collected, not raised one by one; `validate`
then checks values against the injector and assertion schemas.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from bagfault.errors import Problem, ScenarioError, one_line
from bagfault.spec.model import AssertionSpec, FaultSpec, InjectorSpec, Scenario
from bagfault.spec.system import parse_system
from bagfault.spec.yamlnodes import LocatedYaml, PathKey, YamlSyntaxError, format_path, load_located
from bagfault.yamlcpp import as_bool, as_double, as_int

TOP_KEYS = {'injector', 'injectors', 'faults', 'assertions', 'seed', 'name', 'description', 'fault_manager',
            'msg_paths', 'system_under_test', 'bags'}
INJECTOR_KEYS = {'id', 'type', 'topic', 'input_topic', 'output_topic', 'qos_depth', 'trigger_service',
                 'proxy_service', 'target_service', 'seed'}
ENDPOINT_KEYS = {'input_topic', 'output_topic', 'qos_depth'}
SERVICE_KEYS = {'proxy_service', 'target_service'}
FAULT_KEYS = {'id', 'injector_id', 'active_on_startup', 'active', 'start', 'duration', 'config',
              'repeat', 'probability_per_second', 'hold', 'after', 'report'}
SEED_MAX = 2**64 - 1
MAX_SECONDS = 1e7  # any time in a scenario (about 115 days): far beyond a bag, far below int64 nanoseconds


class _Collector:
    """Accumulates problems (errors) and warnings with their YAML positions."""

    def __init__(self, file: str, located: LocatedYaml) -> None:
        self.file = file
        self.located = located
        self.problems: list[Problem] = []
        self.warnings: list[Problem] = [Problem(file, where, format_path(path), message)
                                        for where, path, message in located.warnings]

    def add(self, path: PathKey, message: str) -> None:
        """An error: the scenario cannot be used."""
        self.problems.append(Problem(self.file, self.located.where(path), format_path(path), message))

    def warn(self, path: PathKey, message: str) -> None:
        """Something ros2_fault_injection accepts (and ignores or reads its own way); an error with --strict."""
        self.warnings.append(Problem(self.file, self.located.where(path), format_path(path), message))


def load_scenario(path: str | Path, *, validate: bool = True, strict: bool = False) -> Scenario:
    """Load and (by default) validate a scenario file; raise ScenarioError listing all problems.

    With `strict`, warnings (what ros2_fault_injection accepts but ignores) are errors too.
    """

    file = Path(path)
    try:
        text = file.read_text(encoding='utf-8')
    except FileNotFoundError:
        raise ScenarioError(f'{file}: scenario file not found') from None
    except IsADirectoryError:
        raise ScenarioError(f'{file}: is a directory, not a scenario file') from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ScenarioError(f'{file}: cannot read scenario file: {one_line(exc)}') from None
    return parse_scenario(text, source=file, validate=validate, strict=strict)


def parse_scenario(text: str, *, source: Path | None = None, validate: bool = True,
                   strict: bool = False) -> Scenario:
    """Parse scenario text; raise ScenarioError listing every problem found (and every warning with `strict`)."""
    from bagfault.scenario.validator import validate_scenario  # noqa: PLC0415

    name = str(source) if source else '<scenario>'
    try:
        located = load_located(text)
    except YamlSyntaxError as exc:
        where, _, message = str(exc).partition(': ')
        raise ScenarioError([Problem(name, where, '<top>', message)]) from None
    out = _Collector(name, located)
    scenario = _build(located, out)
    base = source.parent if source is not None else None
    root = located.data if isinstance(located.data, dict) else {}
    if 'system_under_test' in root:
        scenario.system = parse_system(root['system_under_test'], ('system_under_test',), out.add, base)
    if 'bags' in root:
        bags = root['bags']
        if not isinstance(bags, list) or not all(isinstance(b, str) and b for b in bags):
            out.add(('bags',), 'must be a list of bags (files or rosbag2 folders, relative to this file)')
        else:
            scenario.bags = [base / b if base is not None else Path(b) for b in bags]
    scenario.source = source
    if source is not None:
        scenario.msg_paths = [source.parent / p for p in scenario.msg_paths]
    scenario.text = text
    scenario.located = located
    if validate:
        validate_scenario(scenario, out)
    warnings = sorted(out.warnings, key=_position)
    scenario.warnings = [str(w) for w in warnings]
    problems = out.problems + ([Problem(w.file, w.where, w.path, f'{w.message} (a warning, an error with --strict)')
                                for w in warnings] if strict else [])
    if problems:
        raise ScenarioError(sorted(problems, key=_position))
    scenario.seal()
    return scenario


def _position(problem: Any) -> tuple[int, int]:
    line, _, col = problem.where.partition(':')
    return int(line), int(col or 0)


def _build(located: LocatedYaml, out: _Collector) -> Scenario:
    root = located.data
    scenario = Scenario([], [], [])
    if not isinstance(root, dict):
        out.add((), 'a scenario must be a YAML mapping with injectors and faults')
        return scenario
    for key in root:
        if key not in TOP_KEYS:
            out.warn((key,), f'unknown top-level key {key!r} is ignored (known: {", ".join(sorted(TOP_KEYS))})')

    if 'injectors' in root and 'injector' in root:
        out.warn(('injector',), "both 'injector' and 'injectors' are given; 'injectors' is used, as "
                                'ros2_fault_injection does')
    if 'injectors' in root:
        items = root['injectors']
        if not isinstance(items, list):
            out.add(('injectors',), 'must be a list of injectors')
        else:
            scenario.injectors = [x for i, n in enumerate(items) if (x := _injector(n, ('injectors', i), out))]
    elif 'injector' in root:
        if not isinstance(root['injector'], dict):
            out.add(('injector',), 'must be a mapping')
        elif injector := _injector(root['injector'], ('injector',), out):
            scenario.injectors = [injector]
    else:
        out.add((), "scenario has no 'injector' or 'injectors' block")

    faults = root.get('faults', [])
    if faults is None:
        faults = []
    if not isinstance(faults, list):
        out.add(('faults',), 'must be a list of faults')
    else:
        scenario.faults = [f for i, n in enumerate(faults) if (f := _fault(n, ('faults', i), out, located))]

    assertions = root.get('assertions', [])
    if assertions is None:
        assertions = []
    if not isinstance(assertions, list):
        out.add(('assertions',), 'must be a list of assertions')
    else:
        scenario.assertions = [
            a for i, n in enumerate(assertions) if (a := _assertion(n, ('assertions', i), out))
        ]

    if 'seed' in root:
        scenario.seed = _seed(root['seed'], ('seed',), out)
    if 'msg_paths' in root:
        paths = root['msg_paths']
        if not isinstance(paths, list) or not all(isinstance(p, str) and p for p in paths):
            out.add(('msg_paths',), 'must be a list of folders holding <package>/msg/<Name>.msg or .idl files')
        else:
            scenario.msg_paths = [Path(p) for p in paths]
    if 'fault_manager' in root:
        section = root['fault_manager']
        if section is not None and not isinstance(section, dict):
            out.add(('fault_manager',), 'must be a mapping')
        else:
            scenario.fault_manager = section or {}
    return scenario


def _text(node: dict[str, Any], key: str, path: PathKey, out: _Collector, *, required: bool = True) -> str | None:
    if key not in node or node[key] is None:
        if required:
            out.add(path, f'missing required key {key!r}')
        return None
    value = node[key]
    if isinstance(value, (dict, list)):
        out.add((*path, key), f'{value!r} is not a string')
        return None
    text = value if isinstance(value, str) else out.located.raw_text((*path, key), value)  # as written: `id: on`
    if not text:
        out.add((*path, key), 'must not be empty')
        return None
    return text


def seconds(value: object, path: PathKey, out: _Collector, *, positive: bool = False,
            minimum: float = 0.0) -> float | None:
    """A time in seconds as the anchor reads it (`node.as<double>()`, yamlcpp.as_double of the scalar as written:
    a quoted number counts, `1_000` and `0x10` do not), finite, 0..MAX_SECONDS."""
    number: float | None = None
    if isinstance(value, (int, float, str)) and not isinstance(value, bool):
        number = as_double(out.located.raw_text(path, value))
    if number is None:
        out.add(path, f'{value!r} is not a number of seconds')
        return None
    if not math.isfinite(number) or number > MAX_SECONDS:
        out.add(path, f'{value} is not a time bagfault can schedule (0 to {MAX_SECONDS:g} s)')
        return None
    if number < minimum or (positive and number <= 0):
        if positive:
            out.add(path, f'{value} must be greater than 0' if minimum == 0 else f'{value} is below the minimum '
                                                                                f'{minimum:g} s')
        else:
            out.add(path, f'{value} is negative')
        return None
    return number


def _bool(value: object, path: PathKey, out: _Collector) -> bool:
    """A boolean as the anchor reads it, with yaml-cpp's `as<bool>()` (y/n, yes/no, true/false, on/off, quoted
    or not)."""
    read = as_bool(value)
    if read is None:
        out.add(path, f'{value!r} is not true or false (nor yes/no, y/n, on/off, as yaml-cpp reads booleans)')
        return False
    return read


def _seed(value: object, path: PathKey, out: _Collector) -> int | None:
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= SEED_MAX:
        out.add(path, f'{value!r} is not an integer seed from 0 to {SEED_MAX}')
        return None
    return value


def _injector(node: object, path: PathKey, out: _Collector) -> InjectorSpec | None:
    from bagfault.injectors.registry import get_injector_type  # noqa: PLC0415

    if not isinstance(node, dict):
        out.add(path, 'an injector must be a mapping')
        return None
    injector_id = _text(node, 'id', path, out)
    injector_type = _text(node, 'type', path, out)
    spec = InjectorSpec(id=injector_id or '', type=injector_type or '', path=path)
    cls = get_injector_type(spec.type) if injector_type else None
    option_keys = {f.key for f in cls.options} if cls else set()

    for key in node:
        if key not in INJECTOR_KEYS and key not in option_keys:
            if cls is None and injector_type:
                continue  # unknown type: its keys cannot be judged; the type itself is reported
            known = sorted(INJECTOR_KEYS | option_keys)
            out.warn((*path, key), f'unknown injector key {key!r} is ignored (known: {", ".join(known)})')
        elif key in option_keys:
            spec.options[key] = node[key]

    if 'seed' in node:
        spec.seed = _seed(node['seed'], (*path, 'seed'), out)

    service_node, service_path = node, path
    if 'trigger_service' in node:
        service_node, service_path = node['trigger_service'], (*path, 'trigger_service')
        if not isinstance(service_node, dict):
            out.add(service_path, 'must be a mapping with proxy_service and target_service')
            return spec
    is_service = 'trigger_service' in node or any(k in node for k in SERVICE_KEYS) or spec.type == 'trigger_service'
    if is_service:
        spec.proxy_service = _text(service_node, 'proxy_service', service_path, out) or ''
        spec.target_service = _text(service_node, 'target_service', service_path, out) or ''
        return spec

    endpoint, endpoint_path = node, path
    if 'topic' in node:
        endpoint, endpoint_path = node['topic'], (*path, 'topic')
        if not isinstance(endpoint, dict):
            out.add(endpoint_path, 'must be a mapping with input_topic and output_topic')
            return spec
        for key in endpoint:
            if key not in ENDPOINT_KEYS:
                out.warn((*endpoint_path, key),
                         f'unknown topic key {key!r} is ignored (known: {", ".join(sorted(ENDPOINT_KEYS))})')
        for key in sorted(ENDPOINT_KEYS & set(node)):
            out.warn((*path, key), f"{key!r} is given here and in 'topic'; the one in 'topic' is used, "
                                   'as ros2_fault_injection does')
    spec.input_topic = _topic(endpoint, 'input_topic', endpoint_path, out)
    spec.output_topic = _topic(endpoint, 'output_topic', endpoint_path, out)
    if 'qos_depth' in endpoint:  # the anchor: as<std::size_t>() (a quoted number counts, the base follows 0x/0)
        depth = endpoint['qos_depth']
        read = None if isinstance(depth, (bool, dict, list)) else \
            as_int(out.located.raw_text((*endpoint_path, 'qos_depth'), depth), unsigned=True)
        if read is None or read <= 0:
            out.add((*endpoint_path, 'qos_depth'), f'{depth!r} is not a positive integer')
        else:
            spec.qos_depth = read
    return spec


def _topic(node: dict[str, Any], key: str, path: PathKey, out: _Collector) -> str | None:
    """A topic name as written: a bag may hold names without the leading slash (ROS 1 bags, test bags)."""
    return _text(node, key, path, out)


def _fault(node: object, path: PathKey, out: _Collector, located: LocatedYaml) -> FaultSpec | None:
    if not isinstance(node, dict):
        out.add(path, 'a fault must be a mapping')
        return None
    fault = FaultSpec(id=_text(node, 'id', path, out) or '', injector_id=_text(node, 'injector_id', path, out) or '',
                      path=path)
    for key in node:
        if key not in FAULT_KEYS:
            out.warn((*path, key), f'unknown fault key {key!r} is ignored (known: {", ".join(sorted(FAULT_KEYS))})')
    if 'active_on_startup' in node:
        fault.active_on_startup = _bool(node['active_on_startup'], (*path, 'active_on_startup'), out)
    if 'active' in node:  # deprecated alias kept by the anchor
        fault.active_on_startup = fault.active_on_startup or _bool(node['active'], (*path, 'active'), out)
    for key in ('start', 'duration'):
        if key in node and node[key] is not None:
            setattr(fault, key, seconds(node[key], (*path, key), out))
    config = node.get('config', {})
    if config is None:
        config = {}
    if not isinstance(config, dict):
        out.add((*path, 'config'), 'must be a mapping of config keys')
    else:
        fault.config = dict(config)
        fault.config_text = {str(k): located.raw_text((*path, 'config', k), v) for k, v in config.items()}
    from bagfault.scenario.schedules import parse_extended_schedule  # noqa: PLC0415

    parse_extended_schedule(fault, node, path, out)
    if 'report' in node:
        fault.report = node['report']
    return fault


def _assertion(node: object, path: PathKey, out: _Collector) -> AssertionSpec | None:
    if not isinstance(node, dict):
        out.add(path, 'an assertion must be a mapping')
        return None
    spec = AssertionSpec(id=_text(node, 'id', path, out) or '', type=_text(node, 'type', path, out) or '', path=path)
    if 'within' in node and node['within'] is not None:
        spec.within = seconds(node['within'], (*path, 'within'), out)
    if 'duration' in node and node['duration'] is not None:  # parsed and checked by the anchor, used by nothing
        spec.duration = seconds(node['duration'], (*path, 'duration'), out)
    spec.params = {k: v for k, v in node.items() if k not in {'id', 'type', 'within', 'duration'}}
    return spec
