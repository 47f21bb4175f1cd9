"""A candidate: the faults one run draws from the space, each with a value per dimension, and the plain scenario
it makes.

The scenario of a candidate is the space's own file with its `explore:`
section removed, the drawn faults appended to `faults:` and what names an
undrawn candidate left out (an assertion with `after`, `during`, `outside`
or `fault_id` naming it, a sequence of such, a fault chained after it): a
file `bagfault run` or `test` takes as it is. Values sit on a grid of a
thousandth of their range (whole numbers for an integer key), so every
value a search or a shrink writes is short and exact in YAML.
"""

from __future__ import annotations

import copy
import hashlib
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import yaml

if TYPE_CHECKING:
    from bagfault.spec.model import Dimension, Explore, ExploreFault

GRID = 1000  # steps of a dimension's range a value sits on
REFERENCES = ('after', 'during', 'outside', 'fault_id')  # assertion keys that name a fault


def quantize(dimension: Dimension, value: float) -> float:
    """`value` clamped to the dimension and put on its grid (a whole number for an integer key)."""
    value = min(max(value, dimension.low), dimension.high)
    if dimension.integer:
        return float(round(value))
    step = dimension.span / GRID
    on = dimension.low + round((value - dimension.low) / step) * step
    digits = max(0, 3 - math.floor(math.log10(step))) if step > 0 else 6
    return float(min(max(round(on, digits), dimension.low), dimension.high))


@dataclass(frozen=True)
class Drawn:
    """One candidate fault in a run: its id and the value of each of its dimensions, in the space's order."""

    fault: str
    values: tuple[tuple[str, float], ...]  # sorted by name: config.* first, then duration, then start

    def __post_init__(self) -> None:
        object.__setattr__(self, 'values', tuple(sorted(self.values)))  # one order, however it was made

    def value(self, name: str) -> float:
        """The value of one dimension."""
        return next(v for n, v in self.values if n == name)

    def replaced(self, name: str, value: float) -> Drawn:
        """The same fault with one dimension moved."""
        return Drawn(self.fault, tuple((n, value if n == name else v) for n, v in self.values))

    def describe(self) -> str:
        """'yaw_bias(angular_velocity_z_bias=0.3, duration=1.52, start=8)'."""
        inner = ', '.join(f'{n.removeprefix("config.")}={v:g}' for n, v in self.values)
        return f'{self.fault}({inner})'


@dataclass(frozen=True)
class Candidate:
    """The faults of one run, in the order of the space's candidates (none: the baseline run)."""

    faults: tuple[Drawn, ...]

    @property
    def ids(self) -> tuple[str, ...]:
        """The drawn faults' ids."""
        return tuple(d.fault for d in self.faults)

    def drawn(self, fault_id: str) -> Drawn:
        """One drawn fault."""
        return next(d for d in self.faults if d.fault == fault_id)

    def without(self, fault_id: str) -> Candidate:
        """The candidate less one fault."""
        return Candidate(tuple(d for d in self.faults if d.fault != fault_id))

    def replaced(self, drawn: Drawn) -> Candidate:
        """The candidate with one fault's values replaced."""
        return Candidate(tuple(drawn if d.fault == drawn.fault else d for d in self.faults))

    def describe(self) -> str:
        """Its faults and values, or 'no fault'."""
        return ' + '.join(d.describe() for d in self.faults) or 'no fault'

    def to_json(self) -> list[dict[str, Any]]:
        """[{fault, values: {name: value}}] in order."""
        return [{'fault': d.fault, 'values': dict(d.values)} for d in self.faults]

    @classmethod
    def from_json(cls, data: list[dict[str, Any]]) -> Candidate:
        """The candidate `to_json` wrote."""
        return cls(tuple(Drawn(str(d['fault']), tuple((str(n), float(v)) for n, v in d['values'].items()))
                         for d in data))


def ordered(space: Explore, drawn: list[Drawn]) -> Candidate:
    """A candidate of these faults, in the space's order."""
    order = {f.id: n for n, f in enumerate(space.faults)}
    return Candidate(tuple(sorted(drawn, key=lambda d: order[d.fault])))


def fault_entry(fault: ExploreFault, drawn: Drawn) -> dict[str, Any]:
    """The `faults:` entry of one drawn candidate: its fixed values and its drawn ones."""
    values = dict(drawn.values)
    config = dict(fault.config)
    for dimension in fault.dimensions:
        if dimension.name.startswith('config.'):
            value = values[dimension.name]
            config[dimension.name.removeprefix('config.')] = int(value) if dimension.integer else value
    entry: dict[str, Any] = {'id': fault.id, 'injector_id': fault.injector_id}
    start = values.get('start', fault.start)
    entry['start'] = 0.0 if start is None else start
    duration = values.get('duration', fault.duration)
    if duration is not None:
        entry['duration'] = duration
    if config:
        entry['config'] = config
    if fault.report is not None:
        entry['report'] = copy.deepcopy(fault.report)
    return entry


