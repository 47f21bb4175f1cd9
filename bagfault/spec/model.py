"""Scenario records: injectors, faults with their schedules, assertions."""

from __future__ import annotations

from dataclasses import FrozenInstanceError, dataclass, field
from pathlib import Path
from typing import Any

from bagfault.spec.system import SystemUnderTest
from bagfault.spec.yamlnodes import LocatedYaml, PathKey


class Sealed:
    """A record the loader fills in field by field and then seals: assigning to a field of a sealed record
    raises, so a loaded scenario is never edited (what changes while running lives in the engine's FaultState,
    which makes new records)."""

    def __setattr__(self, name: str, value: object) -> None:
        if self.__dict__.get('_sealed') and not name.startswith('_'):
            raise FrozenInstanceError(f'cannot assign to {type(self).__name__}.{name}: a loaded scenario is '
                                      'never edited (run-time changes go through engine.FaultState)')
        object.__setattr__(self, name, value)

    def seal(self) -> None:
        """From now on, read only."""
        object.__setattr__(self, '_sealed', True)


@dataclass
class InjectorSpec(Sealed):
    """One injector: where it reads, where it writes, which type mutates.

    Topic injectors have input_topic/output_topic; service injectors have
    proxy_service/target_service. `options` holds type-specific injector
    keys (for example `message_type` of generic injectors).
    """

    id: str
    type: str
    input_topic: str | None = None
    output_topic: str | None = None
    qos_depth: int = 10
    proxy_service: str | None = None
    target_service: str | None = None
    seed: int | None = None
    options: dict[str, Any] = field(default_factory=dict)
    path: PathKey = ()

    @property
    def is_service(self) -> bool:
        """True for injectors that proxy a service instead of a topic."""
        return self.proxy_service is not None or self.target_service is not None


@dataclass
class Repeat(Sealed):
    """Intermittent schedule: on for `on` seconds at the start of every `period`."""

    period: float
    on: float


@dataclass
class After(Sealed):
    """Chained schedule: activate `delay` seconds after fault `fault` activates."""

    fault: str
    delay: float


@dataclass
class FaultSpec(Sealed):
    """A named fault owned by one injector, with its config and schedule.

    Times are seconds from bag time zero. A fault with neither
    `active_on_startup` nor `start` (nor an extended schedule) is manual-only.
    """

    id: str
    injector_id: str
    config: dict[str, Any] = field(default_factory=dict)
    config_text: dict[str, str] = field(default_factory=dict)
    active_on_startup: bool = False
    start: float | None = None
    duration: float | None = None
    repeat: Repeat | None = None
    probability_per_second: float | None = None
    hold: float | None = None
    after: After | None = None
    report: Any = None
    path: PathKey = ()

    @property
    def manual_only(self) -> bool:
        """True when nothing in the scenario ever activates the fault."""
        return not (
            self.active_on_startup
            or self.start is not None
            or self.repeat is not None
            or self.probability_per_second is not None
            or self.after is not None
        )

    def describe_config(self) -> str:
        """The anchor's `config={k=v, ...}` text, keys sorted, values as written."""
        items = sorted(self.config_text.items())
        return 'config={' + ', '.join(f'{k}={v}' for k, v in items) + '}'

    def describe_fault(self) -> str:
        """The anchor's describe_fault (utils/fault_descriptions.cpp), the details of a switch asked from outside
        and of GetFaultStatus: 'scheduled, start=5000ms, duration=10000ms, config={...}' or 'manual-only, ...'
        (whole milliseconds, truncated as its static_cast<int64_t>(seconds * 1000.0))."""
        parts = ['scheduled', f'start={int(self.start * 1000.0)}ms'] if self.start is not None else ['manual-only']
        if self.duration is not None:
            parts.append(f'duration={int(self.duration * 1000.0)}ms')
        return ', '.join([*parts, self.describe_config()])


def describe_config_update(key: str, value: str) -> str:
    """The anchor's details of a SetFaultConfig event: 'config_update={key=value}'."""
    return f'config_update={{{key}={value}}}'


@dataclass
class AssertionSpec(Sealed):
    """An expected outcome; `params` holds the type-specific keys."""

    id: str
    type: str
    within: float | None = None
    duration: float | None = None  # accepted as ros2_fault_injection does (checked, otherwise unused)
    params: dict[str, Any] = field(default_factory=dict)
    path: PathKey = ()


@dataclass(frozen=True)
class Dimension:
    """A number of a candidate fault that `bagfault explore` draws from [low, high]; low is the weakest.

    `name` is `start`, `duration` or `config.<key>`; an `integer` one (an int config key) takes whole values."""

    name: str
    low: float
    high: float
    integer: bool = False

    @property
    def span(self) -> float:
        """high - low."""
        return self.high - self.low


