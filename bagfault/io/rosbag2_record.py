"""The `rosbag2` metadata record of an MCAP, read as every distro wrote it."""

from __future__ import annotations

import yaml


def distro_of(metadata: dict[str, str]) -> str | None:
    """The distro a `rosbag2` record names: `ROS_DISTRO` (Humble, Iron) or `serialized_metadata` (Jazzy on, its
    keys at the top level as rosbag2 writes them, or nested as bagfault 0.1 did); None when it names none."""
    try:
        info = yaml.safe_load(metadata.get('serialized_metadata', '')) or {}
    except yaml.YAMLError:
        info = {}
    if isinstance(info, dict) and isinstance(info.get('rosbag2_bagfile_information'), dict):
        info = info['rosbag2_bagfile_information']
    distro = metadata.get('ROS_DISTRO') or (info.get('ros_distro') if isinstance(info, dict) else None)
    return distro if isinstance(distro, str) and distro else None
