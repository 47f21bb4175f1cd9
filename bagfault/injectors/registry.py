"""Injector types by name: the built-ins plus entry points of group `bagfault.injectors`.

An external package adds a type by declaring, in its pyproject.toml,

    [project.entry-points."bagfault.injectors"]
    battery_state = "my_package.battery:BatteryStateInjector"

and subclassing `bagfault.injectors.base.Injector`.
"""

from __future__ import annotations

from functools import lru_cache

from bagfault.injectors.base import Injector, InjectorType, ServiceInjector
from bagfault.injectors.field import FieldInjector
from bagfault.injectors.image import ImageInjector
from bagfault.injectors.imu import ImuInjector
from bagfault.injectors.joint_state import JointStateInjector
from bagfault.injectors.link import LinkInjector
from bagfault.injectors.odom import OdomInjector
from bagfault.injectors.pointcloud2 import PointCloud2Injector
from bagfault.injectors.scan import ScanInjector
from bagfault.injectors.system import ClockInjector, ProcessInjector, SystemInjector
from bagfault.injectors.tf import TfInjector
from bagfault.injectors.topic import CompressedImageInjector, TopicInjector
from bagfault.injectors.trigger_service import TriggerServiceInjector
from bagfault.log import log

GROUP = 'bagfault.injectors'

BUILTIN: tuple[InjectorType, ...] = (
    OdomInjector,
    ScanInjector,
    JointStateInjector,
    ImuInjector,
    TfInjector,
    TriggerServiceInjector,
    TopicInjector,
    FieldInjector,
    CompressedImageInjector,
    PointCloud2Injector,
    ImageInjector,
    ProcessInjector,
    ClockInjector,
    LinkInjector,
)

_BUILTIN_TYPES: dict[str, InjectorType] = {cls.type_name: cls for cls in BUILTIN}


@lru_cache(maxsize=1)
def injector_types() -> dict[str, InjectorType]:
    """All known injector types, built-ins first; a plugin cannot replace a built-in."""
    from importlib.metadata import entry_points  # noqa: PLC0415 - 70 ms; scenarios of built-ins never need it

    types: dict[str, InjectorType] = {cls.type_name: cls for cls in BUILTIN}
    for entry in sorted(entry_points(group=GROUP), key=lambda e: e.name):
        if entry.name in types:
            log.warning(f'plugin {entry.value} ignored: type {entry.name!r} is built in')
            continue
        try:
            cls = entry.load()
        except Exception as exc:  # noqa: BLE001 - a broken plugin must not break bagfault
            log.warning(f'plugin {entry.name} = {entry.value} failed to load: {exc}')
            continue
        if not (isinstance(cls, type) and issubclass(cls, (Injector, ServiceInjector, SystemInjector))):
            log.warning(f'plugin {entry.name} = {entry.value} is not an Injector subclass')
            continue
        types[entry.name] = cls
    return types


def get_injector_type(name: str) -> InjectorType | None:
    """Injector class for a type name, or None (plugins are looked for only when no built-in has the name)."""
    return _BUILTIN_TYPES.get(name) or injector_types().get(name)
