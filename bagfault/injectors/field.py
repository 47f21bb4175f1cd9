"""Generic field injector (`field`): operations on field paths of any message type.

    config:
      operations:
        - {op: add, path: pose.pose.position.x, value: 1.0}
        - {op: noise, path: 'ranges[*]', stddev: 0.05}
        - {op: drift, path: linear_acceleration.z, rate: 0.01}   # per second since the fault started

Paths are checked against the bag's own definition of the topic type
(custom types included) before the run starts.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from bagfault.errors import FieldPathError, InjectorConfigError
from bagfault.faults.fieldpath import FLOATS, FieldPath
from bagfault.injectors.base import Injector
from bagfault.schema import DELAY_MS, DROP_PROBABILITY, Key
from bagfault.units import NS

if TYPE_CHECKING:
    from collections.abc import Sequence

    from bagfault.faults.active import ActiveFault
    from bagfault.spec.model import FaultSpec


# operation -> (required parameters, optional parameters)
OPERATIONS: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    'add': (('value',), ()),
    'scale': (('value',), ()),
    'set': (('value',), ()),
    'noise': (('stddev',), ()),
    'uniform_noise': (('low', 'high'), ()),
    'clamp': ((), ('min', 'max')),
    'nan': ((), ()),
    'stuck': ((), ()),
    'drift': (('rate',), ()),
}


def _number(op: dict[str, Any], key: str, where: str) -> float:
    value = op[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InjectorConfigError(f'{where}: {key} {value!r} is not a number')
    return float(value)


def parse_operations(operations: object) -> list[dict[str, Any]]:
    """Check the structure of an operations list; return it with parsed paths."""
    if not isinstance(operations, list) or not operations:
        raise InjectorConfigError('operations must be a non-empty list of {op, path, ...}')
    out = []
    for number, op in enumerate(operations):
        where = f'operations[{number}]'
        if not isinstance(op, dict) or 'op' not in op or 'path' not in op:
            raise InjectorConfigError(f'{where}: give op and path')
        name = op['op']
        if name not in OPERATIONS:
            raise InjectorConfigError(f'{where}: unknown op {name!r} (ops: {", ".join(OPERATIONS)})')
        required, optional = OPERATIONS[name]
        extra = set(op) - {'op', 'path', *required, *optional}
        if extra:
            raise InjectorConfigError(f'{where}: {name} takes {", ".join(required + optional) or "no parameter"}, '
                                      f'not {", ".join(sorted(extra))}')
        for key in required:
            if key not in op:
                raise InjectorConfigError(f'{where}: {name} needs {key}')
        values = {key: _number(op, key, where) for key in (*required, *optional) if key in op}
        if name == 'clamp' and not values:
            raise InjectorConfigError(f'{where}: clamp needs min and/or max')
        if name == 'noise' and values['stddev'] < 0:
            raise InjectorConfigError(f'{where}: stddev must be 0 or more')
        if name == 'uniform_noise' and values['low'] > values['high']:
            raise InjectorConfigError(f'{where}: low is above high')
        try:
            path = FieldPath.parse(op['path'])
        except FieldPathError as exc:
            raise InjectorConfigError(f'{where}: {exc}') from None
        out.append({'op': name, 'path': path, **values})
    return out


class FieldInjector(Injector):
    """add, scale, set, noise, uniform_noise, clamp, nan, stuck, drift on field paths."""

    type_name = 'field'
    description = 'Any message type: operations on field paths (add, scale, set, noise, clamp, drift, ...).'
    message_types = ()
    fields: ClassVar[tuple[Key, ...]] = (
        DROP_PROBABILITY,
        DELAY_MS,
        Key('operations', 'list',
                    'List of {op, path, ...}: add/scale/set (value), noise (stddev), uniform_noise (low, high), '
                    'clamp (min, max), nan, stuck, drift (rate per second); units of the field.'),
    )

    @classmethod
    def check_fault(cls, config: dict[str, Any], options: dict[str, Any]) -> None:
        """Operation structure; paths too when message_type is a standard type."""
        if 'operations' not in config:
            return
        operations = parse_operations(config['operations'])
        msgtype = options.get('message_type')
        if msgtype:
            from bagfault.io.types import TypeCatalog  # noqa: PLC0415

            codec = TypeCatalog([], None).codec(msgtype)
            if codec is not None:
                problems = _check_paths(operations, msgtype, codec.store)
                if problems:
                    raise InjectorConfigError('; '.join(problems))

    @classmethod
    def check_type(cls, msgtype: str, store: Any, faults: Sequence[FaultSpec]) -> list[str]:
        """Every path exists in the bag's definition and fits its operation."""
        problems = []
        for fault in faults:
            if 'operations' in fault.config:
                problems += [f'fault {fault.id!r}: {p}' for p in
                             _check_paths(parse_operations(fault.config['operations']), msgtype, store)]
        return problems

    def __init__(self, spec: Any, codec: Any = None, faults: Sequence[FaultSpec] = ()) -> None:
        super().__init__(spec, codec, faults)
        self.plans: dict[str, list[dict[str, Any]]] = {}
        for fault in faults:
            if 'operations' in fault.config and codec is not None:
                operations = parse_operations(fault.config['operations'])
                for op in operations:
                    op['path'] = op['path'].resolve(codec.msgtype, codec.store)
                self.plans[fault.id] = operations
        self._stuck: dict[tuple[str, int, int], Any] = {}

    @classmethod
    def plot_fields(cls, key: str, config: dict[str, Any]) -> list[str]:
        """The paths of the fault's operations."""
        if key != 'operations' or not isinstance(config.get(key), list):
            return []
        return list(dict.fromkeys(op['path'] for op in config[key] if isinstance(op, dict) and 'path' in op))

    def mutate(self, message: Any, time: int, active: Sequence[ActiveFault]) -> None:
        """Each active fault's operations, in scenario and list order."""
        for fault in active:
            for number, op in enumerate(self.plans.get(fault.id, ())):
                op['path'].update(message, _operation(op, fault, number, time, self._stuck))


