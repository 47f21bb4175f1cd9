"""ROS 1 forms of the synthetic messages, for bags written with rosbags' ROS 1 writer."""

from __future__ import annotations

from rosbags.typesys import Stores, get_typestore

ROS1 = get_typestore(Stores.ROS1_NOETIC)


def _to_ros1(message, msgtype):
    """The ROS 1 form of a synthetic ROS 2 message: a Header with seq, the rest field by field."""
    types = ROS1.types

    def convert(value, typename):
        if typename == 'std_msgs/msg/Header':
            return types['std_msgs/msg/Header'](seq=0, stamp=types['builtin_interfaces/msg/Time'](
                sec=value.stamp.sec, nanosec=value.stamp.nanosec), frame_id=value.frame_id)
        if typename not in types:
            return value
        fields = {}
        for name, desc in ROS1.fielddefs[typename][1]:
            kind, args = int(desc[0]), desc[1]
            item = getattr(value, name)
            fields[name] = convert(item, args) if kind == 2 else item
        return types[typename](**fields)

    return convert(message, msgtype)
