"""Read a scenario file in any of the anchor's layouts into the model.

Layouts of ros2_fault_injection, all accepted unchanged:
- `injectors:` list whose entries nest endpoints under `topic:`;
- `injectors:` list with flat `input_topic`/`output_topic` keys;
- a single `injector:` mapping.
Structural problems are collected, not raised one by one; `validate`
then checks values against the injector and assertion schemas.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from bagfault.errors import Problem, ScenarioError, one_line
from bagfault.io.regular import read_text
from bagfault.spec import sections
from bagfault.spec.model import AssertionSpec, Dimension, Explore, ExploreFault, FaultSpec, InjectorSpec, Scenario
from bagfault.spec.reader import Read, Reader
from bagfault.spec.system import parse_system
from bagfault.spec.yamlnodes import LocatedYaml, PathKey, YamlSyntaxError, format_path, load_located

if TYPE_CHECKING:
    from bagfault.injectors.base import InjectorType
    from bagfault.schema import Key

ENDPOINT_KEYS = {k.name for k in sections.TOPIC.keys}
SERVICE_KEYS = {k.name for k in sections.TRIGGER_SERVICE.keys}


class _Collector:
    """Accumulates problems (errors) and warnings with their YAML positions."""

    def __init__(self, file: str, located: LocatedYaml) -> None:
        self.file = file
        self.located = located
        self.problems: list[Problem] = []
        self.warnings: list[Problem] = [Problem(file, where, format_path(path), message)
                                        for where, path, message in located.warnings]
        self.inert: set[Problem] = set()  # the warnings of things that do nothing

    def add(self, path: PathKey, message: str) -> None:
        """An error: the scenario cannot be used."""
        self.problems.append(Problem(self.file, self.located.where(path), format_path(path), message))

    def warn(self, path: PathKey, message: str) -> None:
        """Something ros2_fault_injection accepts (and ignores or reads its own way); an error with --strict."""
        self.warnings.append(Problem(self.file, self.located.where(path), format_path(path), message))

    def ignored(self, path: PathKey, message: str) -> None:
        """A warning about something that does nothing (a key ignored, a fault skipped): `run` and `test` count
        these at the end of their summary."""
        self.warn(path, message)
        self.inert.add(self.warnings[-1])

    def reader(self) -> Reader:
        """The section reader reporting here, with the scalars as the file writes them (the only warning it
        gives is an unknown key, which is ignored)."""
        return Reader(self.add, self.ignored, self.located.raw_text)


@dataclass(frozen=True)
class ScenarioText:
    """A scenario's text and its YAML, parsed once (under the loader's limits): `build_scenario` makes the model
    of it, and `bagfault run` guesses its leading copy from it before its heavy imports."""

    text: str
    located: LocatedYaml
    source: Path | None = None

    @classmethod
    def parse(cls, text: str, source: Path | None = None) -> ScenarioText:
        """ScenarioError when the YAML cannot be read (a syntax error, a document past the loader's limits)."""
        try:
            return cls(text, load_located(text), source)
        except YamlSyntaxError as exc:
            where, _, message = str(exc).partition(': ')
            raise ScenarioError([Problem(str(source) if source else '<scenario>', where, '<top>', message)]) from None


def read_scenario(path: str | Path) -> ScenarioText:
    """A scenario file read and its YAML parsed; ScenarioError when it cannot be."""
    file = Path(path)
    try:
        text = read_text(file)
    except FileNotFoundError:
        raise ScenarioError([Problem(str(file), '', '', 'scenario file not found')]) from None
    except IsADirectoryError:
        raise ScenarioError([Problem(str(file), '', '', 'is a directory, not a scenario file')]) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ScenarioError([Problem(str(file), '', '', f'cannot read scenario file: {one_line(exc)}')]) from None
    return ScenarioText.parse(text, file)


def load_scenario(path: str | Path, *, validate: bool = True, strict: bool = False) -> Scenario:
    """Load and (by default) validate a scenario file; raise ScenarioError listing all problems.

    With `strict`, warnings (what ros2_fault_injection accepts but ignores) are errors too.
    """
    return build_scenario(read_scenario(path), validate=validate, strict=strict)


def parse_scenario(text: str, *, source: Path | None = None, validate: bool = True,
                   strict: bool = False) -> Scenario:
    """Parse scenario text; raise ScenarioError listing every problem found (and every warning with `strict`)."""
    return build_scenario(ScenarioText.parse(text, source), validate=validate, strict=strict)


def build_scenario(document: ScenarioText, *, validate: bool = True, strict: bool = False) -> Scenario:
    """The model of a parsed scenario, validated unless not `validate`; ScenarioError listing every problem
    (and every warning with `strict`)."""
    from bagfault.scenario.resolve import resolve_scenario  # noqa: PLC0415
    from bagfault.scenario.validator import check_ids, validate_scenario  # noqa: PLC0415

    source, located, text = document.source, document.located, document.text
    name = str(source) if source else '<scenario>'
    out = _Collector(name, located)
    scenario = _build(located, out)
    _beside_file(scenario, located, source, out)
    scenario.source = source
    if source is not None:
        scenario.msg_paths = [source.parent / p for p in scenario.msg_paths]
    scenario.text = text
    scenario.located = located
    if validate:  # ids first (an unknown type's injector counts), then read by type, then checked
        check_ids(scenario, out)
        resolve_scenario(scenario, out)
        validate_scenario(scenario, out)
    _conclude(scenario, out, strict)
    return scenario


def _beside_file(scenario: Scenario, located: LocatedYaml, source: Path | None, out: _Collector) -> None:
    """The parts whose paths are relative to the scenario's folder: the system under test and the bags."""
    base = source.parent if source is not None else None
    root = located.data if isinstance(located.data, dict) else {}
    if isinstance(root.get('system_under_test'), dict):  # (not a mapping: told by the top-level read)
        scenario.system = parse_system(root['system_under_test'], ('system_under_test',), out.add, base)
    bags = root.get('bags')
    if isinstance(bags, list):
        scenario.bags = [base / b if base is not None else Path(b) for b in _texts(bags, 'bags', out)]


def _conclude(scenario: Scenario, out: _Collector, strict: bool) -> None:
    """The warnings into the scenario, sealed; ScenarioError listing every problem (warnings too with `strict`)."""
    warnings = sorted(out.warnings, key=_position)
    scenario.warnings = [str(w) for w in warnings]
    scenario.inert_warnings = sum(w in out.inert for w in warnings)
    problems = out.problems + ([Problem(w.file, w.where, w.path, f'{w.message} (a warning, an error with --strict)')
                                for w in warnings] if strict else [])
    if problems:
        raise ScenarioError(sorted(problems, key=_position), [] if strict else warnings)
    scenario.seal()


def _position(problem: Any) -> tuple[int, int]:
    line, _, col = problem.where.partition(':')
    return int(line), int(col or 0)


def _build(located: LocatedYaml, out: _Collector) -> Scenario:
    scenario = Scenario([], [], [])
    if not isinstance(located.data, dict):
        out.add((), 'a scenario must be a YAML mapping with injectors and faults')
        return scenario
    reader = out.reader()
    top = reader.read(sections.SCENARIO, located.data, ())
    assert top is not None
    scenario.injectors = _injectors(top, out)
    scenario.faults = [f for i, n in enumerate(top.get('faults', [])) if (f := _fault(n, ('faults', i), out))]
    scenario.assertions = [a for i, n in enumerate(top.get('assertions', []))
                           if (a := _assertion(n, ('assertions', i), out))]
    _optional_parts(scenario, top, out)
    return scenario


def _optional_parts(scenario: Scenario, top: Read, out: _Collector) -> None:
    """The seed, message definitions, fault manager section and fault space, where given."""
    if 'seed' in top.given and 'seed' in top:  # (absent: None, so --seed or 0 decides later)
        scenario.seed = top.get('seed')
    if 'msg_paths' in top:
        scenario.msg_paths = [Path(p) for p in _texts(top.get('msg_paths'), 'msg_paths', out)]
    if 'fault_manager' in top.given:
        scenario.fault_manager = top.get('fault_manager', {})
    if 'explore' in top:
        scenario.explore = _explore(top.get('explore'), ('explore',), scenario, out)


def _injectors(top: Read, out: _Collector) -> list[InjectorSpec]:
    """The injectors of the `injectors:` list, or the one `injector:` (the list wins, as in the anchor)."""
    if 'injectors' in top.given and 'injector' in top.given:
        out.warn(('injector',), "both 'injector' and 'injectors' are given; 'injectors' is used, as "
                                'ros2_fault_injection does')
    if 'injectors' in top.given:
        return [x for i, n in enumerate(top.get('injectors', [])) if (x := _injector(n, ('injectors', i), out))]
    if 'injector' not in top.given:
        out.add((), "scenario has no 'injector' or 'injectors' block")
        return []
    injector = _injector(top.get('injector'), ('injector',), out) if 'injector' in top else None
    return [injector] if injector else []


def _texts(items: list[Any], key: str, out: _Collector) -> list[str]:
    """A top-level list of non-empty texts (paths); [] and a problem when one is not."""
    if all(isinstance(p, str) and p for p in items):
        return items
    out.add((key,), f'must be {sections.SCENARIO.key(key).what}')  # type: ignore[union-attr]
    return []


def _explore(node: dict[str, Any], path: PathKey, scenario: Scenario, out: _Collector) -> Explore | None:
    """The fault space: its candidates with their dimensions (their values are checked by the validator)."""
    read = out.reader().read(sections.EXPLORE, node, path)
    if read is None:
        return None
    faults = [f for i, n in enumerate(read.get('faults', []))
              if (f := _explore_fault(n, (*path, 'faults', i), scenario, out))]
    return Explore(faults, read.get('max_faults', min(3, len(faults)) or 1), read.get('budget'), read.get('confirm'),
                   read.get('resolution'), read.get('batch'))


def _explore_fault(node: object, path: PathKey, scenario: Scenario, out: _Collector) -> ExploreFault | None:
    from bagfault.injectors.registry import get_injector_type  # noqa: PLC0415

    if not isinstance(node, dict):
        out.add(path, 'a candidate fault must be a mapping')
        return None
    read = out.reader().read(sections.EXPLORE_FAULT, node, path)
    assert read is not None
    fault = ExploreFault(read.get('id', ''), read.get('injector_id', ''), report=read.get('report'), path=path)
    for name in ('start', 'duration'):
        value = read.get(name)
        if isinstance(value, tuple):
            fault.dimensions.append(Dimension(name, *value))
            value = None
        setattr(fault, name, value)
    injector = scenario.injector(fault.injector_id)
    cls = get_injector_type(injector.type) if injector is not None else None
    for key, value in read.get('config', {}).items():
        _config_value(fault, str(key), value, cls.field(str(key)) if cls is not None else None, path, out)
    return fault


def _config_value(fault: ExploreFault, key: str, value: object, field: Key | None, path: PathKey,
                  out: _Collector) -> None:
    """A candidate's config key: a [low, high] list is a dimension of the space (an integer one for an integer
    key), anything else a fixed value (as is a list-typed key's list: a field's operations)."""
    if not isinstance(value, list) or (field is not None and field.type == 'list'):
        fault.config[key] = value
        return
    declared = sections.Key(key, 'dimension', '', minimum=None, maximum=None)
    ok, ends = out.reader().dimension(declared, value, (*path, 'config', key))
    if ok:
        fault.dimensions.append(Dimension(f'config.{key}', ends[0], ends[1],
                                          integer=field is not None and field.type == 'integer'))


def _injector(node: object, path: PathKey, out: _Collector) -> InjectorSpec | None:
    if not isinstance(node, dict):
        out.add(path, 'an injector must be a mapping')
        return None
    cls = _named_type(node)
    option_keys = {f.name for f in cls.options} if cls else set()
    read = out.reader().read(sections.INJECTOR, node, path, extra=option_keys,
                             judge_unknown=cls is not None or not node.get('type'))
    assert read is not None
    spec = InjectorSpec(id=read.get('id', ''), type=read.get('type', ''), path=path)
    spec.options = {key: node[key] for key in node if key in option_keys}
    if 'seed' in read:
        spec.seed = read.get('seed')
    _endpoints(spec, cls, read, node, path, out)
    return spec


def _endpoints(spec: InjectorSpec, cls: InjectorType | None, read: Read, node: dict[str, Any], path: PathKey,
               out: _Collector) -> None:
    """What the injector acts on, into `spec`: two services, the running system (nothing to read), or topics."""
    from bagfault.injectors.system import SystemInjector  # noqa: PLC0415

    if _service_endpoints(spec, read, node, path, out):
        return
    if cls is not None and issubclass(cls, SystemInjector):  # acts on the system: no topic, no service
        for key in sorted(ENDPOINT_KEYS & read.given):
            out.add((*path, key), f'injector type {spec.type!r} acts on the running system; it takes no {key}')
        return
    _topic_endpoints(spec, read, path, out)


def _named_type(node: dict[str, Any]) -> InjectorType | None:
    """The injector type a mapping names (None without a type, or for one not known)."""
    from bagfault.injectors.registry import get_injector_type  # noqa: PLC0415

    type_name = node.get('type')
    return get_injector_type(type_name) if isinstance(type_name, str) and type_name else None


def _service_endpoints(spec: InjectorSpec, read: Read, node: dict[str, Any], path: PathKey,
                       out: _Collector) -> bool:
    """A service injector's two services (under `trigger_service:`, or flat), into `spec`; False for another
    kind of injector."""
    if 'trigger_service' in read.given:
        service = out.reader().read(sections.TRIGGER_SERVICE, read.get('trigger_service'),
                                    (*path, 'trigger_service')) if 'trigger_service' in read else None
        # None: not a mapping, told once (not again as its missing keys or services)
        spec.proxy_service = service.get('proxy_service', '') if service is not None else ''
        spec.target_service = service.get('target_service', '') if service is not None else ''
        return True
    if not (any(k in node for k in SERVICE_KEYS) or spec.type == 'trigger_service'):
        return False
    for key in sorted(SERVICE_KEYS):
        if key not in read.given:
            out.add(path, f'missing required key {key!r}')
    spec.proxy_service = read.get('proxy_service', '')
    spec.target_service = read.get('target_service', '')
    return True


def _topic_endpoints(spec: InjectorSpec, read: Read, path: PathKey, out: _Collector) -> None:
    """A topic injector's input and output topics and depth (under `topic:`, which wins, or flat), into `spec`."""
    endpoint, endpoint_path = read, path
    if 'topic' in read.given and 'topic' not in read:  # not a mapping: told once, not again as its missing keys
        return
    if 'topic' in read.given:
        nested = out.reader().read(sections.TOPIC, read.get('topic'), (*path, 'topic'))
        if nested is None:
            return
        endpoint, endpoint_path = nested, (*path, 'topic')
        for key in sorted(ENDPOINT_KEYS & read.given):
            out.warn((*path, key), f"{key!r} is given here and in 'topic'; the one in 'topic' is used, "
                                   'as ros2_fault_injection does')
    for key in ('input_topic', 'output_topic'):  # a name as written: ROS 1 and test bags have names without '/'
        if key not in endpoint.given:
            out.add(endpoint_path, f'missing required key {key!r}')
    spec.input_topic = endpoint.get('input_topic')
    spec.output_topic = endpoint.get('output_topic')
    spec.qos_depth = endpoint.get('qos_depth', spec.qos_depth)


def _fault(node: object, path: PathKey, out: _Collector) -> FaultSpec | None:
    if not isinstance(node, dict):
        out.add(path, 'a fault must be a mapping')
        return None
    read = out.reader().read(sections.FAULT, node, path)
    assert read is not None
    fault = FaultSpec(id=read.get('id', ''), injector_id=read.get('injector_id', ''), path=path)
    fault.active_on_startup = read.get('active_on_startup', False) or read.get('active', False)
    fault.start = read.get('start')
    fault.duration = read.get('duration')
    if 'config' in read:
        config = read.get('config')
        fault.config = dict(config)
        fault.config_text = {str(k): out.located.raw_text((*path, 'config', k), v) for k, v in config.items()}
    from bagfault.scenario.schedules import parse_extended_schedule  # noqa: PLC0415

    parse_extended_schedule(fault, node, read, path, out)
    if 'report' in read:
        fault.report = read.get('report')
    return fault


def _assertion(node: object, path: PathKey, out: _Collector) -> AssertionSpec | None:
    if not isinstance(node, dict):
        out.add(path, 'an assertion must be a mapping')
        return None
    read = out.reader().read(sections.ASSERTION, node, path)
    assert read is not None
    spec = AssertionSpec(id=read.get('id', ''), type=read.get('type', ''), path=path)
    spec.within = read.get('within')
    spec.duration = read.get('duration')  # parsed and checked by the anchor, used by nothing
    spec.params = {k: v for k, v in node.items() if k not in {'id', 'type', 'within', 'duration'}}
    return spec