def scenario_data(base: dict[str, Any], space: Explore, candidate: Candidate) -> dict[str, Any]:
    """The plain scenario of a candidate (see the module's docstring); `base` the space file's data."""
    data = {k: copy.deepcopy(v) for k, v in base.items() if k != 'explore'}
    undrawn = space.ids - set(candidate.ids)
    faults, gone = _kept_faults(data.get('faults') or [], undrawn)
    by_id = {f.id: f for f in space.faults}
    data['faults'] = faults + [fault_entry(by_id[d.fault], d) for d in candidate.faults]
    if isinstance(data.get('assertions'), list):
        data['assertions'] = kept_assertions(data['assertions'], gone)
    return data


def _kept_faults(faults: list[Any], undrawn: set[str]) -> tuple[list[dict[str, Any]], set[str]]:
    """The space file's faults that still start without the undrawn candidates, and the ids of those left out."""
    entries = [f for f in faults if isinstance(f, dict)]
    gone = _with_chained(entries, undrawn)
    return [f for f in entries if str(f.get('id')) not in gone], gone


def _with_chained(faults: list[dict[str, Any]], undrawn: set[str]) -> set[str]:
    """The undrawn candidates and the faults chained after them (or after such a fault): none of them starts."""
    gone = set(undrawn)
    while True:
        chained = {str(f.get('id')) for f in faults
                   if isinstance(f.get('after'), dict) and str(f['after'].get('fault')) in gone} - gone
        if not chained:
            return gone
        gone |= chained


def kept_assertions(assertions: list[Any], gone: set[str]) -> list[Any]:
    """The assertions that name none of the faults `gone`, nor (as a sequence) a step left out."""
    dropped = {str(a.get('id')) for a in assertions if _names_any(a, gone)}
    while True:
        more = {str(a.get('id')) for a in assertions if _has_step_in(a, dropped)} - dropped
        if not more:
            break
        dropped |= more
    return [a for a in assertions if not (isinstance(a, dict) and str(a.get('id')) in dropped)]


def _names_any(assertion: object, faults: set[str]) -> bool:
    """True for an assertion that refers to one of the faults (after, during, ...)."""
    return isinstance(assertion, dict) and any(str(assertion.get(key)) in faults for key in REFERENCES
                                               if key in assertion)


def _has_step_in(assertion: object, assertions: set[str]) -> bool:
    """True for a sequence assertion one of whose steps is one of the assertions."""
    return isinstance(assertion, dict) and isinstance(assertion.get('steps'), list) and any(
        str(step) in assertions for step in assertion['steps'])


def dump(data: dict[str, Any], header: str = '') -> str:
    """YAML text of a scenario (keys in their order), after a comment header."""
    text = yaml.safe_dump(data, sort_keys=False, allow_unicode=True, width=120)
    lines = ''.join(f'# {line}\n' if line else '#\n' for line in header.splitlines())
    return lines + text


def digest(text: str) -> str:
    """sha256 of a scenario text (as the output's provenance records it)."""
    return hashlib.sha256(text.encode()).hexdigest()


def relocated(data: dict[str, Any], source: Path, target: Path) -> dict[str, Any]:
    """Scenario data whose paths, relative to `source`'s folder, are made relative to `target`'s: the bags,
    msg_paths, the system's cwd and path_latency's architecture files (absolute ones stay)."""
    out = copy.deepcopy(data)
    origin, there = source.resolve().parent, target.resolve().parent
    for key in ('bags', 'msg_paths'):
        if isinstance(out.get(key), list):
            out[key] = [_moved(p, origin, there) for p in out[key]]
    system = out.get('system_under_test')
    if isinstance(system, dict) and 'cwd' in system:
        system['cwd'] = _moved(system['cwd'], origin, there)
    for assertion in out.get('assertions') or []:
        if _has_architecture(assertion):
            assertion['architecture'] = _moved(assertion['architecture'], origin, there)
    return out


def _has_architecture(assertion: object) -> bool:
    """True for a path_latency assertion that names its architecture file."""
    return isinstance(assertion, dict) and assertion.get('type') == 'path_latency' and 'architecture' in assertion


def _moved(path: Any, origin: Path, there: Path) -> Any:
    """A path relative to `origin` made relative to `there` (an absolute one, or no path, as it is)."""
    if not isinstance(path, str) or not path or Path(path).is_absolute():
        return path
    return os.path.relpath(origin / path, there)
