"""Sources and sinks: MCAP, rosbag2 (sqlite3/mcap), ROS 1, live."""

from __future__ import annotations

from bagfault.errors import BagfaultError


class InputError(BagfaultError):
    """An input bag is missing, unreadable, corrupt or unsupported."""


class OutputError(BagfaultError):
    """The output cannot be written."""