@dataclass
class ExploreFault(Sealed):
    """A candidate fault of an explore space: fixed values and dimensions."""

    id: str
    injector_id: str
    config: dict[str, Any] = field(default_factory=dict)  # the fixed config values, as written
    dimensions: list[Dimension] = field(default_factory=list)
    start: float | None = 0.0  # fixed start (None: a dimension)
    duration: float | None = None  # fixed duration (None: to the end, or a dimension)
    report: Any = None
    path: PathKey = ()

    def dimension(self, name: str) -> Dimension | None:
        """The dimension of this name, if it is one."""
        return next((d for d in self.dimensions if d.name == name), None)


@dataclass
class Explore(Sealed):
    """The `explore:` section: candidate faults and how the search spends its runs."""

    faults: list[ExploreFault]
    max_faults: int
    budget: int
    confirm: int | None  # None: 1 offline, 2 in closed loop
    resolution: float
    batch: int

    @property
    def ids(self) -> set[str]:
        """The candidate faults' ids."""
        return {f.id for f in self.faults}

    def fault(self, fault_id: str) -> ExploreFault | None:
        """The candidate of this id."""
        return next((f for f in self.faults if f.id == fault_id), None)


class _Index:
    """A scenario's injectors and faults by id, for the lists they were made from (as they were then)."""

    def __init__(self, injectors: list[InjectorSpec], faults: list[FaultSpec]) -> None:
        self.lists = (injectors, faults, len(injectors), len(faults))
        self.injectors: dict[str, InjectorSpec] = {}
        self.faults: dict[str, FaultSpec] = {}
        for x in injectors:
            self.injectors.setdefault(x.id, x)
        for f in faults:
            self.faults[f.id] = f  # a fault id defined again: the last definition's config, as the anchor's map

    def matches(self, injectors: list[InjectorSpec], faults: list[FaultSpec]) -> bool:
        """Made from these lists, which have not grown or shrunk since."""
        return (self.lists[0] is injectors and self.lists[1] is faults and self.lists[2] == len(injectors)
                and self.lists[3] == len(faults))


@dataclass
class Scenario(Sealed):
    """A loaded scenario file."""

    injectors: list[InjectorSpec]
    faults: list[FaultSpec]
    assertions: list[AssertionSpec]
    seed: int | None = None
    fault_manager: dict[str, Any] | None = None
    fault_manager_config: Any = None
    warnings: list[str] = field(default_factory=list)
    inert_warnings: int = 0  # of the warnings, those of something that does nothing (a key ignored, a fault skipped)
    skipped_faults: list[str] = field(default_factory=list)  # faults of injectors of a type nothing provides
    msg_paths: list[Path] = field(default_factory=list)  # folders of .msg/.idl definitions (relative to the file)
    system: SystemUnderTest | None = None  # `system_under_test:`, what `bagfault test` starts
    explore: Explore | None = None  # `explore:`, the fault space `bagfault explore` searches
    bags: list[Path] = field(default_factory=list)  # `bags:`, what a scenario file run by pytest plays
    source: Path | None = None
    text: str = ''
    located: LocatedYaml = field(default_factory=lambda: LocatedYaml(None))
    _index: _Index | None = field(default=None, repr=False, compare=False)

    def seal(self) -> None:
        """The scenario and every record in it, read only from now on."""
        records: list[Sealed] = [*self.injectors, *self.faults, *self.assertions]
        records += [x for f in self.faults for x in (f.repeat, f.after) if x is not None]
        if self.explore is not None:
            records += [self.explore, *self.explore.faults]
        for record in records:
            record.seal()
        super().seal()

    def _ids(self) -> _Index:
        """Injectors and faults by id (the first of a repeated id), made again when the lists change."""
        index = self._index
        if index is None or not index.matches(self.injectors, self.faults):
            index = self._index = _Index(self.injectors, self.faults)
        return index

    @property
    def name(self) -> str:
        """File name, or '<scenario>' for one built in memory."""
        return self.source.name if self.source else '<scenario>'

    def injector(self, injector_id: str) -> InjectorSpec | None:
        """Injector with this id (the first, if repeated), if any; a lookup by id, whatever the file's size."""
        return self._ids().injectors.get(injector_id)

    def fault(self, fault_id: str) -> FaultSpec | None:
        """Fault with this id (the last definition, if repeated: the anchor's injector keeps its faults in a map
        by id, so a second definition replaces the first's config), if any; a lookup by id."""
        return self._ids().faults.get(fault_id)

    def faults_of(self, injector_id: str) -> list[FaultSpec]:
        """Faults owned by one injector, in file order, each id once (at its first place, its last definition)."""
        index = self._ids().faults
        seen: set[str] = set()
        out = []
        for x in self.faults:
            if x.injector_id == injector_id and x.id not in seen:
                seen.add(x.id)
                out.append(index.get(x.id, x))
        return out
