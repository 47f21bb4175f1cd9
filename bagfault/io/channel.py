"""Channel record: one topic of one input with its type, schema and QoS."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Collection

Data = bytes | memoryview
InputMessage = tuple[int, int, int, Data]
"""(channel index into the source's `channels`, log_time ns, publish_time ns, serialized data)."""


def normalize_msgtype(name: str) -> str:
    """'std_msgs/String' -> 'std_msgs/msg/String'; full names stay as they are."""
    parts = name.split('/')
    if len(parts) == 2 and parts[0] and parts[1]:
        return f'{parts[0]}/msg/{parts[1]}'
    return name


@dataclass(frozen=True)
class Channel:
    """A topic as stored in a bag.

    Attributes:
        topic: Topic name.
        msgtype: Normalized ROS 2 type name (pkg/msg/Name).
        schema_encoding: 'ros2msg', 'ros2idl' or '' when the bag has no definition.
        schema_text: The stored message definition, '' when absent.
        message_encoding: 'cdr' for ROS 2 data.
        metadata: Channel metadata such as offered_qos_profiles (YAML text).

    """

    topic: str
    msgtype: str
    schema_encoding: str = ''
    schema_text: str = ''
    message_encoding: str = 'cdr'
    metadata: tuple[tuple[str, str], ...] = field(default=())

    @property
    def qos(self) -> str:
        """offered_qos_profiles YAML as recorded, '' if unknown."""
        return dict(self.metadata).get('offered_qos_profiles', '')


def bag_name(name: str, topics: Collection[str]) -> str:
    """A scenario's topic name as the bag spells it: `/scan` and `scan` are one topic of the root namespace."""
    if name in topics:
        return name
    other = name[1:] if name.startswith('/') else '/' + name
    return other if other in topics else name
