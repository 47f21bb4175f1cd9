"""What every input offers, whatever its format: the `Source` protocol each reader implements.

Readers: `McapSource` (mcap_source.py), `Rosbag2Source` (a rosbag2 folder or
storage file: sqlite_source.py, mcap_source.py), `Ros1Source` (ros1_source.py);
`MergedSource` (merged.py) makes several one. `sources.open_source` picks the
reader from the input's first bytes (`sources.FORMATS`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:
    from collections.abc import Iterator

    from bagfault.io.channel import Channel, InputMessage


class Source(Protocol):
    """What every input offers."""

    channels: list[Channel]
    ros_distro: str | None
    message_count: int | None
    start_time: int | None
    end_time: int | None

    @property
    def losses(self) -> list[str]:
        """What salvage skipped so far (each with its place), empty without salvage."""
        ...

    @property
    def warnings(self) -> list[str]:
        """What the reader noticed and worked around."""
        ...

    def messages(self) -> Iterator[InputMessage]:
        """(channel index, log_time, publish_time, data) in log-time order."""
        ...

    def close(self) -> None:
        """Release resources."""
        ...
