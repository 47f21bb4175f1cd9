"""An injector instance for a message type and its faults, checked against the type (routing, live, controls)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from bagfault.errors import EngineError
from bagfault.injectors.base import Injector
from bagfault.injectors.registry import get_injector_type

if TYPE_CHECKING:
    from bagfault.io.types import TypeCatalog
    from bagfault.spec.model import FaultSpec, InjectorSpec


def build_injector(spec: InjectorSpec, msgtype: str, faults: list[FaultSpec], catalog: TypeCatalog,
                   scenario_name: str) -> Injector:
    """An injector for messages of `msgtype`, with a codec when its faults need one; EngineError if it cannot work."""
    cls = get_injector_type(spec.type)
    assert cls is not None and issubclass(cls, Injector)
    codec = catalog.codec(msgtype) if msgtype else None
    if codec is None and cls.decodes(faults):
        raise EngineError(f'{scenario_name}: injector {spec.id!r}: cannot decode {msgtype} on {spec.input_topic}: '
                          + catalog.why_not(msgtype))
    if codec is not None:
        problems = cls.check_type(msgtype, codec.store, faults)
        if problems:
            raise EngineError(f'{scenario_name}: injector {spec.id!r} on {spec.input_topic}: ' + '; '.join(problems))
    return cls(spec, codec, faults)
