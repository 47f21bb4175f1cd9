"""Injector types by name: the built-ins plus entry points of group `bagfault.injectors`.

An external package adds a type by declaring, in its pyproject.toml,

    [project.entry-points."bagfault.injectors"]
    battery_state = "my_package.battery:BatteryStateInjector"

and subclassing `bagfault.injectors.base.Injector`.
"""

from __future__ import annotations

from functools import lru_cache

from bagfault.injectors.base import Injector, InjectorType, ServiceInjector
from bagfault.injectors.system import SystemInjector
from bagfault.log import log
from bagfault.types_by_name import TypesByName

GROUP = 'bagfault.injectors'

BUILTIN: TypesByName[InjectorType] = TypesByName({  # each module imported when a scenario names its type
    'odom': 'bagfault.injectors.odom:OdomInjector',
    'scan': 'bagfault.injectors.scan:ScanInjector',
    'joint_state': 'bagfault.injectors.joint_state:JointStateInjector',
    'imu': 'bagfault.injectors.imu:ImuInjector',
    'tf': 'bagfault.injectors.tf:TfInjector',
    'trigger_service': 'bagfault.injectors.trigger_service:TriggerServiceInjector',
    'topic': 'bagfault.injectors.topic:TopicInjector',
    'field': 'bagfault.injectors.field:FieldInjector',
    'compressed_image': 'bagfault.injectors.topic:CompressedImageInjector',
    'pointcloud2': 'bagfault.injectors.pointcloud2:PointCloud2Injector',
    'image': 'bagfault.injectors.image:ImageInjector',
    'process': 'bagfault.injectors.system:ProcessInjector',
    'clock': 'bagfault.injectors.system:ClockInjector',
    'link': 'bagfault.injectors.link:LinkInjector',
})


@lru_cache(maxsize=1)
def injector_types() -> dict[str, InjectorType]:
    """All known injector types, built-ins first; a plugin cannot replace a built-in."""
    from importlib.metadata import entry_points  # noqa: PLC0415 - 70 ms; scenarios of built-ins never need it

    types: dict[str, InjectorType] = dict(BUILTIN)  # every built-in imported: the list needs them all
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
    return BUILTIN[name] if name in BUILTIN else injector_types().get(name)