def _check_paths(operations: list[dict[str, Any]], msgtype: str, store: Any) -> list[str]:
    problems = []
    for number, op in enumerate(operations):
        try:
            path = op['path'].resolve(msgtype, store)
        except FieldPathError as exc:
            problems.append(f'operations[{number}]: {exc}')
            continue
        if not path.numeric:
            problems.append(f'operations[{number}]: {op["op"]} needs a number, {path.text} is a {path.leaf}')
        elif op['op'] == 'nan' and path.leaf not in FLOATS:
            problems.append(f'operations[{number}]: nan needs a float field, {path.text} is a {path.leaf}')
    return problems


LEAF_DTYPES = {
    'bool': np.bool_, 'byte': np.uint8, 'char': np.uint8, 'octet': np.uint8, 'int8': np.int8, 'uint8': np.uint8,
    'int16': np.int16, 'uint16': np.uint16, 'int32': np.int32, 'uint32': np.uint32, 'int64': np.int64,
    'uint64': np.uint64, 'float32': np.float32, 'float64': np.float64,
}


def _operation(op: dict[str, Any], fault: ActiveFault, number: int, time: int, stuck: dict[Any, Any]) -> Any:
    """The value transform of one operation, bound to its fault's random stream."""
    name = op['op']
    stream_name = f'operations[{number}]'
    leaf = np.dtype(LEAF_DTYPES.get(op['path'].leaf, np.float64))

    def apply(value: Any) -> Any:
        array = np.asarray(value)
        if leaf.kind in 'iu' and leaf.itemsize == 8 and name in EXACT:
            return _exact_int(value, array, op, leaf)
        data = array.astype(np.float64)
        if name == 'add':
            data = data + op['value']
        elif name == 'scale':
            data = data * op['value']
        elif name == 'set':
            data = np.full_like(data, op['value'])
        elif name == 'noise':
            data = data + fault.random.stream(stream_name).standard_normal(data.shape) * op['stddev']
        elif name == 'uniform_noise':
            data = data + fault.random.stream(stream_name).uniform(op['low'], op['high'], data.shape)
        elif name == 'clamp':
            data = np.clip(data, op.get('min', -np.inf), op.get('max', np.inf))
        elif name == 'nan':
            data = np.full_like(data, np.nan)
        elif name == 'drift':
            data = data + op['rate'] * (time - fault.since) / NS
        elif name == 'stuck':
            key = (fault.id, fault.since, number)
            held = stuck.setdefault(key, data.copy())
            if held.shape == data.shape:
                data = held.copy()
        return _restore(value, leaf, data)

    return apply


EXACT = {'add', 'set', 'clamp'}


def _exact_int(original: Any, array: np.ndarray, op: dict[str, Any], leaf: np.dtype) -> Any:
    """add/set/clamp on 64-bit integers in Python integers (float64 would lose the low digits)."""
    info = np.iinfo(leaf)

    def one(v: int) -> int:
        if op['op'] == 'add':
            v = v + int(op['value']) if float(op['value']).is_integer() else round(v + op['value'])
        elif op['op'] == 'set':
            v = round(op['value'])
        else:
            if 'min' in op:
                v = max(v, math.ceil(op['min']))
            if 'max' in op:
                v = min(v, math.floor(op['max']))
        return max(int(info.min), min(int(info.max), v))

    values = [one(int(v)) for v in array.ravel().tolist()]
    if isinstance(original, np.ndarray):
        return np.array(values, dtype=original.dtype).reshape(original.shape)
    return values[0]


def _restore(original: Any, leaf: np.dtype, data: np.ndarray) -> Any:
    """Back to the field's container and type: integers rounded and saturated, not wrapped."""
    if np.issubdtype(leaf, np.integer):
        info = np.iinfo(leaf)
        data = np.clip(np.rint(np.nan_to_num(data)), info.min, info.max)
    elif leaf == np.bool_:
        data = data != 0
    with np.errstate(invalid='ignore', over='ignore'):
        converted = data.astype(leaf)
    if isinstance(original, np.ndarray):
        return converted.astype(original.dtype, copy=False)
    item = converted.item()
    return type(original)(item) if isinstance(original, (bool, int, float)) else item
