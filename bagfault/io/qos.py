"""rosbag2's `offered_qos_profiles`: read in every form rosbag2 ever wrote, written in the one form all distros read.

Humble's and Iron's players read the policies as rmw enum numbers outside a
try; Jazzy's reader detects numbers or names. So bagfault writes numbers, with
all nine keys, as yaml-cpp prints them (block style, no anchors, no trailing
newline), like the rosbag2 recordings of every distro up to metadata version 8.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

import yaml

INFINITE_SEC, INFINITE_NSEC = 9223372036, 854775807  # RMW_DURATION_INFINITE (INT64_MAX ns) as sec and nsec

# rmw's enums (rmw/types.h), by the names rosbag2 version 9 writes
HISTORY = {'system_default': 0, 'keep_last': 1, 'keep_all': 2, 'unknown': 3}
RELIABILITY = {'system_default': 0, 'reliable': 1, 'best_effort': 2, 'unknown': 3, 'best_available': 4}
DURABILITY = {'system_default': 0, 'transient_local': 1, 'volatile': 2, 'unknown': 3, 'best_available': 4}
LIVELINESS = {'system_default': 0, 'automatic': 1, 'manual_by_node': 2, 'manual_by_topic': 3, 'unknown': 4,
              'best_available': 5}


def _infinite() -> dict[str, int]:
    return {'sec': INFINITE_SEC, 'nsec': INFINITE_NSEC}


@dataclass(frozen=True)
class QosProfile:
    """One publisher's offered profile, policies as rmw enum numbers, durations as {sec, nsec}."""

    history: int = 1
    depth: int = 10
    reliability: int = 1
    durability: int = 2
    deadline: dict[str, int] = field(default_factory=_infinite)
    lifespan: dict[str, int] = field(default_factory=_infinite)
    liveliness: int = 1
    liveliness_lease_duration: dict[str, int] = field(default_factory=_infinite)
    avoid_ros_namespace_conventions: bool = False

    @property
    def best_effort(self) -> bool:
        return self.reliability == RELIABILITY['best_effort']

    @property
    def transient_local(self) -> bool:
        return self.durability == DURABILITY['transient_local']


DEFAULT_PROFILE = QosProfile()  # what a channel with no recorded QoS offers: keep last 10, reliable, volatile


def _policy(value: Any, names: dict[str, int], default: int) -> int:
    if isinstance(value, bool):
        return default
    if isinstance(value, int) and 0 <= value <= max(names.values()):
        return value
    if isinstance(value, str):
        return names.get(value.strip().lower(), default)
    return default


def _duration(value: Any) -> dict[str, int]:
    if isinstance(value, dict):
        sec, nsec = value.get('sec'), value.get('nsec')
        if isinstance(sec, int) and isinstance(nsec, int) and not isinstance(sec, bool) and sec >= 0 <= nsec:
            return {'sec': sec, 'nsec': nsec}
    return _infinite()


def _profile(item: dict[str, Any]) -> QosProfile:
    depth = item.get('depth')
    return QosProfile(
        history=_policy(item.get('history'), HISTORY, 1),
        depth=depth if isinstance(depth, int) and not isinstance(depth, bool) and depth >= 0 else 10,
        reliability=_policy(item.get('reliability'), RELIABILITY, 1),
        durability=_policy(item.get('durability'), DURABILITY, 2),
        deadline=_duration(item.get('deadline')),
        lifespan=_duration(item.get('lifespan')),
        liveliness=_policy(item.get('liveliness'), LIVELINESS, 1),
        liveliness_lease_duration=_duration(item.get('liveliness_lease_duration')),
        avoid_ros_namespace_conventions=item.get('avoid_ros_namespace_conventions') is True,
    )


def parse_profiles(recorded: str | list[Any] | None) -> list[QosProfile] | None:
    """The profiles of a recorded `offered_qos_profiles` (text or the version 9 sequence; numbers or names; keys
    missing are given rmw's defaults), None when there is nothing readable."""
    if isinstance(recorded, str):
        if not recorded.strip():
            return None
        try:
            recorded = yaml.safe_load(recorded)
        except yaml.YAMLError:
            return None
    if not isinstance(recorded, list) or not recorded or not all(isinstance(x, dict) for x in recorded):
        return None
    return [_profile(item) for item in recorded]


def dump_profiles(profiles: list[QosProfile]) -> str:
    """The integer form with nine keys, as rosbag2 up to metadata version 8 writes it into MCAP channels."""
    return yaml.safe_dump([asdict(p) for p in profiles], sort_keys=False, default_flow_style=False).rstrip('\n')


def normalized(recorded: str | list[Any] | None) -> str:
    """Any recorded form in the integer form; the default profile when nothing is readable."""
    return dump_profiles(parse_profiles(recorded) or [DEFAULT_PROFILE])


DEFAULT_QOS = dump_profiles([DEFAULT_PROFILE])
