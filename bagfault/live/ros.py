"""rclpy helpers: message classes by type name, QoS profiles, time conversions.

Imported only by the live modules that talk to rclpy, so the rest of
bagfault runs without ROS installed.
"""

from __future__ import annotations

import importlib
import time
from typing import TYPE_CHECKING, Any

from rclpy.duration import Duration
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from bagfault.errors import LiveError
from bagfault.io.qos import DEFAULT_QOS, dump_profiles, parse_profiles
from bagfault.io.qos import QosProfile as StoredProfile
from bagfault.units import NS

if TYPE_CHECKING:
    from collections.abc import Iterable

RELIABILITY = {'reliable': ReliabilityPolicy.RELIABLE, 'best_effort': ReliabilityPolicy.BEST_EFFORT}
DURABILITY = {'volatile': DurabilityPolicy.VOLATILE, 'transient_local': DurabilityPolicy.TRANSIENT_LOCAL}


def interface_class(name: str) -> Any:
    """The Python class of a ROS interface ('sensor_msgs/msg/Imu', 'std_srvs/srv/Trigger')."""
    parts = name.split('/')
    if len(parts) != 3:
        raise LiveError(f'{name}: not a full ROS 2 type name (package/msg/Name)')
    package, kind, type_name = parts
    try:
        return getattr(importlib.import_module(f'{package}.{kind}'), type_name)
    except (ImportError, AttributeError):
        raise LiveError(
            f'{name}: type not installed for rclpy (pip install ros-jazzy-{package.replace("_", "-")} '
            'or source the workspace that builds it)'
        ) from None


def unacknowledged(publishers: Iterable[Any], timeout: float) -> list[str]:
    """Wait until every subscriber acknowledged what the reliable `publishers` sent, `timeout` seconds in all;
    the topics still unacknowledged. A process that exits first takes the samples still being resent with it."""
    deadline = time.monotonic() + timeout
    late = []
    for publisher in publishers:
        left = max(deadline - time.monotonic(), 0.0)
        if not publisher.wait_for_all_acked(Duration(nanoseconds=int(left * NS))):
            late.append(publisher.topic_name)
    return sorted(late)


def has_interface(name: str) -> bool:
    """True when the type can be used with rclpy here."""
    try:
        interface_class(name)
    except LiveError:
        return False
    return True


def qos(depth: int, reliability: str = 'reliable', durability: str = 'volatile') -> QoSProfile:
    """A keep-last profile from an injector's qos_depth, reliability and durability."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth, reliability=RELIABILITY[reliability],
                      durability=DURABILITY[durability])


def adapted_qos(depth: int, endpoints: Iterable[Any]) -> QoSProfile:
    """A subscription every publisher of a topic connects to, as rosbag2's recorder requests it
    (`Rosbag2QoS::adapt_request_to_offers`): reliable only when all offer reliable, transient local only when
    all offer transient local; reliable and volatile when there is none yet."""
    profiles = [e.qos_profile for e in endpoints]
    reliable = all(p.reliability == ReliabilityPolicy.RELIABLE for p in profiles)
    latched = bool(profiles) and all(p.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in profiles)
    return qos(depth, 'reliable' if reliable else 'best_effort', 'transient_local' if latched else 'volatile')


def recorded_qos(text: str, depth: int = 10) -> QoSProfile | None:
    """The first profile of rosbag2's `offered_qos_profiles` YAML (numbers or names), None when absent or
    unreadable; a recorded depth of 0 (what recorders report for other nodes' publishers) gives `depth`."""
    profiles = parse_profiles(text)
    if profiles is None:
        return None
    first = profiles[0]
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=first.depth or depth,
        reliability=ReliabilityPolicy.BEST_EFFORT if first.best_effort else ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if first.transient_local else DurabilityPolicy.VOLATILE)


def _duration(value: Any) -> dict[str, int]:
    nanoseconds = int(getattr(value, 'nanoseconds', 0))
    return {'sec': nanoseconds // NS, 'nsec': nanoseconds % NS}


def offered_yaml(profiles: list[QoSProfile]) -> str:
    """rosbag2's `offered_qos_profiles` text (integer form, nine keys): one entry per publisher, as `ros2 bag
    record` writes them, so a replay offers what the original publishers offered. No publisher: the default."""
    if not profiles:
        return DEFAULT_QOS
    return dump_profiles([StoredProfile(
        history=int(p.history), depth=int(p.depth), reliability=int(p.reliability), durability=int(p.durability),
        deadline=_duration(p.deadline), lifespan=_duration(p.lifespan), liveliness=int(p.liveliness),
        liveliness_lease_duration=_duration(p.liveliness_lease_duration),
        avoid_ros_namespace_conventions=bool(p.avoid_ros_namespace_conventions)) for p in profiles])


def offered_metadata(endpoints: Iterable[Any]) -> dict[str, str]:
    """A recorded channel's metadata as `ros2 bag record` writes it, from the publishers the graph shows: their
    `offered_qos_profiles` and their `topic_type_hash` (empty unless they agree on one RIHS hash)."""
    infos = list(endpoints)
    hashes = {str(info.topic_type_hash) for info in infos if str(info.topic_type_hash).startswith('RIHS')}
    return {'offered_qos_profiles': offered_yaml([info.qos_profile for info in infos]),
            'topic_type_hash': hashes.pop() if len(hashes) == 1 else ''}


def make_node(name: str, context: Any, ros_args: list[str] | None = None, **options: Any) -> Any:
    """A node; `ros_args` (what follows --ros-args on the command line: -r remaps, __node, __ns, -p, params
    files) apply to it alone. LiveError naming the argument rcl refuses."""
    from rclpy.node import Node  # noqa: PLC0415

    cli_args = ['--ros-args', *ros_args] if ros_args else None
    try:
        return Node(name, context=context, cli_args=cli_args, **options)
    except Exception as exc:
        if not ros_args:
            raise
        raise LiveError(f'--ros-args {" ".join(ros_args)}: {" ".join(str(exc).split())[:300]}') from None
